//! `phloem._core`: the thin PyO3 layer over phloem-core. It converts arrays (`convert`), runs
//! core work with the GIL released on a pool of its own while serving Ctrl-C and progress
//! (`call`, `threads`, `progress`), maps errors (`errors`), and nothing else: the algorithms
//! live in `rust/core`, and every option's default lives in the Python package, so each
//! binding takes every option explicitly.

// PyO3 hands every argument over by value (borrowed arrays included); the lint cannot see that.
#![allow(clippy::needless_pass_by_value)]

use pyo3::prelude::*;

mod bending;
mod blend;
mod call;
mod colonisation;
mod convert;
mod correction;
mod crossings;
mod deform;
mod emd;
mod errors;
mod growth;
mod patch;
mod progress;
mod resample;
mod seams;
mod shapes;
mod strokes;
mod tbn;
mod threads;
mod tps;
mod warp;

#[pymodule(gil_used = false)]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(patch::nnf_py, m)?)?;
    m.add_function(wrap_pyfunction!(patch::knn_py, m)?)?;
    m.add_function(wrap_pyfunction!(patch::coherence_candidates_py, m)?)?;
    m.add_function(wrap_pyfunction!(patch::vote_py, m)?)?;
    m.add_function(wrap_pyfunction!(seams::grid_maxflow_py, m)?)?;
    m.add_function(wrap_pyfunction!(seams::seam_py, m)?)?;
    m.add_function(wrap_pyfunction!(blend::seamless_py, m)?)?;
    m.add_function(wrap_pyfunction!(blend::interpolate_field_py, m)?)?;
    m.add_function(wrap_pyfunction!(deform::fragment_maps_py, m)?)?;
    m.add_function(wrap_pyfunction!(tbn::by_numbers_py, m)?)?;
    m.add_function(wrap_pyfunction!(tbn::tbn_upsample_py, m)?)?;
    m.add_function(wrap_pyfunction!(tbn::tbn_downsample_py, m)?)?;
    m.add_function(wrap_pyfunction!(shapes::synthesize_py, m)?)?;
    m.add_function(wrap_pyfunction!(shapes::synthesize_labels_py, m)?)?;
    m.add_function(wrap_pyfunction!(shapes::similarity_py, m)?)?;
    m.add_function(wrap_pyfunction!(shapes::layer_order_py, m)?)?;
    m.add_function(wrap_pyfunction!(warp::mvc_weights_py, m)?)?;
    m.add_function(wrap_pyfunction!(warp::mvc_warp_py, m)?)?;
    m.add_function(wrap_pyfunction!(warp::mvc_combine_py, m)?)?;
    m.add_function(wrap_pyfunction!(emd::emd_map_py, m)?)?;
    m.add_function(wrap_pyfunction!(emd::emd_py, m)?)?;
    m.add_function(wrap_pyfunction!(emd::nearest_colour_py, m)?)?;
    m.add_function(wrap_pyfunction!(tps::tps_register_py, m)?)?;
    m.add_function(wrap_pyfunction!(tps::tps_sample_py, m)?)?;
    m.add_function(wrap_pyfunction!(correction::guided_quilt_py, m)?)?;
    m.add_function(wrap_pyfunction!(strokes::stroke_pieces_py, m)?)?;
    m.add_function(wrap_pyfunction!(strokes::stroke_pair_energies_py, m)?)?;
    m.add_function(wrap_pyfunction!(crossings::polylines_crossing_py, m)?)?;
    m.add_function(wrap_pyfunction!(bending::dist_columns_py, m)?)?;
    m.add_function(wrap_pyfunction!(bending::turn_bins_py, m)?)?;
    m.add_function(wrap_pyfunction!(bending::histogram_moves_py, m)?)?;
    m.add_function(wrap_pyfunction!(resample::polyline_resample_py, m)?)?;
    m.add_function(wrap_pyfunction!(colonisation::density_stamp_py, m)?)?;
    m.add_function(wrap_pyfunction!(growth::growth_choose_py, m)?)?;
    m.add_function(wrap_pyfunction!(threads::default_threads_py, m)?)?;
    m.add_function(wrap_pyfunction!(threads::after_fork_in_child_py, m)?)?;
    Ok(())
}
