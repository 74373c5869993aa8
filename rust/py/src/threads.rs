//! Local rayon pools: `threads=None` uses `PHLOEM_NUM_THREADS` or rayon's default; any other
//! count runs on a pool of that size. Results never depend on the count.
//!
//! A call checks a pool out for its duration and returns it afterwards, so calls made at the
//! same time from several Python threads (the GIL is released around the work) each get
//! their own workers instead of queueing on one shared pool: two `threads=1` calls from two
//! threads run on two cores. Pools are kept for reuse, at most as many per size as were ever
//! in use at once.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use phloem_core::{Error, Result};
use pyo3::prelude::*;
use rayon::ThreadPool;

type Free = HashMap<usize, Vec<Arc<ThreadPool>>>;

fn pools() -> &'static Mutex<Free> {
    static POOLS: OnceLock<Mutex<Free>> = OnceLock::new();
    POOLS.get_or_init(|| Mutex::new(HashMap::new()))
}

fn env_threads() -> Option<usize> {
    std::env::var("PHLOEM_NUM_THREADS")
        .ok()?
        .trim()
        .parse()
        .ok()
        .filter(|n| *n > 0)
}

/// Forgets every cached pool. Called in a forked child, where the pools' worker threads do
/// not exist: using one would hang. The old pools are leaked, not dropped, since dropping
/// would signal threads that are not there. (A pool checked out in the parent at the fork
/// is not returned in the child: the thread that would return it does not exist there.)
pub fn forget_pools() {
    if let Ok(mut map) = pools().lock() {
        std::mem::forget(std::mem::take(&mut *map));
    }
}

#[pyfunction]
#[pyo3(name = "_after_fork_in_child")]
pub fn after_fork_in_child_py() {
    forget_pools();
}

/// The thread count used when none is given.
pub fn default_threads() -> usize {
    env_threads().unwrap_or_else(rayon::current_num_threads)
}

#[pyfunction]
#[pyo3(name = "default_threads")]
pub fn default_threads_py() -> usize {
    default_threads()
}

fn poisoned<T>(_: T) -> Error {
    Error::Internal("thread pool cache poisoned".into())
}

/// A pool of `n` workers checked out of the cache; it goes back when dropped.
struct Lease {
    n: usize,
    pool: Arc<ThreadPool>,
}

impl Drop for Lease {
    fn drop(&mut self) {
        if let Ok(mut map) = pools().lock() {
            map.entry(self.n).or_default().push(Arc::clone(&self.pool));
        }
    }
}

fn lease(n: usize) -> Result<Lease> {
    let cached = pools()
        .lock()
        .map_err(poisoned)?
        .get_mut(&n)
        .and_then(Vec::pop);
    let pool = match cached {
        Some(p) => p,
        None => Arc::new(
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .thread_name(|i| format!("phloem-{i}"))
                .build()
                .map_err(|e| Error::Internal(format!("cannot start {n} threads: {e}")))?,
        ),
    };
    Ok(Lease { n, pool })
}

/// Runs `f` on a pool of `threads` workers of its own.
pub fn install<T: Send>(threads: Option<usize>, f: impl FnOnce() -> Result<T> + Send) -> Result<T> {
    let n = match threads {
        Some(0) => {
            return Err(phloem_core::error::invalid(
                "threads",
                "expected at least 1 thread, got 0",
            ))
        }
        Some(n) => n,
        None => default_threads(),
    };
    lease(n)?.pool.install(f)
}
