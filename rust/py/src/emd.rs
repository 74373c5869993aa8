//! Bindings of `phloem_core::emd` for `phloem.leaves.color_distance` and `phloem.metrics.emd`.

use numpy::{PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
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

/// The index of each colour's nearest palette colour (`phloem.leaves.color`'s quantisation).
#[pyfunction]
#[pyo3(name = "nearest_colour", signature = (points, centres, norms, *, threads))]
pub fn nearest_colour_py<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f32>,
    centres: PyReadonlyArray2<'py, f32>,
    norms: PyReadonlyArray1<'py, f32>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyArray1<i32>>> {
    for (name, a) in [("points", &points), ("centres", &centres)] {
        let (_, d) = a.as_array().dim();
        if d != 3 {
            return Err(to_py(invalid(
                name,
                format!("expected 3 values per colour, got {d}"),
            )));
        }
    }
    let pts = points.as_slice().map_err(not_contiguous("points"))?;
    let cs = centres.as_slice().map_err(not_contiguous("centres"))?;
    let nm = norms.as_slice().map_err(not_contiguous("norms"))?;
    let out = run(py, threads, None, |_| emd::nearest(pts, cs, nm))?;
    Ok(array(py, out.len(), out))
}
