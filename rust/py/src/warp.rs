//! Bindings of `phloem_core::mvc` for `phloem.warp`.

use numpy::{PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use phloem_core::image::Image;
use phloem_core::mvc::{self, Point};
use pyo3::prelude::*;

use crate::call::run;
use crate::convert::{array, image, points};
use crate::errors::{not_contiguous, opt_slice};

fn images<'a>(name: &'static str, a: &'a [PyReadonlyArray3<'_, f32>]) -> PyResult<Vec<Image<'a>>> {
    a.iter().map(|s| image(name, s)).collect()
}

fn contours(name: &'static str, a: &[PyReadonlyArray2<'_, f64>]) -> PyResult<Vec<Vec<Point>>> {
    a.iter().map(|c| points(name, c)).collect()
}

#[pyfunction]
#[pyo3(name = "mvc_weights", signature = (polygon, points, *, threads))]
pub fn mvc_weights_py<'py>(
    py: Python<'py>,
    polygon: PyReadonlyArray2<'py, f64>,
    points: PyReadonlyArray2<'py, f64>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let poly = self::points("polygon", &polygon)?;
    let pts = self::points("points", &points)?;
    let w = run(py, threads, None, |_| {
        mvc::weights_many(&poly, &pts, "polygon", "points")
    })?;
    Ok(array(py, (pts.len(), poly.len()), w))
}

#[pyfunction]
#[pyo3(name = "mvc_warp", signature = (sources, source_contours, target_contour, size, *, region, threads))]
pub fn mvc_warp_py<'py>(
    py: Python<'py>,
    sources: Vec<PyReadonlyArray3<'py, f32>>,
    source_contours: Vec<PyReadonlyArray2<'py, f64>>,
    target_contour: PyReadonlyArray2<'py, f64>,
    size: (usize, usize),
    region: Option<PyReadonlyArray2<'py, bool>>,
    threads: Option<usize>,
) -> PyResult<Vec<Bound<'py, PyArray3<f32>>>> {
    let reg = opt_slice("region", region.as_ref())?;
    let srcs = images("sources", &sources)?;
    let conts = contours("source_contours", &source_contours)?;
    let target = points("target_contour", &target_contour)?;
    let refs: Vec<&[Point]> = conts.iter().map(Vec::as_slice).collect();
    let (h, w) = size;
    let out = run(py, threads, None, |_| {
        mvc::warp(&srcs, &refs, &target, h, w, reg)
    })?;
    let c = srcs[0].c;
    Ok(out
        .into_iter()
        .map(|img| array(py, (h, w, c), img))
        .collect())
}

#[pyfunction]
#[pyo3(name = "mvc_combine", signature = (sources, source_contours, target_contour, weights, size, *, region, threads))]
pub fn mvc_combine_py<'py>(
    py: Python<'py>,
    sources: Vec<PyReadonlyArray3<'py, f32>>,
    source_contours: Vec<PyReadonlyArray2<'py, f64>>,
    target_contour: PyReadonlyArray2<'py, f64>,
    weights: PyReadonlyArray1<'py, f64>,
    size: (usize, usize),
    region: Option<PyReadonlyArray2<'py, bool>>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let reg = opt_slice("region", region.as_ref())?;
    let srcs = images("sources", &sources)?;
    let conts = contours("source_contours", &source_contours)?;
    let target = points("target_contour", &target_contour)?;
    let wts = weights.as_slice().map_err(not_contiguous("weights"))?;
    let refs: Vec<&[Point]> = conts.iter().map(Vec::as_slice).collect();
    let (h, w) = size;
    let out = run(py, threads, None, |_| {
        mvc::warp_combine(&srcs, &refs, &target, wts, h, w, reg)
    })?;
    let c = srcs.first().map_or(0, |s| s.c);
    Ok(array(py, (h, w, c), out))
}
