//! Bindings of `phloem_core::growth` for `phloem.branching.growth`'s step.

use numpy::{PyArray1, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use phloem_core::colonisation::{DensityView, Rays, Skip};
use phloem_core::error::invalid;
use phloem_core::growth::{self, Candidates, Colonisation, Step, Tip};
use pyo3::prelude::*;

use crate::convert::{array, points};
use crate::errors::{not_contiguous, opt_slice, to_py};

type DensityMaps<'py> = (
    PyReadonlyArray2<'py, f32>,
    PyReadonlyArray2<'py, i32>,
    PyReadonlyArray2<'py, i32>,
);

/// The chosen candidates' indices and qualities.
type Chosen<'py> = (Bound<'py, PyArray1<i64>>, Bound<'py, PyArray1<f64>>);

/// The `count` best valid candidates of one growth step and their qualities: `quality` (the
/// bending model's `log Q`, `(C,)`) less `log(D + eps)` and `log(G + eps)` read along each
/// candidate's ray (`ray_of`, into `directions`), valid when its path (`relative`, `(C, m, 2)`,
/// turned by `(cos, sin)` and moved to `tip`) stays in the `height × width` image and crosses
/// none of `segments`. `density` = `(map, owner_branch, owner_vertex)` or None; `skip` =
/// `(branch, vertex, near, floor)`; `border_rho` counts the image border as structure.
#[pyfunction]
#[pyo3(
    name = "growth_choose",
    signature = (
        quality, relative, ray_of, tip, cos, sin, height, width, directions, length, samples,
        density, skip, border_rho, guide, segments, count, eps
    )
)]
#[allow(clippy::too_many_arguments)]
pub fn growth_choose_py<'py>(
    py: Python<'py>,
    quality: PyReadonlyArray1<'py, f64>,
    relative: PyReadonlyArray3<'py, f64>,
    ray_of: PyReadonlyArray1<'py, i64>,
    tip: (f64, f64),
    cos: f64,
    sin: f64,
    height: usize,
    width: usize,
    directions: PyReadonlyArray2<'py, f64>,
    length: f64,
    samples: usize,
    density: Option<DensityMaps<'py>>,
    skip: Option<(i32, i32, i32, f64)>,
    border_rho: Option<f64>,
    guide: Option<PyReadonlyArray2<'py, f64>>,
    segments: PyReadonlyArray2<'py, f64>,
    count: usize,
    eps: f64,
) -> PyResult<Chosen<'py>> {
    let (_, m, two) = relative.as_array().dim();
    if two != 2 {
        return Err(to_py(invalid(
            "relative",
            format!("expected (C, m, 2) points, got (C, m, {two})"),
        )));
    }
    let rays_of: Vec<usize> = ray_of
        .as_slice()
        .map_err(not_contiguous("ray_of"))?
        .iter()
        .map(|&r| usize::try_from(r).unwrap_or(usize::MAX))
        .collect();
    let dirs = points("directions", &directions)?;
    let mut view = None;
    if let Some((d, b, v)) = &density {
        for (name, dims) in [
            ("density", d.as_array().dim()),
            ("owner_branch", b.as_array().dim()),
            ("owner_vertex", v.as_array().dim()),
        ] {
            if dims != (height, width) {
                return Err(to_py(invalid(
                    name,
                    format!("expected a {height}×{width} map, got {}×{}", dims.0, dims.1),
                )));
            }
        }
        view = Some(DensityView {
            density: d.as_slice().map_err(not_contiguous("density"))?,
            owner_branch: b.as_slice().map_err(not_contiguous("owner_branch"))?,
            owner_vertex: v.as_slice().map_err(not_contiguous("owner_vertex"))?,
            height,
            width,
        });
    }
    let step = Step {
        candidates: Candidates {
            relative: relative.as_slice().map_err(not_contiguous("relative"))?,
            m,
            ray_of: &rays_of,
        },
        tip: Tip {
            point: [tip.0, tip.1],
            cos,
            sin,
        },
        shape: (height, width),
        rays: Rays {
            tip: [tip.0, tip.1],
            directions: &dirs,
            length,
            samples,
        },
        colonisation: view.map(|view| Colonisation {
            view,
            skip: skip.map(|(branch, vertex, near, floor)| Skip {
                branch,
                vertex,
                near,
                floor,
            }),
            border_rho,
        }),
        guide: opt_slice("guide", guide.as_ref())?,
        segments: segments.as_slice().map_err(not_contiguous("segments"))?,
        eps,
    };
    let q = quality.as_slice().map_err(not_contiguous("quality"))?;
    let (chosen, qualities) = py
        .detach(|| growth::choose(&step, q, count))
        .map_err(to_py)?;
    let idx: Vec<i64> = chosen.into_iter().map(|i| i as i64).collect();
    Ok((
        array(py, idx.len(), idx),
        array(py, qualities.len(), qualities),
    ))
}
