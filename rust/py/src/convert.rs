//! Array conversion shared by the bindings: NumPy arrays in, core types out, and back.

use ndarray::{Array, Dimension, StrideShape};
use numpy::{Element, IntoPyArray, PyArray, PyReadonlyArray2, PyReadonlyArray3};
use phloem_core::error::invalid;
use phloem_core::image::Image;
use phloem_core::patch::NONE;
use pyo3::prelude::*;

use crate::errors::{not_contiguous, to_py};

/// An `(H, W, C)` float32 array as a core [`Image`]; errors name `name`.
pub fn image<'a>(name: &'static str, a: &'a PyReadonlyArray3<'_, f32>) -> PyResult<Image<'a>> {
    let (h, w, c) = a.as_array().dim();
    Image::new(name, a.as_slice().map_err(not_contiguous(name))?, h, w, c).map_err(to_py)
}

/// An `(N, 2)` float64 array as `(x, y)` points; errors name `name`.
pub fn points(name: &'static str, a: &PyReadonlyArray2<'_, f64>) -> PyResult<Vec<[f64; 2]>> {
    let (n, two) = a.as_array().dim();
    if two != 2 {
        return Err(to_py(invalid(
            name,
            format!("expected shape (N, 2), got ({n}, {two})"),
        )));
    }
    Ok(a.as_slice()
        .map_err(not_contiguous(name))?
        .chunks_exact(2)
        .map(|p| [p[0], p[1]])
        .collect())
}

/// Flat indices into an image `w` pixels wide as (row, col) pairs, [`NONE`] as `(-1, -1)`.
pub fn rowcol(idx: &[u32], w: usize) -> Vec<i32> {
    idx.iter()
        .flat_map(|&i| {
            if i == NONE {
                [-1, -1]
            } else {
                [(i as usize / w) as i32, (i as usize % w) as i32]
            }
        })
        .collect()
}

/// The inverse of [`rowcol`]: (row, col) pairs to flat indices into an `h × w` `image`
/// (the word the error uses), `(-1, -1)` to [`NONE`] where `missing` allows it; any other pair
/// outside is an error naming `name`.
pub fn flat(
    name: &'static str,
    rc: &[i32],
    (h, w): (usize, usize),
    image: &str,
    missing: bool,
) -> PyResult<Vec<u32>> {
    rc.chunks_exact(2)
        .map(|p| {
            if missing && p[0] == -1 && p[1] == -1 {
                Ok(NONE)
            } else if p[0] < 0 || p[1] < 0 || p[0] as usize >= h || p[1] as usize >= w {
                Err(to_py(invalid(
                    name,
                    format!("({}, {}) is outside the {h}×{w} {image}", p[0], p[1]),
                )))
            } else {
                Ok((p[0] as usize * w + p[1] as usize) as u32)
            }
        })
        .collect()
}

/// A result vector as a NumPy array of `shape` (which the core guarantees it fills).
pub fn array<T: Element, D: Dimension>(
    py: Python<'_>,
    shape: impl Into<StrideShape<D>>,
    data: Vec<T>,
) -> Bound<'_, PyArray<T, D>> {
    Array::from_shape_vec(shape, data)
        .expect("the core's output has the shape it promises")
        .into_pyarray(py)
}
