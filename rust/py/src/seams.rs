//! Bindings of `phloem_core::{maxflow, seams}` for `phloem.seams`.

use numpy::{PyArray2, PyReadonlyArray2, PyReadonlyArray3};
use phloem_core::error::invalid;
use phloem_core::maxflow::{EdgeLayout, GridGraph, Method};
use phloem_core::seams::{self, SeamCost, SeamInput};
use pyo3::prelude::*;

use crate::call::run;
use crate::convert::{array, image};
use crate::errors::{not_contiguous, opt_slice, to_py};

type FlowOut<'py> = (f64, Bound<'py, PyArray2<bool>>, &'static str);

/// Returns the flow, the sink side and the method that ran (`"planar"` or `"bk"`); `method`
/// `"auto"` picks the planar dual shortest path where it applies, `"planar"` and `"bk"`
/// force one (tests compare them).
#[pyfunction]
#[pyo3(name = "grid_maxflow", signature = (source, sink, edges, *, connectivity, directed, threads, method))]
#[allow(clippy::too_many_arguments)]
pub fn grid_maxflow_py<'py>(
    py: Python<'py>,
    source: PyReadonlyArray2<'py, f32>,
    sink: PyReadonlyArray2<'py, f32>,
    edges: PyReadonlyArray3<'py, f32>,
    connectivity: usize,
    directed: bool,
    threads: Option<usize>,
    method: &str,
) -> PyResult<FlowOut<'py>> {
    let method = match method {
        "auto" => None,
        "planar" => Some(Method::Planar),
        "bk" => Some(Method::BoykovKolmogorov),
        other => {
            return Err(to_py(invalid(
                "method",
                format!("expected 'auto', 'planar' or 'bk', got {other:?}"),
            )))
        }
    };
    let (h, w) = source.as_array().dim();
    let (eh, ew, _) = edges.as_array().dim();
    if sink.as_array().dim() != (h, w) || (eh, ew) != (h, w) {
        return Err(to_py(invalid(
            if (eh, ew) == (h, w) { "sink" } else { "edges" },
            format!("expected the shape of source ({h}, {w}) in the first two axes"),
        )));
    }
    let s = source.as_slice().map_err(not_contiguous("source"))?;
    let t = sink.as_slice().map_err(not_contiguous("sink"))?;
    let e = edges.as_slice().map_err(not_contiguous("edges"))?;
    let layout = if directed {
        EdgeLayout::Directed
    } else {
        EdgeLayout::Symmetric
    };
    let (flow, side, used) = run(py, threads, None, |_| {
        let mut g = GridGraph::new(h, w, connectivity)?;
        g.set_edges("edges", e, layout)?;
        g.set_terminals(s, t)?;
        let flow = match method {
            None => g.maxflow(),
            Some(m) => g.maxflow_with(m)?,
        };
        phloem_core::cancel::check()?;
        let used = match g.method() {
            Some(Method::Planar) => "planar",
            _ => "bk",
        };
        Ok((flow, g.sink_side().unwrap_or_default().to_vec(), used))
    })?;
    Ok((flow, array(py, (h, w), side), used))
}

type SeamOut<'py> = (Bound<'py, PyArray2<bool>>, f64, (usize, usize));

#[pyfunction]
#[pyo3(name = "seam", signature = (a, b, region, *, cost, connectivity, border_weight, a_mask, b_mask, seeds, edges, threads))]
pub fn seam_py<'py>(
    py: Python<'py>,
    a: PyReadonlyArray3<'py, f32>,
    b: PyReadonlyArray3<'py, f32>,
    region: PyReadonlyArray2<'py, bool>,
    cost: &str,
    connectivity: usize,
    border_weight: Option<f32>,
    a_mask: Option<PyReadonlyArray2<'py, bool>>,
    b_mask: Option<PyReadonlyArray2<'py, bool>>,
    seeds: Option<PyReadonlyArray2<'py, u8>>,
    edges: Option<PyReadonlyArray3<'py, f32>>,
    threads: Option<usize>,
) -> PyResult<SeamOut<'py>> {
    let cost = match cost {
        "kwatra" => SeamCost::Kwatra,
        "gradient" => SeamCost::Gradient,
        "luo" => SeamCost::Luo,
        other => {
            return Err(to_py(invalid(
                "cost",
                format!(
                    "expected 'kwatra', 'gradient', 'luo' or an array of edge costs, got {other:?}"
                ),
            )))
        }
    };
    let (h, w, _) = a.as_array().dim();
    let region_s = region.as_slice().map_err(not_contiguous("region"))?;
    let a_mask_s = opt_slice("a_mask", a_mask.as_ref())?;
    let b_mask_s = opt_slice("b_mask", b_mask.as_ref())?;
    let seeds_s = opt_slice("seeds", seeds.as_ref())?;
    let edges_s = opt_slice("cost", edges.as_ref())?;
    let input = SeamInput {
        a: image("a", &a)?,
        b: image("b", &b)?,
        region: region_s,
        a_mask: a_mask_s,
        b_mask: b_mask_s,
        seeds: seeds_s,
        cost,
        edges: edges_s,
        border_weight: border_weight.unwrap_or_else(|| cost.default_border_weight()),
        connectivity,
    };
    let s = run(py, threads, None, |_| seams::seam(&input))?;
    Ok((array(py, (h, w), s.take_b), s.energy, s.tied))
}
