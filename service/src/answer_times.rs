//! How long the serving thread takes to answer: each served request of at most
//! [`crate::answering::STEP_POINTS`] points (an NC's kind), from being received from iceoryx2
//! (its wait in the service's fair queue included) to its answer being sent, counted in the
//! buckets of the telemetry report, and those that took longer than the deadline. Relaxed
//! atomics written by the serving thread alone (a load and a store, no locked instruction),
//! read by the control thread. Not included: the time a request waits in iceoryx2 before the
//! serving thread receives it (a sleeping thread's wake-up), requests their client gave up on
//! before the answer, and the client's side of the round trip; the NC's own count of late
//! answers (the LinuxCNC component's `fault-count`) is the authority on those.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use hexacomp_protocol::{LATENCY_BUCKETS, latency_bucket};

/// The default deadline for answering a request: 200 µs (the LinuxCNC component waits that long
/// by default, but its wait also holds the round trip and the service's wake-up).
pub const DEFAULT_DEADLINE: Duration = Duration::from_micros(200);

/// The answer times so far, and the deadline they are held against.
#[derive(Debug)]
pub struct AnswerTimes {
    deadline: Duration,
    misses: AtomicU64,
    buckets: [AtomicU64; LATENCY_BUCKETS],
    sum_ns: AtomicU64,
}

impl Default for AnswerTimes {
    fn default() -> Self {
        Self::new(DEFAULT_DEADLINE)
    }
}

impl AnswerTimes {
    /// No answers yet; a request answered later than `deadline` after it was taken is a miss.
    pub fn new(deadline: Duration) -> Self {
        Self {
            deadline,
            misses: AtomicU64::new(0),
            buckets: std::array::from_fn(|_| AtomicU64::new(0)),
            sum_ns: AtomicU64::new(0),
        }
    }

    /// Counts one answer sent `elapsed` after its request was received. Allocates nothing.
    /// Only one thread may record (the serving thread): the counts are loaded and stored, not
    /// incremented atomically.
    pub fn record(&self, elapsed: Duration) {
        let nanoseconds = u64::try_from(elapsed.as_nanos()).unwrap_or(u64::MAX);
        add(&self.buckets[latency_bucket(nanoseconds)], 1);
        add(&self.sum_ns, nanoseconds);
        if elapsed > self.deadline {
            add(&self.misses, 1);
        }
    }

    /// The deadline.
    pub fn deadline(&self) -> Duration {
        self.deadline
    }

    /// Answers later than the deadline.
    pub fn misses(&self) -> u64 {
        self.misses.load(Ordering::Relaxed)
    }

    /// Answers per bucket ([`hexacomp_protocol::latency_bucket_bound_ns`]).
    pub fn buckets(&self) -> [u64; LATENCY_BUCKETS] {
        std::array::from_fn(|i| self.buckets[i].load(Ordering::Relaxed))
    }

    /// The sum of the answer times, ns.
    pub fn sum_ns(&self) -> u64 {
        self.sum_ns.load(Ordering::Relaxed)
    }
}

/// `counter += amount` by its one writer (wrapping, as a counter that overflows would).
fn add(counter: &AtomicU64, amount: u64) {
    let value = counter.load(Ordering::Relaxed).wrapping_add(amount);
    counter.store(value, Ordering::Relaxed);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn answers_are_counted_in_their_bucket_and_misses_are_those_beyond_the_deadline() {
        let times = AnswerTimes::new(Duration::from_micros(200));
        for micros in [1, 1, 150, 200, 201, 5_000] {
            times.record(Duration::from_micros(micros));
        }
        let buckets = times.buckets();
        assert_eq!(buckets.iter().sum::<u64>(), 6);
        // 1 µs: above 512 ns, up to 1024 ns (bucket 2); 150 and 200 µs up to 262 144 ns
        // (bucket 10); 201 µs too; 5 ms up to 8 388 608 ns (bucket 15).
        assert_eq!(buckets[2], 2);
        assert_eq!(buckets[10], 3);
        assert_eq!(buckets[15], 1);
        assert_eq!(times.misses(), 2, "exactly the deadline is no miss");
        assert_eq!(times.sum_ns(), (2 + 150 + 200 + 201 + 5_000) * 1_000);
    }
}
