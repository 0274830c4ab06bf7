//! Overload protection on the serving thread: a token bucket of points per client.
//!
//! iceoryx2's server takes requests from its client connections in a fixed order, so a client
//! that keeps requests queued (big batches, several in flight) would be served before every later
//! client, for as long as it keeps sending. Each client therefore has a budget of points per
//! second. A request beyond it is still served while no other request waits (a lone batch job
//! gets the whole thread); while others wait, it is answered at once with the `Overloaded`
//! outcome and no points computed, which costs the serving thread about as much as one point.
//! An NC client at 1 kHz uses a thousandth of the default budget.
//!
//! Fixed-size table, no allocation; a request is charged as of the time it was taken from the
//! server port (the clock read the answer times use too: `Instant::now`, a vDSO call on Linux).

use std::time::Instant;

use hexacomp_protocol::{MAX_BATCH, MAX_CLIENTS};

/// Default sustained budget per client, points per second: about a third of what one serving
/// thread computes (3.0 M points/s in batches of 1024, `hexacomp-bench batches`), so that one
/// client alone cannot hold the serving thread.
pub const DEFAULT_POINTS_PER_SECOND: f64 = 1_000_000.0;

/// Points a client may ask for at once after being idle: four full batches.
pub const BURST_POINTS: f64 = 4.0 * MAX_BATCH as f64;

/// Table slots: every client the service admits, and as many again that have left.
const SLOTS: usize = 2 * MAX_CLIENTS;

#[derive(Debug, Clone, Copy)]
struct Bucket {
    client: u128,
    tokens: f64,
    refilled: Instant,
}

/// Per-client token buckets.
#[derive(Debug)]
pub struct Admission {
    /// Sustained budget, points per second; `None`: unlimited.
    rate: Option<f64>,
    buckets: [Option<Bucket>; SLOTS],
}

impl Admission {
    /// Budgets of `points_per_second` per client (`None` or a non-positive rate: unlimited).
    pub fn new(points_per_second: Option<f64>) -> Self {
        Self {
            rate: points_per_second.filter(|r| *r > 0.0 && r.is_finite()),
            buckets: [None; SLOTS],
        }
    }

    /// Whether `client` (its iceoryx2 client id) may have `points` computed at `now()`: within
    /// its budget, or beyond it while `others_waiting()` says no other request waits (asked
    /// only then). Admitted points are taken from the budget, which does not go below empty.
    /// Without a budget neither the clock nor `others_waiting` is asked.
    pub fn admit(
        &mut self,
        client: u128,
        points: usize,
        now: impl FnOnce() -> Instant,
        others_waiting: impl FnOnce() -> bool,
    ) -> bool {
        let Some(rate) = self.rate else {
            return true;
        };
        let now = now();
        let bucket = self.bucket(client, now);
        // Requests are charged as of when they were taken, not always in that order (a small
        // request may be answered before an earlier large one): the refill time never moves
        // back, so no stretch of time is credited twice.
        if now > bucket.refilled {
            let elapsed = now.duration_since(bucket.refilled).as_secs_f64();
            bucket.tokens = (bucket.tokens + elapsed * rate).min(BURST_POINTS);
            bucket.refilled = now;
        }
        let cost = points.max(1) as f64;
        let admitted = bucket.tokens >= cost.min(BURST_POINTS) || !others_waiting();
        if admitted {
            bucket.tokens = (bucket.tokens - cost).max(0.0);
        }
        admitted
    }

    /// The bucket of `client`, taking a free slot or the one idle longest for a new client.
    fn bucket(&mut self, client: u128, now: Instant) -> &mut Bucket {
        let slot = match self
            .buckets
            .iter()
            .position(|b| b.is_some_and(|b| b.client == client))
        {
            Some(slot) => slot,
            None => {
                let slot = self
                    .buckets
                    .iter()
                    .enumerate()
                    .min_by_key(|(_, b)| b.map(|b| b.refilled))
                    .map_or(0, |(slot, _)| slot);
                self.buckets[slot] = Some(Bucket {
                    client,
                    tokens: BURST_POINTS,
                    refilled: now,
                });
                slot
            }
        };
        self.buckets[slot].as_mut().expect("slot filled above")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn a_client_within_its_rate_is_always_admitted() {
        let mut admission = Admission::new(Some(1_000_000.0));
        let start = Instant::now();
        // 1000 points every millisecond = exactly the rate, for 10 s of simulated time.
        for ms in 0..10_000u64 {
            let now = start + Duration::from_millis(ms);
            assert!(
                admission.admit(7, 1000, || now, || true),
                "refused at {ms} ms"
            );
        }
    }

    #[test]
    fn a_flooding_client_gets_its_rate_and_no_more() {
        let mut admission = Admission::new(Some(1_000_000.0));
        let start = Instant::now();
        let mut admitted = 0usize;
        // A full batch every 100 µs for 1 s: ten times the rate.
        for tick in 0..10_000u64 {
            let now = start + Duration::from_micros(100 * tick);
            if admission.admit(1, MAX_BATCH, || now, || true) {
                admitted += MAX_BATCH;
            }
        }
        let expected = 1_000_000.0 + BURST_POINTS;
        let got = admitted as f64;
        assert!(
            (got - expected).abs() <= 2.0 * MAX_BATCH as f64,
            "admitted {got} points in 1 s, expected {expected} ± two batches"
        );
    }

    #[test]
    fn requests_charged_out_of_order_are_not_credited_twice() {
        let mut admission = Admission::new(Some(1_000_000.0));
        let t1 = Instant::now();
        // Empty the bucket at t1, then charge at t2, at the earlier t1 (a large request
        // answered after a later small one), and at t3: the credit is (t3 − t1) × rate.
        while admission.admit(3, 1, || t1, || true) {}
        let t2 = t1 + Duration::from_millis(2);
        let t3 = t1 + Duration::from_millis(3);
        let mut admitted = 0;
        for (at, points) in [(t2, 2000), (t1, 1000), (t3, 3000), (t3, 1000)] {
            if admission.admit(3, points, || at, || true) {
                admitted += points;
            }
        }
        // 3 ms at 1 M points/s: 3000 points — the 2000 at t2 and the last 1000 at t3. Had
        // t1 to t2 been credited again (the refill time moved back to t1), the 3000 at t3
        // would have been admitted as well.
        assert_eq!(admitted, 3000);
    }

    #[test]
    fn one_client_flooding_does_not_take_another_clients_budget() {
        let mut admission = Admission::new(Some(1000.0));
        let now = Instant::now();
        while admission.admit(1, 1, || now, || true) {}
        assert!(!admission.admit(1, 1, || now, || true));
        assert!(admission.admit(2, 100, || now, || true));
    }

    #[test]
    fn more_clients_than_slots_evict_the_idlest_and_keep_working() {
        let mut admission = Admission::new(Some(1000.0));
        let start = Instant::now();
        for client in 0..(3 * SLOTS) as u128 {
            let now = start + Duration::from_micros(client as u64);
            assert!(admission.admit(client, 1, || now, || true));
        }
        // The most recent client kept its (slightly drained) bucket.
        let last = (3 * SLOTS - 1) as u128;
        let now = start + Duration::from_micros(last as u64);
        assert!(admission.admit(last, 4000, || now, || true));
        assert!(!admission.admit(last, 100, || now, || true));
    }

    #[test]
    fn beyond_its_budget_a_lone_client_is_served_and_a_contended_one_refused() {
        let mut admission = Admission::new(Some(1000.0));
        let now = Instant::now();
        let mut asked = false;
        for _ in 0..100 {
            assert!(admission.admit(5, MAX_BATCH, || now, || false));
        }
        assert!(!admission.admit(
            5,
            1,
            || now,
            || {
                asked = true;
                true
            }
        ));
        assert!(asked);
        // Within the budget, whether others wait is not even asked.
        assert!(admission.admit(6, 1, || now, || unreachable!()));
    }

    #[test]
    fn without_a_rate_everything_is_admitted() {
        let mut admission = Admission::new(None);
        let now = Instant::now();
        for _ in 0..100_000 {
            assert!(admission.admit(3, MAX_BATCH, || now, || true));
        }
        let mut zero = Admission::new(Some(0.0));
        // Without a budget the clock is not read.
        assert!(zero.admit(3, MAX_BATCH, || -> Instant { unreachable!() }, || true));
    }
}
