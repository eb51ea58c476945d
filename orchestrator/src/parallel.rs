//! Independent jobs over a few worker threads (the candidates of a diagnosis, the runs of a
//! finite-difference Jacobian, the groups of a band's directions): scoped threads taking the
//! next job as they finish one, so a long job does not hold back the others' thread.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// The cores this process may use (`std::thread::available_parallelism`, at least 1), asked
/// once: on Linux each ask reads the process's cgroup files (1.3 % of a 3-storey calibration
/// start's CPU time, asked at five places).
pub fn cores() -> usize {
    static CORES: std::sync::OnceLock<usize> = std::sync::OnceLock::new();
    *CORES.get_or_init(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}

/// `work` on every job over at most `threads` worker threads, the results in the jobs' order.
pub fn on_threads<T: Send, J: Sync>(
    jobs: &[J],
    threads: usize,
    work: impl Fn(&J) -> T + Sync,
) -> Vec<T> {
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<T>>> = Mutex::new((0..jobs.len()).map(|_| None).collect());
    std::thread::scope(|scope| {
        for _ in 0..threads.clamp(1, jobs.len().max(1)) {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= jobs.len() {
                    break;
                }
                let r = work(&jobs[i]);
                if let Ok(mut all) = results.lock() {
                    all[i] = Some(r);
                }
            });
        }
    });
    results
        .into_inner()
        .unwrap_or_default()
        .into_iter()
        .map(|r| r.expect("every job ran"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Jobs of uneven length on more threads than jobs and on one: every result, in order.
    #[test]
    fn every_job_runs_once_and_the_results_keep_the_jobs_order() {
        let jobs: Vec<u64> = (0..37).collect();
        let work = |&j: &u64| {
            // Uneven work, so the threads finish out of order.
            let spin: u64 = (0..(j % 5) * 20_000).fold(0, |a, x| a ^ x.wrapping_mul(j));
            (j * j, spin)
        };
        for threads in [1, 3, 64] {
            let got = on_threads(&jobs, threads, work);
            let squares: Vec<u64> = got.iter().map(|r| r.0).collect();
            assert_eq!(squares, jobs.iter().map(|j| j * j).collect::<Vec<_>>());
        }
        assert!(on_threads(&Vec::<u64>::new(), 4, work).is_empty());
    }
}
