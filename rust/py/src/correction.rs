//! Binding of `phloem_core::correction` for `phloem.leaves.correction`.

use numpy::{PyArray3, PyReadonlyArray2, PyReadonlyArray3};
use phloem_core::correction::{guided_quilt, QuiltParams};
use phloem_core::error::invalid;
use pyo3::prelude::*;

use crate::call::run;
use crate::convert::{array, image};
use crate::errors::{not_contiguous, to_py};

#[pyfunction]
#[pyo3(name = "guided_quilt", signature = (target, source, hole, field, *, block, rim, radius, bias, alpha_known))]
#[allow(clippy::too_many_arguments)]
pub fn guided_quilt_py<'py>(
    py: Python<'py>,
    target: PyReadonlyArray3<'py, f32>,
    source: PyReadonlyArray3<'py, f32>,
    hole: PyReadonlyArray2<'py, bool>,
    field: PyReadonlyArray3<'py, f32>,
    block: usize,
    rim: usize,
    radius: usize,
    bias: f32,
    alpha_known: bool,
) -> PyResult<Bound<'py, PyArray3<i32>>> {
    let tgt = image("target", &target)?;
    let src = image("source", &source)?;
    if hole.as_array().dim() != (tgt.h, tgt.w) {
        return Err(to_py(invalid(
            "hole",
            format!("expected shape ({}, {}) like target", tgt.h, tgt.w),
        )));
    }
    let holes = hole.as_slice().map_err(not_contiguous("hole"))?;
    let f = field.as_slice().map_err(not_contiguous("field"))?;
    let params = QuiltParams {
        block,
        rim,
        radius,
        bias,
        alpha_known,
    };
    // One worker: the loop is sequential (each block depends on the ones before it).
    let pos = run(py, Some(1), None, |_| {
        guided_quilt(&tgt, &src, holes, f, &params)
    })?;
    Ok(array(py, (tgt.h, tgt.w, 2), pos))
}
