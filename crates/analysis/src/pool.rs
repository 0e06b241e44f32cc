//! The worker threads of `--jobs`: rayon pools started once per process and
//! kept (normally one, sized by the CLI's `--jobs`), so a run's parallel
//! parts wake threads instead of starting them. Starting a thread per run cost more than the
//! start itself: with a fresh thread for every 2.7 ms run of 256 cells, the
//! two threads together took about 20 % more processor time than one thread
//! alone (see README, Speed).
//!
//! [`on_threads`] runs one closure on `threads` threads at once, the calling
//! thread being one of them, and returns the results in thread order.
//! Which work each thread takes is up to the closure (an atomic counter, a
//! range per index); every caller puts the results back in item order, so
//! the output never depends on the thread count or on timing.
//! [`Helper::beside`] runs a helper next to the calling thread (guided
//! refinement's second evaluator).
//!
//! Work already on a pool thread runs nested parallel parts on its own thread
//! (the same results): a worker that waited for its own pool could wait for
//! itself.

use std::sync::{Arc, Mutex, OnceLock};

/// The pools made so far, smallest first. A caller asking for `threads`
/// threads takes the smallest pool with at least `threads − 1` workers (the
/// calling thread works too), so a process normally keeps one pool: the
/// CLI's `--jobs`.
static POOLS: OnceLock<Mutex<Vec<Arc<rayon::ThreadPool>>>> = OnceLock::new();

/// The most threads a pool starts: twice the machine's cores, at least 8,
/// at most 1024. A larger `--jobs` runs on this many (the results never
/// depend on the count), instead of starting a million threads on request.
/// Read once: the standard library reads the cgroup's files on every call
/// (about 50 µs here, the time of four double-integrator cells).
fn cap() -> usize {
    static CAP: OnceLock<usize> = OnceLock::new();
    *CAP.get_or_init(|| {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        (2 * cores).clamp(8, 1024)
    })
}

/// How many threads a caller asking for `threads` gets: at most the cap, and
/// one on a pool thread. Callers that split work into one part per thread
/// split it this many ways ([`on_threads`] runs every part it is given,
/// queueing parts beyond the pool's threads).
pub fn available(threads: usize) -> usize {
    if rayon::current_thread_index().is_some() {
        1
    } else {
        threads.clamp(1, cap())
    }
}

/// A pool for `threads` threads: at least `min(threads, cap) − 1` workers,
/// made on first use. `None` when `threads < 2`, when the system refuses to
/// start a thread, or when the caller is itself a pool thread: the caller
/// then works alone, with the same results.
fn pool(threads: usize) -> Option<Arc<rayon::ThreadPool>> {
    let workers = threads.min(cap()).saturating_sub(1);
    if workers == 0 || rayon::current_thread_index().is_some() {
        return None;
    }
    let pools = POOLS.get_or_init(|| Mutex::new(Vec::new()));
    let mut pools = pools.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(p) = pools.iter().find(|p| p.current_num_threads() >= workers) {
        return Some(p.clone());
    }
    let p = Arc::new(
        rayon::ThreadPoolBuilder::new()
            .num_threads(workers)
            .thread_name(|i| format!("ravel-worker-{i}"))
            .build()
            .ok()?,
    );
    pools.push(p.clone());
    pools.sort_by_key(|p| p.current_num_threads());
    Some(p)
}

/// Starts the workers for `threads` threads now, so that they start while
/// the caller does other work (the CLI calls this before it reads a spec).
pub fn warm(threads: usize) {
    let _ = pool(threads);
}

/// `work(i)` for `i` in `0..threads`, on `threads` threads at once (the
/// calling thread runs `work(0)`), or one after the other on the calling
/// thread when no worker is to be had; the results in index order. A panic
/// in any of them is raised again here, after all have ended.
pub fn on_threads<R: Send>(threads: usize, work: &(dyn Fn(usize) -> R + Sync)) -> Vec<R> {
    let Some(pool) = pool(threads) else {
        return (0..threads).map(work).collect();
    };
    let mut slots: Vec<Option<R>> = (0..threads).map(|_| None).collect();
    if let Some((first, rest)) = slots.split_first_mut() {
        pool.in_place_scope(|scope| {
            for (i, slot) in rest.iter_mut().enumerate() {
                scope.spawn(move |_| *slot = Some(work(i + 1)));
            }
            *first = Some(work(0));
        });
    }
    slots.into_iter().flatten().collect()
}

/// A pool thread to run a helper beside the calling thread.
pub struct Helper(Arc<rayon::ThreadPool>);

impl Helper {
    /// A helper for a caller that asked for `threads ≥ 2`; `None` when there
    /// is none to be had (the caller then works alone).
    pub fn new(threads: usize) -> Option<Helper> {
        pool(threads).map(Helper)
    }

    /// `helper` on a pool thread while `main` runs on the calling thread;
    /// returns `main`'s result once both have ended (a panic in either is
    /// raised again here). `main` must not wait for `helper` to start in a
    /// way that cannot end: another caller's work may hold the pool's
    /// threads for a while first.
    pub fn beside<'s, R>(self, helper: impl FnOnce() + Send + 's, main: impl FnOnce() -> R) -> R {
        self.0.in_place_scope(|scope| {
            scope.spawn(move |_| helper());
            main()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[test]
    fn every_part_runs_once_and_comes_back_in_order() {
        // beyond the cap, parts queue on the pool's threads
        for threads in [1, 2, 3, 5, cap() + 3] {
            let ran = AtomicUsize::new(0);
            let out = on_threads(threads, &|i| {
                ran.fetch_add(1, Ordering::Relaxed);
                i * 10
            });
            assert_eq!(out, (0..threads).map(|i| i * 10).collect::<Vec<_>>());
            assert_eq!(ran.load(Ordering::Relaxed), threads);
        }
    }

    #[test]
    fn a_part_runs_nested_parts_on_its_own_thread() {
        // a worker waiting for its own pool's threads could wait for itself
        let out = on_threads(2, &|i| {
            let inner = on_threads(3, &|j| (i, j, rayon::current_thread_index().is_some()));
            let on_worker = rayon::current_thread_index().is_some();
            if on_worker {
                assert_eq!(available(4), 1);
                assert!(Helper::new(2).is_none());
                assert!(inner.iter().all(|(_, _, w)| *w));
            }
            inner
                .into_iter()
                .map(|(a, b, _)| (a, b))
                .collect::<Vec<_>>()
        });
        assert_eq!(
            out,
            (0..2)
                .map(|i| (0..3).map(|j| (i, j)).collect::<Vec<_>>())
                .collect::<Vec<_>>()
        );
    }

    #[test]
    fn a_helper_runs_beside_the_caller() {
        let helper = Helper::new(2).expect("a thread can be started");
        let (tx, rx) = std::sync::mpsc::channel();
        // the caller waits for the helper's answer: both run at once
        let got = helper.beside(move || tx.send(7).expect("caller waits"), || rx.recv());
        assert_eq!(got, Ok(7));
    }

    #[test]
    fn a_panic_in_a_part_reaches_the_caller() {
        let r = std::panic::catch_unwind(|| {
            on_threads(2, &|i| {
                assert!(i != 1, "part 1 fails");
                i
            })
        });
        assert!(r.is_err());
        // the pool still works afterwards
        assert_eq!(on_threads(2, &|i| i), vec![0, 1]);
    }

    #[test]
    fn the_cap_bounds_what_a_caller_gets() {
        assert_eq!(available(0), 1);
        assert_eq!(available(1), 1);
        assert_eq!(available(usize::MAX), cap());
        assert!(cap() >= 8 && cap() <= 1024);
    }
}
