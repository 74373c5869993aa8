//! The progress bridge: engines report `(done, total)` from whatever worker runs their
//! driver; the reports queue here and the calling thread hands them, in order, to the Python
//! callback (see [`crate::call::run`]), so Python code only ever runs on the caller's thread.

use std::sync::Mutex;

use pyo3::prelude::*;

/// Reports not yet handed to Python.
#[derive(Default)]
pub struct Reports(Mutex<Vec<(usize, usize)>>);

impl Reports {
    /// Queues one report; called by the engine, never blocks on Python.
    pub fn push(&self, done: usize, total: usize) {
        if let Ok(mut q) = self.0.lock() {
            q.push((done, total));
        }
    }

    /// The same for engines whose callback may ask to stop: never does (the caller cancels
    /// through the pool's token instead).
    pub fn push_and_go_on(&self, done: usize, total: usize) -> bool {
        self.push(done, total);
        true
    }

    /// Calls `callback(done, total)` for every queued report; the first exception stops the
    /// delivery and is returned.
    pub fn deliver(&self, py: Python<'_>, callback: &Py<PyAny>) -> PyResult<()> {
        let queued = self.0.lock().map(|mut q| std::mem::take(&mut *q));
        for (done, total) in queued.unwrap_or_default() {
            callback.call1(py, (done, total))?;
        }
        Ok(())
    }
}
