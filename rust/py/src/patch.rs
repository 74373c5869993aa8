//! Bindings of `phloem_core::{patch, knn, vote}` for `phloem.patch`.

use numpy::{PyArray2, PyArray3, PyArray4, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use phloem_core::knn::{self, KnnParams};
use phloem_core::patch::{self, Method, NnfInput, NnfParams};
use phloem_core::vote;
use pyo3::prelude::*;

use crate::call::run;
use crate::convert::{array, flat, image, rowcol};
use crate::errors::{not_contiguous, opt_slice, to_py};

/// (row, col) pairs of an array argument to flat indices, `(-1, -1)` to `NONE`.
fn indices(name: &'static str, a: &[i32], shape: (usize, usize)) -> PyResult<Vec<u32>> {
    flat(name, a, shape, "image", true)
}

type NnfOut<'py> = (Bound<'py, PyArray3<i32>>, Bound<'py, PyArray2<f32>>, u64);

#[pyfunction]
#[pyo3(name = "nnf", signature = (source, target, *, patch_size, iterations, levels, exact, seed, weights, source_mask, target_mask, init, source_knn, source_cost, threads, kdtree, tileable=false))]
pub fn nnf_py<'py>(
    py: Python<'py>,
    source: PyReadonlyArray3<'py, f32>,
    target: PyReadonlyArray3<'py, f32>,
    patch_size: usize,
    iterations: usize,
    levels: usize,
    exact: bool,
    seed: u64,
    weights: Option<PyReadonlyArray1<'py, f32>>,
    source_mask: Option<PyReadonlyArray2<'py, bool>>,
    target_mask: Option<PyReadonlyArray2<'py, bool>>,
    init: Option<PyReadonlyArray3<'py, i32>>,
    source_knn: Option<numpy::PyReadonlyArray4<'py, i32>>,
    source_cost: Option<PyReadonlyArray2<'py, f32>>,
    threads: Option<usize>,
    kdtree: bool,
    tileable: bool,
) -> PyResult<NnfOut<'py>> {
    let (sh, sw) = (source.as_array().dim().0, source.as_array().dim().1);
    let table = match &source_knn {
        Some(t) => {
            let k = t.as_array().dim().2;
            let flat = indices(
                "source_knn",
                t.as_slice().map_err(not_contiguous("source_knn"))?,
                (sh, sw),
            )?;
            Some((flat, k))
        }
        None => None,
    };
    let input = NnfInput {
        source: image("source", &source)?,
        target: image("target", &target)?,
        weights: opt_slice("weights", weights.as_ref())?,
        source_mask: opt_slice("source_mask", source_mask.as_ref())?,
        target_mask: opt_slice("target_mask", target_mask.as_ref())?,
        init: opt_slice("init", init.as_ref())?,
        source_knn: table.as_ref().map(|(t, k)| (t.as_slice(), *k)),
        source_cost: opt_slice("source_cost", source_cost.as_ref())?,
        tileable,
    };
    let method = if exact {
        Method::Exact
    } else if kdtree {
        Method::KdTree
    } else {
        Method::PatchMatch
    };
    let params = NnfParams {
        patch_size,
        iterations,
        levels,
        seed,
        method,
    };
    let f = run(py, threads, None, |_| patch::nnf(&input, &params))?;
    let field = array(py, (f.h, f.w, 2), f.to_rowcol());
    Ok((field, array(py, (f.h, f.w), f.dist), f.evaluations))
}

type KnnOut<'py> = (Bound<'py, PyArray4<i32>>, Bound<'py, PyArray3<f32>>);

#[pyfunction]
#[pyo3(name = "knn", signature = (exemplar, *, k, patch_size, iterations, exact, exclude, seed, weights, threads))]
pub fn knn_py<'py>(
    py: Python<'py>,
    exemplar: PyReadonlyArray3<'py, f32>,
    k: usize,
    patch_size: usize,
    iterations: usize,
    exact: bool,
    exclude: usize,
    seed: u64,
    weights: Option<PyReadonlyArray1<'py, f32>>,
    threads: Option<usize>,
) -> PyResult<KnnOut<'py>> {
    let img = image("exemplar", &exemplar)?;
    let weights = opt_slice("weights", weights.as_ref())?;
    let params = KnnParams {
        patch_size,
        k,
        iterations,
        exact,
        exclude,
        seed,
    };
    let t = run(py, threads, None, |_| knn::knn(&img, weights, &params))?;
    let idx = array(py, (t.h, t.w, t.k, 2), rowcol(&t.idx, t.w));
    Ok((idx, array(py, (t.h, t.w, t.k), t.dist)))
}

#[pyfunction]
#[pyo3(name = "coherence_candidates", signature = (refs, exemplar_shape, *, patch_size, wrap, knn_idx, threads))]
pub fn coherence_candidates_py<'py>(
    py: Python<'py>,
    refs: PyReadonlyArray3<'py, i32>,
    exemplar_shape: (usize, usize),
    patch_size: usize,
    wrap: bool,
    knn_idx: Option<numpy::PyReadonlyArray4<'py, i32>>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyArray4<i32>>> {
    let (eh, ew) = exemplar_shape;
    let (h, w, _) = refs.as_array().dim();
    let r = indices(
        "refs",
        refs.as_slice().map_err(not_contiguous("refs"))?,
        (eh, ew),
    )?;
    let table = match &knn_idx {
        Some(t) => {
            let (th, tw, k, _) = t.as_array().dim();
            let idx = indices(
                "knn_idx",
                t.as_slice().map_err(not_contiguous("knn_idx"))?,
                (eh, ew),
            )?;
            Some(knn::Knn {
                h: th,
                w: tw,
                k,
                idx,
                dist: Vec::new(),
            })
        }
        None => None,
    };
    let (c, m) = run(py, threads, None, |_| {
        knn::coherence_candidates(&r, h, w, eh, ew, table.as_ref(), patch_size, wrap, false)
    })?;
    Ok(array(py, (h, w, m, 2), rowcol(&c, ew)))
}

type VoteOut<'py> = (Bound<'py, PyArray3<f32>>, Bound<'py, PyArray2<f32>>);

#[pyfunction]
#[pyo3(name = "vote", signature = (source, field, *, patch_size, weights, threads, mean_shift, pixels, tileable=false))]
pub fn vote_py<'py>(
    py: Python<'py>,
    source: PyReadonlyArray3<'py, f32>,
    field: PyReadonlyArray3<'py, i32>,
    patch_size: usize,
    weights: Option<PyReadonlyArray2<'py, f32>>,
    threads: Option<usize>,
    mean_shift: usize,
    pixels: Option<PyReadonlyArray2<'py, bool>>,
    tileable: bool,
) -> PyResult<VoteOut<'py>> {
    let src = image("source", &source)?;
    let (h, w, two) = field.as_array().dim();
    if two != 2 {
        return Err(to_py(phloem_core::error::invalid(
            "field",
            format!("expected shape (H, W, 2), got last axis {two}"),
        )));
    }
    let idx = vote::idx_from_rowcol(
        field.as_slice().map_err(not_contiguous("field"))?,
        src.h,
        src.w,
        patch_size,
    )
    .map_err(to_py)?;
    let wts = opt_slice("weights", weights.as_ref())?;
    let at = opt_slice("pixels", pixels.as_ref())?;
    let v = run(py, threads, None, |_| {
        vote::vote_mode(&src, &idx, h, w, wts, patch_size, mean_shift, at, tileable)
    })?;
    Ok((
        array(py, (h, w, src.c), v.image),
        array(py, (h, w), v.weight),
    ))
}
