//! How a client waits for the service's answer: spin while answers come quickly, sleep while
//! they do not.
//!
//! Spinning answers fastest (p50 10–18 µs with sixteen 1 kHz clients on a 2-core machine) but
//! keeps the client runnable: when the service is busy (another client floods it), sixteen
//! spinning or yielding clients took the CPU from the service itself and turned slow answers
//! into timeouts. So a [`Waiter`] spins for at most [`SPIN_WINDOW`], and only while its recent
//! answers came within that window; otherwise it sleeps [`SLEEP_STEP`] between looks, and every
//! [`PROBE_EVERY`] requests spins once more to find out whether answers are quick again.

use std::time::{Duration, Instant};

use crate::{Error, transport};

/// Longest a waiter spins before it sleeps: an answer from an unloaded service comes within it.
const SPIN_WINDOW: Duration = Duration::from_micros(20);

/// Sleep between two looks once a waiter sleeps (the kernel's timer slack, 50 µs by default for
/// threads without a real-time policy, adds to it).
const SLEEP_STEP: Duration = Duration::from_micros(10);

/// After this many answers that needed sleeping, the next wait spins again.
const PROBE_EVERY: u32 = 8;

/// The waiting strategy of one client, adapted to how quickly its answers came.
#[derive(Debug, Clone)]
pub(crate) struct Waiter {
    /// Whether the last answer came within the spin window.
    answers_are_quick: bool,
    /// Answers since the last wait that spun.
    since_spin: u32,
}

impl Default for Waiter {
    fn default() -> Self {
        Self {
            answers_are_quick: true,
            since_spin: 0,
        }
    }
}

impl Waiter {
    /// Polls `receive` until it yields or `timeout` has passed ([`Error::Timeout`]). A sleeping
    /// waiter returns the timeout up to one sleep late: [`SLEEP_STEP`] plus the timer slack
    /// (about 60 µs on a thread without a real-time policy, about 10 µs with one).
    pub(crate) fn wait_for<T, E: std::fmt::Display>(
        &mut self,
        timeout: Duration,
        mut receive: impl FnMut() -> Result<Option<T>, E>,
    ) -> Result<T, Error> {
        let spin = self.answers_are_quick || self.since_spin >= PROBE_EVERY;
        let spin_window = if spin { SPIN_WINDOW } else { Duration::ZERO };
        let start = Instant::now();
        let deadline = start + timeout;
        loop {
            if let Some(value) = receive().map_err(transport)? {
                self.answers_are_quick = start.elapsed() <= spin_window;
                self.since_spin = if spin { 0 } else { self.since_spin + 1 };
                return Ok(value);
            }
            let now = Instant::now();
            if now > deadline {
                self.answers_are_quick = false;
                return Err(Error::Timeout { timeout });
            }
            if now - start < spin_window {
                std::hint::spin_loop();
            } else {
                std::thread::sleep(SLEEP_STEP.min(deadline - now));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `receive` that answers on its `n`-th look, counting looks.
    fn answer_on_look(n: u32, looks: &mut u32) -> impl FnMut() -> Result<Option<()>, String> + '_ {
        move || {
            *looks += 1;
            Ok((*looks >= n).then_some(()))
        }
    }

    #[test]
    fn a_quick_answer_keeps_the_waiter_spinning() {
        let mut waiter = Waiter::default();
        let mut looks = 0;
        waiter
            .wait_for(Duration::from_secs(1), answer_on_look(3, &mut looks))
            .unwrap();
        assert!(waiter.answers_are_quick);
        assert_eq!(waiter.since_spin, 0);
    }

    #[test]
    fn a_slow_answer_makes_the_waiter_sleep_until_it_probes_again() {
        let mut waiter = Waiter::default();
        // Slow: answered only after the spin window has passed.
        let slow = |waiter: &mut Waiter| {
            let start = Instant::now();
            let mut looks = 0u32;
            waiter
                .wait_for(Duration::from_secs(1), || -> Result<_, String> {
                    looks += 1;
                    Ok((start.elapsed() > 2 * SPIN_WINDOW).then_some(()))
                })
                .unwrap();
            looks
        };
        let spun_looks = slow(&mut waiter);
        assert!(!waiter.answers_are_quick);
        // While sleeping, each look costs at least one sleep step: far fewer looks than spinning.
        let mut sleeping_looks = Vec::new();
        for _ in 0..PROBE_EVERY {
            sleeping_looks.push(slow(&mut waiter));
        }
        assert_eq!(waiter.since_spin, PROBE_EVERY);
        let most_sleeping = *sleeping_looks.iter().max().unwrap();
        assert!(
            most_sleeping <= 2 * SPIN_WINDOW.as_micros() as u32 / SLEEP_STEP.as_micros() as u32 + 2,
            "{most_sleeping} looks while sleeping (spinning: {spun_looks})"
        );
        assert!(
            spun_looks > most_sleeping,
            "{spun_looks} vs {most_sleeping}"
        );
        // The probe: the next wait spins again, and a quick answer keeps it spinning.
        let mut looks = 0;
        waiter
            .wait_for(Duration::from_secs(1), answer_on_look(2, &mut looks))
            .unwrap();
        assert!(waiter.answers_are_quick);
        assert_eq!(waiter.since_spin, 0);
    }

    #[test]
    fn no_answer_is_a_timeout_near_the_deadline() {
        let mut waiter = Waiter::default();
        let timeout = Duration::from_millis(5);
        let start = Instant::now();
        let result = waiter.wait_for(timeout, || -> Result<Option<()>, String> { Ok(None) });
        let took = start.elapsed();
        assert!(matches!(result, Err(Error::Timeout { timeout: t }) if t == timeout));
        assert!(took >= timeout, "gave up after {took:?}");
        assert!(!waiter.answers_are_quick);
    }

    #[test]
    fn a_receive_error_is_a_transport_error() {
        let mut waiter = Waiter::default();
        let result = waiter.wait_for(Duration::from_secs(1), || -> Result<Option<()>, String> {
            Err("connection lost".into())
        });
        assert!(matches!(result, Err(Error::Transport(m)) if m == "connection lost"));
    }
}
