//! Stroke-based editing of object structure (Luo, Lin, Shen & Chen): the per-pixel work of
//! re-drawing an object along new strokes.
//!
//! - [`fetch`]: a piece of the source object copied rigidly around a target sample, turned so
//!   that the source stroke's direction at the source sample lies along the target stroke's,
//!   and as wide across as the object is there (the paper's "fetching source texture");
//! - [`energy`]: the compositing energy (their Eqs. 1–2, the [`crate::seams`] cost
//!   [`crate::seams::SeamCost::Luo`]) of many pairs of pieces at once, which the
//!   dynamic-programming sampling along a stroke minimises.
//!
//! See `docs/pipelines/strokes.md`.

pub mod energy;
pub mod fetch;

pub use energy::pair_energies;
pub use fetch::{fetch, Piece, PieceSpec, WIDTH_MARGIN};
