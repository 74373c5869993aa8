//! Bindings of `phloem_core::crossings` for `phloem.branching.growth`'s planarity test.

use numpy::{PyArray1, PyReadonlyArray2, PyReadonlyArray3};
use phloem_core::crossings;
use phloem_core::error::invalid;
use pyo3::prelude::*;

use crate::convert::array;
use crate::errors::{not_contiguous, to_py};

/// For each `(len, 2)` polyline of `paths`, whether one of its edges crosses one of the
/// `(m, 4)` `segments` properly (touching at an end point is not a crossing).
#[pyfunction]
#[pyo3(name = "polylines_crossing", signature = (paths, segments))]
pub fn polylines_crossing_py<'py>(
    py: Python<'py>,
    paths: PyReadonlyArray3<'py, f64>,
    segments: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyArray1<bool>>> {
    let (n, len, two) = paths.as_array().dim();
    if two != 2 {
        return Err(to_py(invalid(
            "paths",
            format!("expected (n, len, 2) points, got (n, len, {two})"),
        )));
    }
    let cols = segments.as_array().dim().1;
    if cols != 4 {
        return Err(to_py(invalid(
            "segments",
            format!("expected (m, 4) rows, got (m, {cols})"),
        )));
    }
    let p = paths.as_slice().map_err(not_contiguous("paths"))?;
    let s = segments.as_slice().map_err(not_contiguous("segments"))?;
    let hit = py
        .detach(|| crossings::polylines_crossing(p, len, s))
        .map_err(to_py)?;
    Ok(array(py, n, hit))
}
