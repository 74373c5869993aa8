//! Bindings of `phloem_core::shapes` for `phloem.shapes`.

use numpy::{PyArray2, PyReadonlyArray2};
use phloem_core::error::invalid;
use phloem_core::shapes::{self, LabelMap, Method, Rotations, ShapeParams};
use pyo3::prelude::*;

use crate::call::run;
use crate::convert::array;
use crate::errors::{not_contiguous, opt_slice, to_py};

fn label_map(name: &'static str, a: &PyReadonlyArray2<'_, u8>, k: usize) -> PyResult<LabelMap> {
    let (h, w) = a.as_array().dim();
    let data = a.as_slice().map_err(not_contiguous(name))?.to_vec();
    LabelMap::new(name, data, h, w, k).map_err(to_py)
}

/// Runs `f` through [`run`], handing it the engine's form of the progress callback.
fn with_progress<T: Send>(
    py: Python<'_>,
    progress: Option<Py<PyAny>>,
    threads: Option<usize>,
    f: impl FnOnce(shapes::Progress<'_>) -> phloem_core::Result<T> + Send,
) -> PyResult<T> {
    run(py, threads, progress.as_ref(), |reports| {
        let report = reports.map(|r| move |done, total| r.push_and_go_on(done, total));
        f(report
            .as_ref()
            .map(|f| f as &(dyn Fn(usize, usize) -> bool + Sync)))
    })
}

fn params(
    patch_size: usize,
    levels: usize,
    iterations: usize,
    rotations: usize,
    tileable: bool,
    seed: u64,
) -> PyResult<ShapeParams> {
    Ok(ShapeParams {
        patch_size,
        levels,
        iterations,
        rotations: Rotations::from_count(rotations).map_err(to_py)?,
        tileable,
        seed,
    })
}

fn to_array(py: Python<'_>, m: LabelMap) -> Bound<'_, PyArray2<u8>> {
    array(py, (m.h, m.w), m.data)
}

#[pyfunction]
#[pyo3(name = "shape_synthesize", signature = (shape, *, height, width, patch_size, levels, iterations, rotations, tileable, seed, mask, threads, progress))]
pub fn synthesize_py<'py>(
    py: Python<'py>,
    shape: PyReadonlyArray2<'py, u8>,
    height: usize,
    width: usize,
    patch_size: usize,
    levels: usize,
    iterations: usize,
    rotations: usize,
    tileable: bool,
    seed: u64,
    mask: Option<PyReadonlyArray2<'py, bool>>,
    threads: Option<usize>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyArray2<u8>>> {
    let ex = label_map("shape", &shape, 2)?;
    let mask = opt_slice("mask", mask.as_ref())?;
    let p = params(patch_size, levels, iterations, rotations, tileable, seed)?;
    let out = with_progress(py, progress, threads, |cb| {
        shapes::synthesize(&ex, height, width, mask, &p, cb)
    })?;
    Ok(to_array(py, out))
}

#[pyfunction]
#[pyo3(name = "shape_synthesize_labels", signature = (labels, *, k, height, width, method, patch_size, levels, iterations, rotations, tileable, seed, order, threads, progress))]
pub fn synthesize_labels_py<'py>(
    py: Python<'py>,
    labels: PyReadonlyArray2<'py, u8>,
    k: usize,
    height: usize,
    width: usize,
    method: &str,
    patch_size: usize,
    levels: usize,
    iterations: usize,
    rotations: usize,
    tileable: bool,
    seed: u64,
    order: Option<Vec<u8>>,
    threads: Option<usize>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyArray2<u8>>> {
    let method = match method {
        "layered" => Method::Layered,
        "joint" => Method::Joint,
        other => {
            return Err(to_py(invalid(
                "method",
                format!("expected 'layered' or 'joint', got {other:?}"),
            )))
        }
    };
    let ex = label_map("labels", &labels, shapes::MAX_LABELS)?;
    let p = params(patch_size, levels, iterations, rotations, tileable, seed)?;
    let out = with_progress(py, progress, threads, |cb| {
        shapes::synthesize_labels(&ex, k, height, width, method, order.as_deref(), &p, cb)
    })?;
    Ok(to_array(py, out))
}

#[pyfunction]
#[pyo3(name = "shape_similarity", signature = (a, b, *, patch_size, rotations, threads))]
pub fn similarity_py(
    py: Python<'_>,
    a: PyReadonlyArray2<'_, u8>,
    b: PyReadonlyArray2<'_, u8>,
    patch_size: usize,
    rotations: usize,
    threads: Option<usize>,
) -> PyResult<f64> {
    let a = label_map("a", &a, shapes::MAX_LABELS)?;
    let b = label_map("b", &b, shapes::MAX_LABELS)?;
    let rotations = Rotations::from_count(rotations).map_err(to_py)?;
    with_progress(py, None, threads, |_| {
        shapes::similarity(&a, &b, patch_size, rotations)
    })
}

#[pyfunction]
#[pyo3(name = "shape_layer_order", signature = (labels, *, k))]
pub fn layer_order_py(labels: PyReadonlyArray2<'_, u8>, k: usize) -> PyResult<Vec<u8>> {
    let m = label_map("labels", &labels, k)?;
    Ok(shapes::layer_order(&m, k))
}
