//! Bindings of `phloem_core::emd` for `phloem.leaves.color_distance` and `phloem.metrics.emd`.

use numpy::{PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use phloem_core::emd::{self, MapInput};
use phloem_core::error::invalid;
use pyo3::prelude::*;

use crate::call::run;
use crate::convert::array;
use crate::errors::{not_contiguous, to_py};

fn square<'a>(a: &'a PyReadonlyArray2<'_, f64>) -> PyResult<(usize, &'a [f64])> {
    let (n, m) = a.as_array().dim();
    if n != m {
        return Err(to_py(invalid(
            "ground",
            format!("expected a square matrix, got ({n}, {m})"),
        )));
    }
    Ok((n, a.as_slice().map_err(not_contiguous("ground"))?))
}

/// The normalised EMD between `target` and each pixel's `window × window` histogram of
/// `labels` (−1: outside, NaN out).
#[pyfunction]
#[pyo3(name = "emd_map", signature = (labels, ground, target, *, window, threads))]
pub fn emd_map_py<'py>(
    py: Python<'py>,
    labels: PyReadonlyArray2<'py, i32>,
    ground: PyReadonlyArray2<'py, f64>,
    target: PyReadonlyArray1<'py, f64>,
    window: usize,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let size = labels.as_array().dim();
    let (n_bins, ground) = square(&ground)?;
    let input = MapInput {
        labels: labels.as_slice().map_err(not_contiguous("labels"))?,
        size,
        n_bins,
        ground,
        target: target.as_slice().map_err(not_contiguous("target"))?,
        window,
    };
    let out = run(py, threads, None, |_| emd::emd_map(&input))?;
    Ok(array(py, size, out))
}

/// The exact EMD between two histograms (each scaled to unit mass) under `ground`.
#[pyfunction]
#[pyo3(name = "emd", signature = (hist_a, hist_b, ground))]
pub fn emd_py(
    hist_a: PyReadonlyArray1<'_, f64>,
    hist_b: PyReadonlyArray1<'_, f64>,
    ground: PyReadonlyArray2<'_, f64>,
) -> PyResult<f64> {
    let (_, g) = square(&ground)?;
    emd::emd(
        hist_a.as_slice().map_err(not_contiguous("hist_a"))?,
        hist_b.as_slice().map_err(not_contiguous("hist_b"))?,
        g,
    )
    .map_err(to_py)
}
