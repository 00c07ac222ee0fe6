//! Loading ahead of the consumer: worker threads run a load function on upcoming jobs (decoding images,
//! reading masks) while the training step works on the current item, so decoding does not stall it.
//!
//! [`Prefetcher`] is an iterator over the loaded items **in job order**, whichever worker finishes first.
//!
//! - Bounded memory: a job is started only when fewer than `capacity` jobs are started but not yet yielded,
//!   so at most `capacity` items are in memory at once, loaded or being loaded. Consequently at most
//!   `min(workers, capacity)` loads run concurrently; a capacity of about twice the worker count keeps every
//!   worker busy while the consumer catches up.
//! - Errors: every job yields exactly one item. An error returned by the load function, or a panic inside it,
//!   is yielded in the job's position and the following jobs carry on; the consumer decides whether to stop
//!   (dropping the prefetcher stops the workers). A panic in the job iterator itself is yielded as an error in
//!   the position of the job it failed to produce, and ends the sequence. Panics are reported as
//!   [`DataError::Config`], the error variant not tied to a file, with the panic message.
//! - Jobs are taken from the job iterator one at a time, in order, under a lock that also gates the
//!   consumer's progress: the iterator should only produce job descriptions (paths, indices) and leave the
//!   expensive work to the load function.
//! - Dropping: no new job is started after the prefetcher is dropped; the drop waits for the loads in
//!   progress (at most one per worker) to finish and for every worker thread to exit.
//!
//! Workers are plain threads, not rayon tasks, so that I/O and decoding do not occupy the compute pool.

use std::any::Any;
use std::collections::HashMap;
use std::iter::FusedIterator;
use std::panic::{self, AssertUnwindSafe};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::{self, JoinHandle};

use crossbeam_channel::{Receiver, Sender};

use crate::error::{DataError, Result};

/// A job's position and what became of it.
type Indexed<T> = (usize, Result<T>);

/// Which jobs may start: shared by the consumer, which frees room, and the workers, which take it.
struct Admission {
    /// Jobs taken from the job iterator so far; also the index of the next job.
    taken: usize,
    /// Items handed to the consumer so far.
    yielded: usize,
    /// The job iterator has ended (or panicked): no more jobs will be taken.
    exhausted: bool,
    /// The prefetcher was dropped: no more jobs will be taken.
    stopped: bool,
}

struct Shared {
    admission: Mutex<Admission>,
    changed: Condvar,
    capacity: usize,
}

impl Shared {
    fn admission(&self) -> MutexGuard<'_, Admission> {
        self.admission.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// An iterator over `load(job)` for each job, computed ahead by worker threads (see the module documentation).
pub struct Prefetcher<T> {
    results: Receiver<Indexed<T>>,
    /// Loaded items that arrived before an earlier job's item.
    early: HashMap<usize, Result<T>>,
    next: usize,
    shared: Arc<Shared>,
    workers: Vec<JoinHandle<()>>,
}

impl<T: Send + 'static> Prefetcher<T> {
    /// Starts `workers` threads loading `jobs` with `load`, at most `capacity` items ahead of the consumer.
    /// Errors when either count is zero or a thread cannot be started.
    pub fn new<J, F>(
        jobs: impl Iterator<Item = J> + Send + 'static,
        workers: usize,
        capacity: usize,
        load: F,
    ) -> Result<Self>
    where
        J: Send + 'static,
        F: Fn(J) -> Result<T> + Send + Sync + 'static,
    {
        if workers == 0 || capacity == 0 {
            return Err(DataError::Config(format!(
                "prefetching needs at least one worker and a capacity of at least one, got {workers} workers and \
                 capacity {capacity}"
            )));
        }
        let shared = Arc::new(Shared {
            admission: Mutex::new(Admission { taken: 0, yielded: 0, exhausted: false, stopped: false }),
            changed: Condvar::new(),
            capacity,
        });
        let (sender, results) = crossbeam_channel::unbounded();
        let mut prefetcher = Self { results, early: HashMap::new(), next: 0, shared, workers: Vec::new() };
        let jobs = Arc::new(Mutex::new(jobs));
        let load = Arc::new(load);
        for i in 0..workers {
            let worker = Worker {
                shared: Arc::clone(&prefetcher.shared),
                jobs: Arc::clone(&jobs),
                load: Arc::clone(&load),
                results: sender.clone(),
            };
            // On failure the prefetcher built so far is dropped, which stops the workers already started.
            let handle = thread::Builder::new()
                .name(format!("prefetch-{i}"))
                .spawn(move || worker.run())
                .map_err(|e| DataError::Config(format!("cannot start prefetch worker {i}: {e}")))?;
            prefetcher.workers.push(handle);
        }
        Ok(prefetcher)
    }
}

impl<T> Iterator for Prefetcher<T> {
    type Item = Result<T>;

    fn next(&mut self) -> Option<Result<T>> {
        loop {
            if let Some(item) = self.early.remove(&self.next) {
                self.next += 1;
                self.shared.admission().yielded = self.next;
                self.shared.changed.notify_one();
                return Some(item);
            }
            // Disconnected means every worker has exited after sending all it loaded: the sequence is over.
            let (index, item) = self.results.recv().ok()?;
            self.early.insert(index, item);
        }
    }
}

impl<T> FusedIterator for Prefetcher<T> {}

impl<T> Drop for Prefetcher<T> {
    fn drop(&mut self) {
        self.shared.admission().stopped = true;
        self.shared.changed.notify_all();
        for worker in self.workers.drain(..) {
            // Workers catch panics of user code, so a join error can only come from a bug here; there is no
            // one left to report it to during a drop.
            let _ = worker.join();
        }
    }
}

struct Worker<I, F, T> {
    shared: Arc<Shared>,
    /// Locked only while holding the admission lock, so that jobs are taken in index order.
    jobs: Arc<Mutex<I>>,
    load: Arc<F>,
    results: Sender<Indexed<T>>,
}

impl<J, I, F, T> Worker<I, F, T>
where
    I: Iterator<Item = J>,
    F: Fn(J) -> Result<T>,
{
    fn run(self) {
        while let Some((index, job)) = self.take_job() {
            let result = job.and_then(|job| {
                panic::catch_unwind(AssertUnwindSafe(|| (self.load)(job)))
                    .unwrap_or_else(|payload| Err(panicked(index, "loading", &*payload)))
            });
            if self.results.send((index, result)).is_err() {
                return;
            }
        }
    }

    /// Waits until there is room ahead of the consumer, then takes the next job with its index. `None` once
    /// no more jobs will be taken.
    fn take_job(&self) -> Option<Indexed<J>> {
        let mut admission = self.shared.admission();
        loop {
            if admission.stopped || admission.exhausted {
                return None;
            }
            if admission.taken - admission.yielded < self.shared.capacity {
                break;
            }
            admission = self.shared.changed.wait(admission).unwrap_or_else(PoisonError::into_inner);
        }
        let index = admission.taken;
        let next =
            panic::catch_unwind(AssertUnwindSafe(|| self.jobs.lock().unwrap_or_else(PoisonError::into_inner).next()));
        match next {
            Ok(Some(job)) => {
                admission.taken += 1;
                Some((index, Ok(job)))
            }
            Ok(None) => {
                admission.exhausted = true;
                self.shared.changed.notify_all();
                None
            }
            Err(payload) => {
                admission.taken += 1;
                admission.exhausted = true;
                self.shared.changed.notify_all();
                Some((index, Err(panicked(index, "producing the job", &*payload))))
            }
        }
    }
}

/// The error reported in place of a job whose code panicked.
fn panicked(index: usize, during: &str, payload: &(dyn Any + Send)) -> DataError {
    let message = payload
        .downcast_ref::<&str>()
        .copied()
        .or_else(|| payload.downcast_ref::<String>().map(String::as_str))
        .unwrap_or("(no message)");
    DataError::Worker(format!("prefetch job {index} panicked while {during}: {message}"))
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::time::Duration;

    use rand::rngs::SmallRng;
    use rand::{RngExt, SeedableRng};

    use super::*;

    /// Runs `test` on its own thread and fails if it has not finished within `seconds`: a hang becomes a
    /// failure instead of a stuck test run.
    fn finishes_within(seconds: u64, test: impl FnOnce() + Send + 'static) {
        let (done, finished) = crossbeam_channel::bounded(1);
        let handle = thread::spawn(move || {
            test();
            let _ = done.send(());
        });
        match finished.recv_timeout(Duration::from_secs(seconds)) {
            Ok(()) => handle.join().unwrap(),
            Err(_) if handle.is_finished() => std::panic::resume_unwind(handle.join().unwrap_err()),
            Err(_) => panic!("did not finish within {seconds} s"),
        }
    }

    fn random_delay(job: usize) -> Duration {
        Duration::from_micros(SmallRng::seed_from_u64(job as u64).random_range(0..2000))
    }

    #[test]
    fn yields_in_job_order_despite_random_delays() {
        finishes_within(30, || {
            for (workers, capacity) in [(4, 8), (8, 3), (1, 1), (1, 5)] {
                let loaded = Prefetcher::new(0..150usize, workers, capacity, |job| {
                    thread::sleep(random_delay(job));
                    Ok(job * 10)
                })
                .unwrap();
                let values: Vec<usize> = loaded.map(Result::unwrap).collect();
                assert_eq!(values, (0..150).map(|j| j * 10).collect::<Vec<_>>(), "{workers} workers");
            }
        });
    }

    #[test]
    fn never_loads_more_than_capacity_ahead() {
        finishes_within(30, || {
            let capacity = 3;
            let started = Arc::new(AtomicUsize::new(0));
            let counter = Arc::clone(&started);
            let mut loaded = Prefetcher::new(0..40usize, 6, capacity, move |job| {
                counter.fetch_add(1, Ordering::SeqCst);
                Ok(job)
            })
            .unwrap();
            while started.load(Ordering::SeqCst) < capacity {
                thread::sleep(Duration::from_millis(1));
            }
            thread::sleep(Duration::from_millis(20));
            assert_eq!(started.load(Ordering::SeqCst), capacity, "workers fill the capacity, then wait");
            for consumed in 1..=40 {
                assert_eq!(loaded.next().unwrap().unwrap(), consumed - 1);
                if consumed % 5 == 0 {
                    thread::sleep(Duration::from_millis(5));
                }
                let ahead = started.load(Ordering::SeqCst);
                assert!(ahead <= consumed + capacity, "{ahead} loads started after consuming {consumed}");
            }
            assert!(loaded.next().is_none());
        });
    }

    #[test]
    fn dropping_early_stops_the_workers() {
        finishes_within(30, || {
            let started = Arc::new(AtomicUsize::new(0));
            let counter = Arc::clone(&started);
            let mut endless = Prefetcher::new(0usize.., 4, 8, move |job| {
                counter.fetch_add(1, Ordering::SeqCst);
                thread::sleep(Duration::from_millis(1));
                Ok(job)
            })
            .unwrap();
            assert_eq!(endless.by_ref().take(20).map(Result::unwrap).collect::<Vec<_>>(), (0..20).collect::<Vec<_>>());
            drop(endless);
            let after_drop = started.load(Ordering::SeqCst);
            assert!(after_drop <= 20 + 8, "{after_drop} loads started");
            thread::sleep(Duration::from_millis(20));
            assert_eq!(started.load(Ordering::SeqCst), after_drop, "no load starts after the drop");

            // Dropped before anything is read, with workers blocked waiting for room.
            let blocked = Prefetcher::new(0usize.., 4, 1, Ok::<usize, DataError>).unwrap();
            thread::sleep(Duration::from_millis(10));
            drop(blocked);
        });
    }

    #[test]
    fn ends_when_the_jobs_run_out_with_idle_workers() {
        finishes_within(30, || {
            let few = Prefetcher::new(0..3usize, 4, 1, Ok::<usize, DataError>).unwrap();
            assert_eq!(few.map(Result::unwrap).collect::<Vec<_>>(), vec![0, 1, 2]);
            let mut none = Prefetcher::new(std::iter::empty::<usize>(), 3, 2, Ok::<usize, DataError>).unwrap();
            assert!(none.next().is_none());
            assert!(none.next().is_none(), "stays ended");
        });
    }

    #[test]
    fn errors_and_panics_take_their_job_position() {
        finishes_within(30, || {
            let loaded = Prefetcher::new(0..8usize, 3, 4, |job| match job {
                2 => Err(DataError::Config("job two is bad".into())),
                5 => panic!("job five exploded"),
                _ => Ok(job),
            })
            .unwrap();
            let items: Vec<_> = loaded.collect();
            assert_eq!(items.len(), 8, "the sequence carries on after errors");
            for (job, item) in items.iter().enumerate() {
                match (job, item) {
                    (2, Err(DataError::Config(message))) => assert_eq!(message, "job two is bad"),
                    (5, Err(DataError::Worker(message))) => {
                        assert!(
                            message.contains("job 5 panicked") && message.contains("job five exploded"),
                            "{message}"
                        );
                    }
                    (_, Ok(value)) => assert_eq!(*value, job),
                    other => panic!("unexpected item {other:?}"),
                }
            }
        });
    }

    #[test]
    fn a_panicking_job_iterator_ends_the_sequence_with_an_error() {
        finishes_within(30, || {
            let jobs = (0..10usize).map(|job| if job == 3 { panic!("no job three") } else { job });
            let items: Vec<_> = Prefetcher::new(jobs, 2, 4, Ok::<usize, DataError>).unwrap().collect();
            assert_eq!(items.len(), 4);
            assert!(items[..3].iter().zip(0..).all(|(item, job)| matches!(item, Ok(v) if *v == job)));
            assert!(matches!(&items[3], Err(DataError::Worker(m)) if m.contains("no job three")), "{:?}", items[3]);
        });
    }

    #[test]
    fn zero_workers_or_capacity_is_a_configuration_error() {
        assert!(matches!(Prefetcher::new(0..3usize, 0, 2, Ok::<usize, DataError>), Err(DataError::Config(_))));
        assert!(matches!(Prefetcher::new(0..3usize, 2, 0, Ok::<usize, DataError>), Err(DataError::Config(_))));
    }
}
