//! Independent jobs spread over the machine's cores (the hidden-node sweep, the lead-screw
//! resolutions' cross-validation): each worker takes every `workers`-th job, and the results
//! come back in the jobs' order, whichever core ran which.

/// `run` on every job, spread over the machine's cores; the results in the jobs' order.
pub(crate) fn in_parallel<J: Sync, R: Send>(jobs: &[J], run: impl Fn(&J) -> R + Sync) -> Vec<R> {
    let workers = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .clamp(1, jobs.len().max(1));
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
            .flat_map(|h| h.join().expect("a worker panicked"))
            .collect()
    });
    indexed.sort_by_key(|(j, _)| *j);
    indexed.into_iter().map(|(_, r)| r).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_results_come_back_in_the_jobs_order() {
        let jobs: Vec<u64> = (0..37).collect();
        let squares = in_parallel(&jobs, |j| {
            // Later jobs finish first.
            std::thread::sleep(std::time::Duration::from_micros(40 - j));
            j * j
        });
        assert_eq!(squares, jobs.iter().map(|j| j * j).collect::<Vec<_>>());
        assert!(in_parallel(&[] as &[u64], |j| *j).is_empty());
    }
}
