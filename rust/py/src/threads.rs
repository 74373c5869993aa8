//! Local rayon pools: `threads=None` uses `PHLOEM_NUM_THREADS` or rayon's default; any other
//! count runs in a cached pool of that size. Results never depend on the count.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use phloem_core::{Error, Result};
use pyo3::prelude::*;
use rayon::ThreadPool;

fn pools() -> &'static Mutex<HashMap<usize, Arc<ThreadPool>>> {
    static POOLS: OnceLock<Mutex<HashMap<usize, Arc<ThreadPool>>>> = OnceLock::new();
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
/// would signal threads that are not there.
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

/// Runs `f` on a pool of `threads` workers.
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
    let pool = {
        let mut map = pools()
            .lock()
            .map_err(|_| Error::Internal("thread pool cache poisoned".into()))?;
        if let Some(p) = map.get(&n) {
            Arc::clone(p)
        } else {
            let p = Arc::new(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .thread_name(|i| format!("phloem-{i}"))
                    .build()
                    .map_err(|e| Error::Internal(format!("cannot start {n} threads: {e}")))?,
            );
            map.insert(n, Arc::clone(&p));
            p
        }
    };
    pool.install(f)
}
