//! Bindings of `phloem_core::colonisation` for `phloem.branching.growth`'s density map.

use numpy::{PyReadonlyArray1, PyReadonlyArray2, PyReadwriteArray2};
use phloem_core::colonisation::{self, DensityMap};
use pyo3::prelude::*;

use crate::call::run;
use crate::convert;
use crate::errors::not_contiguous;

/// Stamps the polyline `points` (vertices `first, …` of branch `branch`, with `thickness`) into
/// the `density` map and its owner maps in place; returns how much the map's sum grew.
#[pyfunction]
#[pyo3(
    name = "density_stamp",
    signature = (density, owner_branch, owner_vertex, points, thickness, branch, first, rho)
)]
#[allow(clippy::too_many_arguments)]
pub fn density_stamp_py<'py>(
    py: Python<'py>,
    mut density: PyReadwriteArray2<'py, f32>,
    mut owner_branch: PyReadwriteArray2<'py, i32>,
    mut owner_vertex: PyReadwriteArray2<'py, i32>,
    points: PyReadonlyArray2<'py, f64>,
    thickness: PyReadonlyArray1<'py, f64>,
    branch: i32,
    first: i32,
    rho: f64,
) -> PyResult<f64> {
    let (height, width) = density.as_array().dim();
    let pts = convert::points("points", &points)?;
    let th = thickness.as_slice().map_err(not_contiguous("thickness"))?;
    let mut map = DensityMap {
        density: density.as_slice_mut().map_err(not_contiguous("density"))?,
        owner_branch: owner_branch
            .as_slice_mut()
            .map_err(not_contiguous("owner_branch"))?,
        owner_vertex: owner_vertex
            .as_slice_mut()
            .map_err(not_contiguous("owner_vertex"))?,
        height,
        width,
    };
    // a large window is split between the pool's threads
    run(py, None, None, move |_| {
        colonisation::stamp(&mut map, &pts, th, branch, first, rho)
    })
}
