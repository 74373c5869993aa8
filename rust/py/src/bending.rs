//! Bindings of `phloem_core::bending` for `phloem.branching.bending`'s growth-step terms.

use numpy::{PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use phloem_core::bending;
use phloem_core::error::invalid;
use pyo3::prelude::*;

use crate::convert::array;
use crate::errors::{not_contiguous, to_py};

/// The paper's `dist` of each column of the `(L, C)` `cols` against the `(L,)` history `y`.
#[pyfunction]
#[pyo3(name = "dist_columns", signature = (cols, y))]
pub fn dist_columns_py<'py>(
    py: Python<'py>,
    cols: PyReadonlyArray2<'py, f64>,
    y: PyReadonlyArray1<'py, f64>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (rows, c) = cols.as_array().dim();
    let cs = cols.as_slice().map_err(not_contiguous("cols"))?;
    let ys = y.as_slice().map_err(not_contiguous("y"))?;
    if rows != ys.len() {
        return Err(to_py(invalid(
            "cols",
            format!(
                "expected one row per history element ({}), got {rows}",
                ys.len()
            ),
        )));
    }
    let out = py.detach(|| bending::dist_columns(cs, ys)).map_err(to_py)?;
    Ok(array(py, c, out))
}

/// The heading-change bin in `[0, bins)` of each of the `(C, P)` `turns`.
#[pyfunction]
#[pyo3(name = "turn_bins", signature = (turns, bins))]
pub fn turn_bins_py<'py>(
    py: Python<'py>,
    turns: PyReadonlyArray2<'py, f64>,
    bins: usize,
) -> PyResult<Bound<'py, PyArray2<i64>>> {
    let dim = turns.as_array().dim();
    let t = turns.as_slice().map_err(not_contiguous("turns"))?;
    let out = py.detach(|| bending::turn_bins(t, bins)).map_err(to_py)?;
    Ok(array(py, dim, out))
}

/// §4.2's `Δ` of a histogram for every candidate adding one count to each of its `(C, P)`
/// `bins` (see `phloem_core::bending::histogram_moves`).
#[pyfunction]
#[pyo3(name = "histogram_moves", signature = (u, uu, now, n, bins))]
pub fn histogram_moves_py<'py>(
    py: Python<'py>,
    u: PyReadonlyArray1<'py, f64>,
    uu: f64,
    now: f64,
    n: f64,
    bins: PyReadonlyArray2<'py, i64>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (c, p) = bins.as_array().dim();
    let us = u.as_slice().map_err(not_contiguous("u"))?;
    let bs = bins.as_slice().map_err(not_contiguous("bins"))?;
    let out = py
        .detach(|| bending::histogram_moves(us, uu, now, n, bs, p))
        .map_err(to_py)?;
    Ok(array(py, c, out))
}
