//! Bindings of `phloem_core::strokes` for `phloem.strokes`.

use numpy::{PyArray2, PyArray3, PyReadonlyArray2, PyReadonlyArray3};
use phloem_core::error::invalid;
use phloem_core::strokes::{self, Piece, PieceSpec};
use pyo3::prelude::*;

use crate::call::run;
use crate::convert::{array, image};
use crate::errors::{not_contiguous, to_py};

/// Columns of a spec row: target x, y, target tangent x, y, source x, y, source tangent x, y,
/// half length, most half width, target half width (0: the source's) and its slope along the
/// stroke.
const SPEC_COLUMNS: usize = 12;

fn specs(a: &PyReadonlyArray2<'_, f64>) -> PyResult<Vec<PieceSpec>> {
    let (n, k) = a.as_array().dim();
    if k != SPEC_COLUMNS {
        return Err(to_py(invalid(
            "specs",
            format!("expected shape (N, {SPEC_COLUMNS}), got ({n}, {k})"),
        )));
    }
    Ok(a.as_slice()
        .map_err(not_contiguous("specs"))?
        .chunks_exact(SPEC_COLUMNS)
        .map(|r| PieceSpec {
            target: [r[0], r[1]],
            target_tangent: [r[2], r[3]],
            source: [r[4], r[5]],
            source_tangent: [r[6], r[7]],
            half_length: r[8],
            max_half_width: r[9],
            target_half_width: r[10],
            target_half_width_slope: r[11],
        })
        .collect())
}

type PieceOut<'py> = (
    (i64, i64),
    Bound<'py, PyArray3<f32>>,
    Bound<'py, PyArray2<bool>>,
    (f64, f64),
);

#[pyfunction]
#[pyo3(name = "stroke_pieces", signature = (source, specs, *, threads))]
pub fn stroke_pieces_py<'py>(
    py: Python<'py>,
    source: PyReadonlyArray3<'py, f32>,
    specs: PyReadonlyArray2<'py, f64>,
    threads: Option<usize>,
) -> PyResult<Vec<PieceOut<'py>>> {
    let src = image("source", &source)?;
    let sp = self::specs(&specs)?;
    let pieces = run(py, threads, None, |_| strokes::fetch(&src, &sp))?;
    Ok(pieces
        .into_iter()
        .map(|p: Piece| {
            (
                (p.y0, p.x0),
                array(py, (p.h, p.w, 4), p.rgba),
                array(py, (p.h, p.w), p.support),
                (p.widths[0], p.widths[1]),
            )
        })
        .collect())
}

#[pyfunction]
#[pyo3(name = "stroke_pair_energies", signature = (source, specs, pairs, *, threads))]
pub fn stroke_pair_energies_py(
    py: Python<'_>,
    source: PyReadonlyArray3<'_, f32>,
    specs: PyReadonlyArray2<'_, f64>,
    pairs: PyReadonlyArray2<'_, i64>,
    threads: Option<usize>,
) -> PyResult<Vec<f64>> {
    let src = image("source", &source)?;
    let sp = self::specs(&specs)?;
    let (n, two) = pairs.as_array().dim();
    if two != 2 {
        return Err(to_py(invalid(
            "pairs",
            format!("expected shape (N, 2), got ({n}, {two})"),
        )));
    }
    let pr = pairs
        .as_slice()
        .map_err(not_contiguous("pairs"))?
        .chunks_exact(2)
        .map(|p| match (usize::try_from(p[0]), usize::try_from(p[1])) {
            (Ok(i), Ok(j)) => Ok((i, j)),
            _ => Err(to_py(invalid(
                "pairs",
                format!("expected piece indices, got ({}, {})", p[0], p[1]),
            ))),
        })
        .collect::<PyResult<Vec<_>>>()?;
    run(py, threads, None, |_| {
        let pieces = strokes::fetch(&src, &sp)?;
        strokes::pair_energies(&pieces, &pr)
    })
}
