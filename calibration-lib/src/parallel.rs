//! Independent jobs spread over the machine's cores (the hidden-node sweep, the lead-screw
//! resolutions' cross-validation): each worker takes every `workers`-th job, and the results
//! come back in the jobs' order, whichever core ran which.

/// `run` on every job, spread over the machine's cores; the results in the jobs' order.
pub(crate) fn in_parallel<J: Sync, R: Send>(jobs: &[J], run: impl Fn(&J) -> R + Sync) -> Vec<R> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    in_parallel_on(cores, jobs, run)
}

/// `run` on every job, spread over `workers` threads (at least one, at most one per job); the
/// results in the jobs' order.
fn in_parallel_on<J: Sync, R: Send>(
    workers: usize,
    jobs: &[J],
    run: impl Fn(&J) -> R + Sync,
) -> Vec<R> {
    let workers = workers.clamp(1, jobs.len().max(1));
    let run = &run;
    let mut indexed: Vec<(usize, R)> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..workers)
            .map(|w| {
                scope.spawn(move || {
                    (w..jobs.len())
                        .step_by(workers)
                        .map(|j| (j, run(&jobs[j])))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| {
                h.join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
            })
            .collect()
    });
    indexed.sort_by_key(|(j, _)| *j);
    indexed.into_iter().map(|(_, r)| r).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_results_come_back_in_the_jobs_order_on_any_number_of_workers() {
        let jobs: Vec<u64> = (0..37).collect();
        let squares: Vec<u64> = jobs.iter().map(|j| j * j).collect();
        for workers in [0, 1, 2, 3, 5, 40] {
            assert_eq!(
                in_parallel_on(workers, &jobs, |j| j * j),
                squares,
                "{workers}"
            );
            assert!(in_parallel_on(workers, &[] as &[u64], |j| *j).is_empty());
        }
        assert_eq!(in_parallel(&jobs, |j| j * j), squares);
    }
}
