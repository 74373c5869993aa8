//! Bindings of `phloem_core::{poisson, field}` for `phloem.blend`.

use numpy::{PyArray3, PyReadonlyArray2, PyReadonlyArray3};
use phloem_core::field::{self, FieldParams};
use phloem_core::poisson::{self, BlendInput, BlendParams, Mode};
use pyo3::prelude::*;

use crate::call::run;
use crate::convert::{array, image};
use crate::errors::{not_contiguous, opt_slice, to_py};

type Out<'py> = (Bound<'py, PyArray3<f32>>, usize, f64);

#[pyfunction]
#[pyo3(name = "seamless", signature = (src, dst, mask, offset, *, mixed, tol, max_iterations, fixed, threads, labels=None))]
pub fn seamless_py<'py>(
    py: Python<'py>,
    src: PyReadonlyArray3<'py, f32>,
    dst: PyReadonlyArray3<'py, f32>,
    mask: PyReadonlyArray2<'py, bool>,
    offset: (i64, i64),
    mixed: bool,
    tol: f64,
    max_iterations: usize,
    fixed: Option<PyReadonlyArray2<'py, bool>>,
    threads: Option<usize>,
    labels: Option<PyReadonlyArray2<'py, i32>>,
) -> PyResult<Out<'py>> {
    let input = BlendInput {
        src: image("src", &src)?,
        dst: image("dst", &dst)?,
        mask: mask.as_slice().map_err(not_contiguous("mask"))?,
        offset,
        fixed: opt_slice("fixed", fixed.as_ref())?,
        labels: opt_slice("labels", labels.as_ref())?,
    };
    let params = BlendParams {
        mode: if mixed { Mode::Mixed } else { Mode::Normal },
        tol,
        max_iterations,
    };
    let b = run(py, threads, None, |_| poisson::seamless(&input, &params))?;
    let (h, w, c) = (input.dst.h, input.dst.w, input.dst.c);
    Ok((array(py, (h, w, c), b.image), b.iterations, b.residual))
}

#[pyfunction]
#[pyo3(name = "interpolate_field", signature = (region, points, values, *, tol, max_iterations, threads))]
pub fn interpolate_field_py<'py>(
    py: Python<'py>,
    region: PyReadonlyArray2<'py, bool>,
    points: PyReadonlyArray2<'py, i64>,
    values: PyReadonlyArray2<'py, f64>,
    tol: f64,
    max_iterations: usize,
    threads: Option<usize>,
) -> PyResult<Out<'py>> {
    let (h, w) = region.as_array().dim();
    let (k, two) = points.as_array().dim();
    if two != 2 {
        return Err(to_py(phloem_core::error::invalid(
            "points",
            format!("expected shape (K, 2), got ({k}, {two})"),
        )));
    }
    let (kv, d) = values.as_array().dim();
    if kv != k {
        return Err(to_py(phloem_core::error::invalid(
            "values",
            format!("expected {k} rows like points, got {kv}"),
        )));
    }
    let pts: Vec<[i64; 2]> = points
        .as_slice()
        .map_err(not_contiguous("points"))?
        .chunks_exact(2)
        .map(|p| [p[0], p[1]])
        .collect();
    let reg = region.as_slice().map_err(not_contiguous("region"))?;
    let vals = values.as_slice().map_err(not_contiguous("values"))?;
    let params = FieldParams {
        tol,
        max_iterations,
    };
    let f = run(py, threads, None, |_| {
        field::interpolate_field(reg, h, w, &pts, vals, d, &params)
    })?;
    Ok((array(py, (h, w, d), f.values), f.iterations, f.residual))
}
