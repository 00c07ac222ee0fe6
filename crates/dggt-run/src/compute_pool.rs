//! Tensor work (a training step, a validation pass, a reconstruction, an evaluation, a benchmark's sweep, a
//! refiner's training step) run on one of rayon's worker threads.
//!
//! The CPU backend and the project's host kernels split large operations over rayon's pool. Called from a thread
//! outside the pool (the program's main thread), every such operation hands its work to the pool, wakes the
//! workers and puts the caller to sleep until they are done: a few context switches per operation, and thousands
//! of operations in a training step. Called from a worker, an operation keeps a share of its work on the calling
//! thread and wakes only the others. On two cores this made the main job's step 0.87x as long and the real
//! log's first steps 0.92x, with bit-identical losses (docs/BENCHMARKS.md, *A step's work on rayon's pool*); a
//! reconstruction's renders took 0.93x as long, an evaluation and a benchmark's rows 0.85x and the tiny refiner's
//! training 0.91x, with the same outputs.

/// Runs `work` on a thread of rayon's global pool and returns its result, the caller waiting meanwhile; inside
/// the pool already, `work` runs where it is.
///
/// `work` must not wait for something another thread computes with rayon's pool (a channel fed by such a
/// thread, a thread it spawns and joins): on a pool of one thread that thread's jobs could never run.
pub fn on_pool_worker<T: Send>(work: impl FnOnce() -> T + Send) -> T {
    rayon::scope(|_| work())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn work_runs_on_a_pool_thread_and_returns_its_result() {
        assert_eq!(rayon::current_thread_index(), None, "the test harness's thread is outside the pool");
        let (index, sum) = on_pool_worker(|| (rayon::current_thread_index(), (1..=10).sum::<i32>()));
        assert!(index.is_some(), "the work should have run on a pool thread");
        assert_eq!(sum, 55);
    }

    #[test]
    fn nested_calls_stay_on_the_calling_worker() {
        let (outer, inner) = on_pool_worker(|| {
            let outer = rayon::current_thread_index();
            (outer, on_pool_worker(rayon::current_thread_index))
        });
        assert_eq!(outer, inner);
    }
}
