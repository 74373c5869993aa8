//! One place that turns phloem-core errors and panics into Python exceptions: bad input is a
//! `ValueError` naming the argument, anything else a `RuntimeError`.

use std::panic::{catch_unwind, AssertUnwindSafe};

use numpy::AsSliceError;
use phloem_core::Error;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::PyErr;

pub fn to_py(e: Error) -> PyErr {
    match e {
        Error::InvalidArgument { .. } => PyValueError::new_err(e.to_string()),
        // Only a run the caller cancelled stops so, and the caller raises its own exception.
        Error::Internal(_) | Error::Cancelled => PyRuntimeError::new_err(e.to_string()),
    }
}

pub fn not_contiguous(name: &'static str) -> impl Fn(AsSliceError) -> PyErr {
    move |_| PyValueError::new_err(format!("{name}: expected a C-contiguous array"))
}

/// The contiguous data of an optional array argument (`None` stays `None`); a non-contiguous
/// array is an error naming `name`.
pub fn opt_slice<'a, T: numpy::Element, D: numpy::ndarray::Dimension>(
    name: &'static str,
    a: Option<&'a numpy::PyReadonlyArray<'_, T, D>>,
) -> pyo3::PyResult<Option<&'a [T]>> {
    a.map(|a| a.as_slice().map_err(not_contiguous(name)))
        .transpose()
}

/// Runs `f`, turning a Rust panic into an `Error::Internal` instead of aborting Python with a
/// `PanicException`.
pub fn guarded<T>(f: impl FnOnce() -> phloem_core::Result<T>) -> phloem_core::Result<T> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(payload) => {
            let msg = payload
                .downcast_ref::<&str>()
                .map(|s| (*s).to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            Err(Error::Internal(format!(
                "phloem-core panicked: {msg} (please report this as a bug)"
            )))
        }
    }
}
