//! Bindings of `phloem_core::{patch, knn, vote}` for `phloem.patch`.

use ndarray::{Array2, Array3, Array4};
use numpy::{
    IntoPyArray, PyArray2, PyArray3, PyArray4, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
};
use phloem_core::image::Image;
use phloem_core::knn::{self, KnnParams};
use phloem_core::patch::{self, Method, NnfInput, NnfParams, NONE};
use phloem_core::vote;
use pyo3::prelude::*;

use crate::errors::{guarded, not_contiguous, opt_slice, to_py};
use crate::threads::install;

pub(crate) fn image<'a>(
    name: &'static str,
    a: &'a PyReadonlyArray3<'_, f32>,
) -> PyResult<Image<'a>> {
    let (h, w, c) = a.as_array().dim();
    Image::new(name, a.as_slice().map_err(not_contiguous(name))?, h, w, c).map_err(to_py)
}

fn rowcol(idx: &[u32], sw: usize) -> Vec<i32> {
    idx.iter()
        .flat_map(|&i| {
            if i == NONE {
                [-1, -1]
            } else {
                [(i as usize / sw) as i32, (i as usize % sw) as i32]
            }
        })
        .collect()
}

/// The inverse of [`rowcol`]: (row, col) pairs to flat indices into an `h × w` image,
/// `(-1, -1)` to [`NONE`]; any other pair outside the image is an error naming `name`.
fn flat_indices(name: &'static str, rc: &[i32], h: usize, w: usize) -> PyResult<Vec<u32>> {
    rc.chunks_exact(2)
        .map(|p| {
            if p[0] == -1 && p[1] == -1 {
                Ok(NONE)
            } else if p[0] < 0 || p[1] < 0 || p[0] as usize >= h || p[1] as usize >= w {
                Err(to_py(phloem_core::error::invalid(
                    name,
                    format!("({}, {}) is outside the {h}×{w} image", p[0], p[1]),
                )))
            } else {
                Ok((p[0] as usize * w + p[1] as usize) as u32)
            }
        })
        .collect()
}

type NnfOut<'py> = (Bound<'py, PyArray3<i32>>, Bound<'py, PyArray2<f32>>, u64);

#[pyfunction]
#[pyo3(name = "nnf", signature = (source, target, *, patch_size, iterations, levels, exact, seed, weights=None, source_mask=None, target_mask=None, init=None, source_knn=None, source_cost=None, threads=None, kdtree=false))]
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
) -> PyResult<NnfOut<'py>> {
    let (sh, sw) = (source.as_array().dim().0, source.as_array().dim().1);
    let table = match &source_knn {
        Some(t) => {
            let k = t.as_array().dim().2;
            let flat = flat_indices(
                "source_knn",
                t.as_slice().map_err(not_contiguous("source_knn"))?,
                sh,
                sw,
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
    let f = py
        .detach(|| guarded(|| install(threads, || patch::nnf(&input, &params))))
        .map_err(to_py)?;
    let field = Array3::from_shape_vec((f.h, f.w, 2), f.to_rowcol()).expect("field shape");
    let dist = Array2::from_shape_vec((f.h, f.w), f.dist).expect("dist shape");
    Ok((field.into_pyarray(py), dist.into_pyarray(py), f.evaluations))
}

type KnnOut<'py> = (Bound<'py, PyArray4<i32>>, Bound<'py, PyArray3<f32>>);

#[pyfunction]
#[pyo3(name = "knn", signature = (exemplar, *, k, patch_size, iterations, exact, exclude, seed, weights=None, threads=None))]
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
    let t = py
        .detach(|| guarded(|| install(threads, || knn::knn(&img, weights, &params))))
        .map_err(to_py)?;
    let idx = Array4::from_shape_vec((t.h, t.w, t.k, 2), rowcol(&t.idx, t.w)).expect("knn shape");
    let dist = Array3::from_shape_vec((t.h, t.w, t.k), t.dist).expect("knn dist shape");
    Ok((idx.into_pyarray(py), dist.into_pyarray(py)))
}

#[pyfunction]
#[pyo3(name = "coherence_candidates", signature = (refs, exemplar_shape, *, patch_size, wrap, knn_idx=None, threads=None))]
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
    let r = flat_indices(
        "refs",
        refs.as_slice().map_err(not_contiguous("refs"))?,
        eh,
        ew,
    )?;
    let table = match &knn_idx {
        Some(t) => {
            let (th, tw, k, _) = t.as_array().dim();
            let idx = flat_indices(
                "knn_idx",
                t.as_slice().map_err(not_contiguous("knn_idx"))?,
                eh,
                ew,
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
    let (c, m) = py
        .detach(|| {
            guarded(|| {
                install(threads, || {
                    knn::coherence_candidates(
                        &r,
                        h,
                        w,
                        eh,
                        ew,
                        table.as_ref(),
                        patch_size,
                        wrap,
                        false,
                    )
                })
            })
        })
        .map_err(to_py)?;
    let out = Array4::from_shape_vec((h, w, m, 2), rowcol(&c, ew)).expect("candidate shape");
    Ok(out.into_pyarray(py))
}

type VoteOut<'py> = (Bound<'py, PyArray3<f32>>, Bound<'py, PyArray2<f32>>);

#[pyfunction]
#[pyo3(name = "vote", signature = (source, field, *, patch_size, weights=None, threads=None, mean_shift=0))]
pub fn vote_py<'py>(
    py: Python<'py>,
    source: PyReadonlyArray3<'py, f32>,
    field: PyReadonlyArray3<'py, i32>,
    patch_size: usize,
    weights: Option<PyReadonlyArray2<'py, f32>>,
    threads: Option<usize>,
    mean_shift: usize,
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
    let v = py
        .detach(|| {
            guarded(|| {
                install(threads, || {
                    vote::vote_mode(&src, &idx, h, w, wts, patch_size, mean_shift)
                })
            })
        })
        .map_err(to_py)?;
    let img = Array3::from_shape_vec((h, w, src.c), v.image).expect("vote shape");
    let wt = Array2::from_shape_vec((h, w), v.weight).expect("weight shape");
    Ok((img.into_pyarray(py), wt.into_pyarray(py)))
}
