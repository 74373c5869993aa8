//! Bindings of `phloem_core::tbn` for `phloem.texture.by_numbers`.

use numpy::{PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use phloem_core::error::invalid;
use phloem_core::tbn::{self, pyramid, Init, Selection, TbnInput, TbnParams};
use pyo3::prelude::*;

use crate::call::run;
use crate::convert::{array, flat, image, rowcol};
use crate::errors::{not_contiguous, opt_slice, to_py};

fn labels(name: &'static str, a: &PyReadonlyArray2<'_, i32>) -> PyResult<Vec<u32>> {
    a.as_slice()
        .map_err(not_contiguous(name))?
        .iter()
        .map(|&v| {
            u32::try_from(v).map_err(|_| {
                to_py(invalid(
                    name,
                    format!("expected compact labels >= 0, got {v}"),
                ))
            })
        })
        .collect()
}

#[pyfunction]
#[pyo3(name = "by_numbers", signature = (exemplar, labels_in, labels_out, *, patch_size, k, label_weight, levels, iterations, init, wrap, tileable, seed, selection, composite, stand_in_weight, seam_channels, weights, threads, progress))]
pub fn by_numbers_py<'py>(
    py: Python<'py>,
    exemplar: PyReadonlyArray3<'py, f32>,
    labels_in: PyReadonlyArray2<'py, i32>,
    labels_out: PyReadonlyArray2<'py, i32>,
    patch_size: usize,
    k: usize,
    label_weight: f32,
    levels: Option<usize>,
    iterations: usize,
    init: &str,
    wrap: bool,
    tileable: bool,
    seed: u64,
    selection: &str,
    composite: usize,
    stand_in_weight: f32,
    seam_channels: usize,
    weights: Option<PyReadonlyArray1<'py, f32>>,
    threads: Option<usize>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyArray3<i32>>> {
    let ex = image("exemplar", &exemplar)?;
    let (ih, iw) = labels_in.as_array().dim();
    if (ih, iw) != (ex.h, ex.w) {
        return Err(to_py(invalid(
            "labels_in",
            format!(
                "expected shape ({}, {}) to match the exemplar, got ({ih}, {iw})",
                ex.h, ex.w
            ),
        )));
    }
    let (oh, ow) = labels_out.as_array().dim();
    let la = labels("labels_in", &labels_in)?;
    let lb = labels("labels_out", &labels_out)?;
    let init = match init {
        "smart" => Init::Smart,
        "random" => Init::Random,
        other => {
            return Err(to_py(invalid(
                "init",
                format!("expected 'smart' or 'random', got {other:?}"),
            )))
        }
    };
    let selection = match selection {
        "average" => Selection::Average,
        "medoid" => Selection::Medoid,
        "hybrid" => Selection::Hybrid,
        other => {
            return Err(to_py(invalid(
                "selection",
                format!("expected 'medoid', 'hybrid' or 'average', got {other:?}"),
            )))
        }
    };
    let input = TbnInput {
        exemplar: ex,
        weights: opt_slice("weights", weights.as_ref())?,
        labels_in: &la,
        labels_out: &lb,
        out_h: oh,
        out_w: ow,
    };
    let params = TbnParams {
        patch_size,
        k,
        label_weight,
        levels,
        iterations,
        init,
        selection,
        composite,
        stand_in_weight,
        seam_channels,
        wrap,
        tileable,
        random_search: true,
        seed,
    };
    let t = run(py, threads, progress.as_ref(), |reports| {
        let report = reports.map(|r| move |done, total| r.push(done, total));
        let report = report.as_ref().map(|f| f as &(dyn Fn(usize, usize) + Sync));
        tbn::by_numbers(&input, &params, report)
    })?;
    Ok(array(py, (t.h, t.w, 2), rowcol(&t.refs, ex.w)))
}

#[pyfunction]
#[pyo3(name = "tbn_upsample", signature = (refs, out_shape, exemplar_shape, *, wrap))]
pub fn tbn_upsample_py<'py>(
    py: Python<'py>,
    refs: PyReadonlyArray3<'py, i32>,
    out_shape: (usize, usize),
    exemplar_shape: (usize, usize),
    wrap: bool,
) -> PyResult<Bound<'py, PyArray3<i32>>> {
    let (ch, cw, _) = refs.as_array().dim();
    let (oh, ow) = out_shape;
    let (eh, ew) = exemplar_shape;
    let (os, es) = steps(ch, cw, oh, ow, eh, ew)?;
    let coarse = flat(
        "refs",
        refs_slice(&refs)?,
        (es.ch(), es.cw()),
        "exemplar",
        false,
    )?;
    let fine = pyramid::upsample_refs(&coarse, &os, &es, wrap);
    Ok(array(py, (oh, ow, 2), rowcol(&fine, ew)))
}

#[pyfunction]
#[pyo3(name = "tbn_downsample", signature = (refs, exemplar_shape))]
pub fn tbn_downsample_py<'py>(
    py: Python<'py>,
    refs: PyReadonlyArray3<'py, i32>,
    exemplar_shape: (usize, usize),
) -> PyResult<Bound<'py, PyArray3<i32>>> {
    let (oh, ow, _) = refs.as_array().dim();
    let (eh, ew) = exemplar_shape;
    let (os, es) = steps(oh.div_ceil(2), ow.div_ceil(2), oh, ow, eh, ew)?;
    let fine = flat("refs", refs_slice(&refs)?, (eh, ew), "exemplar", false)?;
    let coarse = pyramid::downsample_refs(&fine, &os, &es);
    Ok(array(py, (os.ch(), os.cw(), 2), rowcol(&coarse, es.cw())))
}

fn refs_slice<'a>(refs: &'a PyReadonlyArray3<'_, i32>) -> PyResult<&'a [i32]> {
    refs.as_slice().map_err(not_contiguous("refs"))
}

/// The one-level steps of the pyramid `level_sizes(_, 2)` for output and exemplar.
fn steps(
    ch: usize,
    cw: usize,
    oh: usize,
    ow: usize,
    eh: usize,
    ew: usize,
) -> PyResult<(pyramid::Step, pyramid::Step)> {
    let half = |n: usize| pyramid::level_sizes(n, 2)[1];
    if (ch, cw) != (half(oh), half(ow)) {
        return Err(to_py(invalid(
            "refs",
            format!(
                "expected shape ({}, {}, 2) for a {oh}×{ow} output, got ({ch}, {cw}, 2)",
                half(oh),
                half(ow)
            ),
        )));
    }
    Ok((
        pyramid::Step::new(oh, ow, half(oh), half(ow)),
        pyramid::Step::new(eh, ew, half(eh), half(ew)),
    ))
}
