//! Bindings of `phloem_core::tps` for `phloem.leaves.registration`.

use numpy::{PyArray1, PyArray2, PyArray3, PyReadonlyArray2, PyReadonlyArray3};
use phloem_core::error::invalid;
use phloem_core::tps::{self, Params, Side};
use pyo3::prelude::*;

use crate::call::run;
use crate::convert::{array, image, points};
use crate::errors::{not_contiguous, opt_slice, to_py};

fn pairs(v: &[[f32; 2]]) -> Vec<f32> {
    v.iter().flat_map(|p| [p[0], p[1]]).collect()
}

/// The output of `tps_register`: forward and inverse displacement fields, the matches (−1 for
/// an outlier), the spline of the forward map evaluated at the fixed points, the number of
/// stiffening refits and the smallest Jacobian determinant.
type Registered<'py> = (
    Bound<'py, PyArray3<f32>>,
    Bound<'py, PyArray3<f32>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray2<f64>>,
    usize,
    f64,
);

#[pyfunction]
#[pyo3(name = "tps_register", signature = (fixed_points, moving_points, fixed_mask, moving_mask, *, rate, iterations, final_ratio, lambda1, lambda2, step, threads))]
#[allow(clippy::too_many_arguments)]
pub fn tps_register_py<'py>(
    py: Python<'py>,
    fixed_points: PyReadonlyArray2<'py, f64>,
    moving_points: PyReadonlyArray2<'py, f64>,
    fixed_mask: PyReadonlyArray2<'py, bool>,
    moving_mask: PyReadonlyArray2<'py, bool>,
    rate: f64,
    iterations: usize,
    final_ratio: f64,
    lambda1: f64,
    lambda2: f64,
    step: usize,
    threads: Option<usize>,
) -> PyResult<Registered<'py>> {
    let fx = points("fixed_points", &fixed_points)?;
    let mv = points("moving_points", &moving_points)?;
    let fm = opt_slice("fixed_mask", Some(&fixed_mask))?;
    let mm = opt_slice("moving_mask", Some(&moving_mask))?;
    let fs = Side {
        size: fixed_mask.as_array().dim(),
        mask: fm,
    };
    let ms = Side {
        size: moving_mask.as_array().dim(),
        mask: mm,
    };
    let params = Params {
        rate,
        iterations,
        final_ratio,
        lambda1,
        lambda2,
        ..Params::default()
    };
    let d = run(py, threads, None, |_| {
        tps::register(&fx, &mv, &params, fs, ms, step)
    })?;
    let at: Vec<f64> = fx.iter().flat_map(|&p| d.forward_tps.eval(p)).collect();
    let matches: Vec<i64> = d
        .rpm
        .matches
        .iter()
        .map(|m| m.map_or(-1, |j| j as i64))
        .collect();
    let (hf, wf) = fs.size;
    let (hm, wm) = ms.size;
    Ok((
        array(py, (hf, wf, 2), pairs(&d.forward)),
        array(py, (hm, wm, 2), pairs(&d.inverse)),
        array(py, matches.len(), matches),
        array(py, (fx.len(), 2), at),
        d.refits,
        d.min_det,
    ))
}

#[pyfunction]
#[pyo3(name = "tps_sample", signature = (image, field, *, threads))]
pub fn tps_sample_py<'py>(
    py: Python<'py>,
    image: PyReadonlyArray3<'py, f32>,
    field: PyReadonlyArray3<'py, f32>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let img = self::image("image", &image)?;
    let (h, w, two) = field.as_array().dim();
    if two != 2 {
        return Err(to_py(invalid(
            "field",
            format!("expected shape (H, W, 2), got ({h}, {w}, {two})"),
        )));
    }
    let f: Vec<[f32; 2]> = field
        .as_slice()
        .map_err(not_contiguous("field"))?
        .chunks_exact(2)
        .map(|p| [p[0], p[1]])
        .collect();
    let out = run(py, threads, None, |_| tps::sample(&img, &f, h, w))?;
    Ok(array(py, (h, w, img.c), out))
}
