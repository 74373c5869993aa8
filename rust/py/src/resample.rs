//! Bindings of `phloem_core::resample` for `phloem.branching.Branch.resample`.

use numpy::{PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use phloem_core::resample;
use pyo3::prelude::*;

use crate::convert::{array, points as as_points};
use crate::errors::{not_contiguous, to_py};

/// The new vertices and their arc positions on the old polyline.
type Resampled<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<f64>>);

/// Up to `count` vertices along the `(n, 2)` polyline `points` at consecutive distance `h`
/// (`(m, 2)`; its two ends where the walk cannot start), and the arc length along it of each one's nearest point (`(m,)`); `cum` is the
/// polyline's running length.
#[pyfunction]
#[pyo3(name = "polyline_resample", signature = (points, cum, count, h))]
pub fn polyline_resample_py<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
    cum: PyReadonlyArray1<'py, f64>,
    count: usize,
    h: f64,
) -> PyResult<Resampled<'py>> {
    let pts = as_points("points", &points)?;
    let cum = cum.as_slice().map_err(not_contiguous("cum"))?;
    let (walk, s) = py
        .detach(|| resample::resample(&pts, cum, count, h))
        .map_err(to_py)?;
    let m = walk.len();
    Ok((
        array(py, (m, 2), walk.into_iter().flatten().collect()),
        array(py, m, s),
    ))
}
