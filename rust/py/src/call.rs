//! How every binding runs core work: on a checked-out pool (see [`crate::threads`]) with the
//! GIL released, panics and errors mapped in one place (see [`crate::errors`]), and the
//! calling thread waiting in short slices so that Ctrl-C and progress callbacks are served
//! while the work runs.
//!
//! Python runs signal handlers only on its main thread, so the check for a pending
//! `KeyboardInterrupt` must be made by the caller, not by a worker: every [`POLL`] the caller
//! re-attaches, runs `check_signals` and hands queued progress reports to the callback. An
//! exception from either cancels the pool's token; the engine stops at its next check point
//! (see `phloem_core::cancel`), and the exception is raised once the work has stopped, so the
//! pool goes back idle and the next call can use it.

use std::sync::mpsc::{sync_channel, RecvTimeoutError};
use std::time::Duration;

use phloem_core::{Error, Result};
use pyo3::prelude::*;

use crate::errors::{guarded, to_py};
use crate::progress::Reports;
use crate::threads::lease;

/// How long the caller waits between two checks for signals and progress.
const POLL: Duration = Duration::from_millis(50);

/// Runs `f` on a pool of `threads` workers and returns its result as Python sees it. `f`
/// gets the report queue when `progress` is a callback, `None` otherwise.
pub fn run<T: Send>(
    py: Python<'_>,
    threads: Option<usize>,
    progress: Option<&Py<PyAny>>,
    f: impl FnOnce(Option<&Reports>) -> Result<T> + Send,
) -> PyResult<T> {
    let lease = lease(threads).map_err(to_py)?;
    let pool = lease.pool();
    let reports = Reports::default();
    let queue = progress.is_some().then_some(&reports);
    let mut failure: Option<PyErr> = None;
    let (tx, mut rx) = sync_channel(1);
    let result = pool.pool.in_place_scope(|s| {
        s.spawn(move |_| {
            // The receiver outlives the scope, so the send cannot fail.
            let _ = tx.send(guarded(|| f(queue)));
        });
        loop {
            // A receiver is not `Sync`: it goes into the detached closure and comes back.
            let (back, got) = py.detach(move || {
                let got = rx.recv_timeout(POLL);
                (rx, got)
            });
            rx = back;
            match got {
                Ok(r) => break r,
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => {
                    break Err(Error::Internal("the work ended without a result".into()))
                }
            }
            if failure.is_none() {
                let served = py.check_signals().and_then(|()| match progress {
                    Some(cb) => reports.deliver(py, cb),
                    None => Ok(()),
                });
                if let Err(e) = served {
                    pool.token.cancel();
                    failure = Some(e);
                }
            }
        }
    });
    if let Some(e) = failure {
        return Err(e);
    }
    if let Some(cb) = progress {
        reports.deliver(py, cb)?;
    }
    result.map_err(to_py)
}
