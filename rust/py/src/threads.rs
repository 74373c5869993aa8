//! Local rayon pools: `threads=None` uses `PHLOEM_NUM_THREADS` or rayon's default; any other
//! count runs on a pool of that size. Results never depend on the count.
//!
//! A call checks a pool out for its duration and returns it afterwards, so calls made at the
//! same time from several Python threads (the GIL is released around the work) each get
//! their own workers instead of queueing on one shared pool: two `threads=1` calls from two
//! threads run on two cores. Pools are kept for reuse, at most as many per size as were ever
//! in use at once. Every worker of a pool carries the pool's cancellation token, through which
//! `call::run` stops the work it runs there.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use phloem_core::cancel::Token;
use phloem_core::{Error, Result};
use pyo3::prelude::*;
use rayon::ThreadPool;

type Free = HashMap<usize, Vec<Arc<Pool>>>;

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

/// A pool and the cancellation token bound to each of its workers.
pub struct Pool {
    pub pool: ThreadPool,
    pub token: Token,
}

/// A pool of `n` workers checked out of the cache; it goes back when dropped.
pub struct Lease {
    n: usize,
    pool: Arc<Pool>,
}

impl Lease {
    pub fn pool(&self) -> &Pool {
        &self.pool
    }
}

impl Drop for Lease {
    fn drop(&mut self) {
        if let Ok(mut map) = pools().lock() {
            map.entry(self.n).or_default().push(Arc::clone(&self.pool));
        }
    }
}

/// Checks out a pool of `threads` workers (`None`: the default count) with its token cleared.
pub fn lease(threads: Option<usize>) -> Result<Lease> {
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
    let cached = pools()
        .lock()
        .map_err(poisoned)?
        .get_mut(&n)
        .and_then(Vec::pop);
    let pool = if let Some(p) = cached {
        p
    } else {
        let token = Token::new();
        let bound = token.clone();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .thread_name(|i| format!("phloem-{i}"))
            .start_handler(move |_| bound.bind())
            .build()
            .map_err(|e| Error::Internal(format!("cannot start {n} threads: {e}")))?;
        Arc::new(Pool { pool, token })
    };
    // A cancelled run has stopped before its pool came back; its request must not carry over.
    pool.token.reset();
    Ok(Lease { n, pool })
}
