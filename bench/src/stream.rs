//! Streams a path through a variant, request by request, paced at the interpolation rate or free
//! running, and records every request's round trip.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use hdrhistogram::Histogram;
use hexacomp_client::wire::MAX_BATCH;
use hexacomp_client::{CompensatedPoint, PointStatus};

use crate::variant::Variant;

/// How requests are timed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pacing {
    /// One request per interpolation period, as an NC interpolator sends them, s.
    Period(f64),
    /// Each request right after the previous answer.
    FreeRunning,
}

/// How to stream.
#[derive(Debug, Clone)]
pub struct StreamOptions {
    /// Request timing.
    pub pacing: Pacing,
    /// Points per request (1..=1024).
    pub batch: usize,
    /// Keep every compensated point (for the accuracy along the path).
    pub keep_points: bool,
    /// Set while a model is being swapped: requests sent meanwhile are recorded apart.
    pub swapping: Option<Arc<AtomicBool>>,
    /// The round trip beyond which a request counts as a deadline miss (the interpolation
    /// period), s.
    pub deadline_s: f64,
}

/// What streaming recorded.
#[derive(Debug)]
pub struct StreamRun {
    /// Round trip of every request, ns (requests sent outside model swaps).
    pub histogram: Histogram<u64>,
    /// Round trips of requests sent while a model was being swapped, ns.
    pub during_swaps: Histogram<u64>,
    /// Round trip of every request in order, ns (saturated at `u32::MAX`).
    pub latencies_ns: Vec<u32>,
    /// Points streamed.
    pub points: usize,
    /// Requests whose round trip took longer than the deadline (the interpolation period).
    pub deadline_misses: usize,
    /// Paced requests sent more than a period late because this process's own timer woke late
    /// (the machine's scheduling, not the variant's round trip).
    pub late_starts: usize,
    /// Requests that failed (timeout, transport), with the first error.
    pub failures: usize,
    /// The first failure's message.
    pub first_failure: Option<String>,
    /// Points answered with a status other than `ok`, per status.
    pub not_ok: Vec<(PointStatus, usize)>,
    /// Model generations that answered, in order of first appearance.
    pub generations: Vec<u64>,
    /// Wall time of the whole stream.
    pub elapsed: Duration,
    /// Every compensated point, when kept.
    pub points_out: Vec<CompensatedPoint>,
}

impl StreamRun {
    /// An error naming `what` when any request failed.
    pub fn ensure_no_failures(&self, what: &str) -> anyhow::Result<()> {
        anyhow::ensure!(
            self.failures == 0,
            "{what}: {} requests failed; the first: {}",
            self.failures,
            self.first_failure.as_deref().unwrap_or("?")
        );
        Ok(())
    }

    /// Points per second over the whole stream.
    pub fn points_per_second(&self) -> f64 {
        self.points as f64 / self.elapsed.as_secs_f64()
    }
}

/// A latency histogram from 1 ns to 100 s with 3 significant digits.
pub fn new_histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 100_000_000_000, 3).expect("valid histogram bounds")
}

/// Streams `poses` through `variant`.
pub fn stream(
    variant: &mut dyn Variant,
    poses: &[[f64; 6]],
    options: &StreamOptions,
) -> anyhow::Result<StreamRun> {
    anyhow::ensure!(
        (1..=MAX_BATCH).contains(&options.batch),
        "the batch size must be 1..={MAX_BATCH}, not {}",
        options.batch
    );
    let mut run = StreamRun {
        histogram: new_histogram(),
        during_swaps: new_histogram(),
        latencies_ns: Vec::with_capacity(poses.len().div_ceil(options.batch)),
        points: 0,
        deadline_misses: 0,
        late_starts: 0,
        failures: 0,
        first_failure: None,
        not_ok: Vec::new(),
        generations: Vec::new(),
        elapsed: Duration::ZERO,
        points_out: Vec::with_capacity(if options.keep_points { poses.len() } else { 0 }),
    };
    let mut out = vec![CompensatedPoint::empty(); options.batch];
    let deadline = Duration::from_secs_f64(options.deadline_s);
    let start = Instant::now();
    for (index, chunk) in poses.chunks(options.batch).enumerate() {
        let due = match options.pacing {
            Pacing::Period(period) => {
                let due = start + Duration::from_secs_f64(period * index as f64);
                wait_until(due);
                due
            }
            Pacing::FreeRunning => Instant::now(),
        };
        let swapping = options
            .swapping
            .as_ref()
            .is_some_and(|flag| flag.load(Ordering::Relaxed));
        let out = &mut out[..chunk.len()];
        let sent = Instant::now();
        let result = variant.compensate(chunk, out);
        let answered = Instant::now();
        let nanos = (answered - sent).as_nanos().max(1) as u64;
        if answered - sent > deadline {
            run.deadline_misses += 1;
        }
        if sent > due + deadline {
            run.late_starts += 1;
        }
        run.points += chunk.len();
        match result {
            Ok(()) => {
                let histogram = if swapping {
                    &mut run.during_swaps
                } else {
                    &mut run.histogram
                };
                histogram.saturating_record(nanos);
                run.latencies_ns.push(nanos.min(u32::MAX as u64) as u32);
                record_points(&mut run, out, options.keep_points);
            }
            Err(e) => {
                run.failures += 1;
                run.first_failure.get_or_insert_with(|| format!("{e:#}"));
                run.latencies_ns.push(u32::MAX);
            }
        }
    }
    run.elapsed = start.elapsed();
    Ok(run)
}

fn record_points(run: &mut StreamRun, out: &[CompensatedPoint], keep: bool) {
    for point in out {
        if point.status != PointStatus::Ok {
            match run.not_ok.iter_mut().find(|(s, _)| *s == point.status) {
                Some((_, count)) => *count += 1,
                None => run.not_ok.push((point.status, 1)),
            }
        }
        if run.generations.last() != Some(&point.generation)
            && !run.generations.contains(&point.generation)
        {
            run.generations.push(point.generation);
        }
    }
    if keep {
        run.points_out.extend_from_slice(out);
    }
}

/// Sleeps until shortly before `due`, then spins to it, as an interpolator's timer thread
/// would wake. (Spinning or yielding through the whole period was tried: with a spinning
/// service on a 2-core machine, both cores busy leaves kernel threads to preempt one of them,
/// and the tail grows into milliseconds.)
fn wait_until(due: Instant) {
    const SPIN: Duration = Duration::from_micros(200);
    let now = Instant::now();
    if due > now + SPIN {
        std::thread::sleep(due - now - SPIN);
    }
    while Instant::now() < due {
        std::hint::spin_loop();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::variant::InProcess;
    use hexacomp_core::Geometry;

    #[test]
    fn paced_streams_take_their_period_and_count_every_point() {
        let mut variant = InProcess::new(Geometry::prototype(), None);
        let poses = vec![[0.0, 0.0, 280.0, 0.0, 0.0, 0.0]; 50];
        let options = StreamOptions {
            pacing: Pacing::Period(0.002),
            batch: 4,
            keep_points: true,
            swapping: None,
            deadline_s: 0.002,
        };
        let run = stream(&mut variant, &poses, &options).unwrap();
        assert_eq!(run.points, 50);
        assert_eq!(run.latencies_ns.len(), 13);
        assert_eq!(run.histogram.len(), 13);
        assert_eq!(run.points_out.len(), 50);
        // 13 requests, the last due 24 ms after the first.
        assert!(
            run.elapsed >= Duration::from_millis(24),
            "{:?}",
            run.elapsed
        );
        // Without a model every point says so.
        assert_eq!(run.not_ok, vec![(PointStatus::NoModel, 50)]);
        assert_eq!(run.generations, vec![0]);
    }

    #[test]
    fn batches_beyond_the_wire_limit_are_refused() {
        let mut variant = InProcess::new(Geometry::prototype(), None);
        let options = StreamOptions {
            pacing: Pacing::FreeRunning,
            batch: MAX_BATCH + 1,
            keep_points: false,
            swapping: None,
            deadline_s: 0.001,
        };
        assert!(stream(&mut variant, &[[0.0; 6]], &options).is_err());
    }
}
