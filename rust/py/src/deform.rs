//! Bindings of `phloem_core::deform` for `phloem.branching.render`'s fragment warp.

use numpy::{PyArray2, PyReadonlyArray2};
use phloem_core::deform::{self, Placement};
use phloem_core::error::invalid;
use pyo3::prelude::*;

use crate::call::run;
use crate::convert::{array, points};
use crate::errors::{not_contiguous, to_py};

/// The fragment's sampling maps.
type Maps<'py> = (Bound<'py, PyArray2<f32>>, Bound<'py, PyArray2<f32>>, f64);

/// Source `(x, y)` maps of every pixel of a target fragment's crop (`disk`'s shape, top-left
/// at `origin` = (row, col)), deformed so that `points` (`(K, 2)` `(x, y)`) move by
/// `displacement` (`(K, 2)`), and the scale `α` the field was applied with (see
/// `phloem_core::deform`).
#[pyfunction]
#[pyo3(
    name = "fragment_maps",
    signature = (disk, origin, centre, points, displacement, radius, rigid, source_centre)
)]
#[allow(clippy::too_many_arguments)]
pub fn fragment_maps_py<'py>(
    py: Python<'py>,
    disk: PyReadonlyArray2<'py, bool>,
    origin: (i64, i64),
    centre: (f64, f64),
    points: PyReadonlyArray2<'py, f64>,
    displacement: PyReadonlyArray2<'py, f64>,
    radius: f64,
    rigid: PyReadonlyArray2<'py, f64>,
    source_centre: (f64, f64),
) -> PyResult<Maps<'py>> {
    let shape = disk.as_array().dim();
    let mask = disk.as_slice().map_err(not_contiguous("disk"))?;
    let pts = self::points("points", &points)?;
    let d = self::points("displacement", &displacement)?;
    let m = rigid.as_array();
    if m.dim() != (2, 2) {
        return Err(to_py(invalid(
            "rigid",
            format!("expected shape (2, 2), got {:?}", m.dim()),
        )));
    }
    let placement = Placement {
        shape,
        origin,
        centre: [centre.0, centre.1],
        points: &pts,
        displacement: &d,
        radius,
        rigid: [[m[[0, 0]], m[[0, 1]]], [m[[1, 0]], m[[1, 1]]]],
        source_centre: [source_centre.0, source_centre.1],
        disk: mask,
    };
    // One fragment is small work: one thread, as the render paints fragments side by side.
    let maps = run(py, Some(1), None, |_| deform::fragment_maps(&placement))?;
    Ok((
        array(py, shape, maps.x),
        array(py, shape, maps.y),
        maps.alpha,
    ))
}
