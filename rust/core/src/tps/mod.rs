//! Non-rigid registration of point sets by TPS-RPM (Chui & Rangarajan 2003) and the dense
//! warps it defines, for the leaves pipeline (Assa & Cohen-Or, §3).
//!
//! - [`spline`]: thin-plate splines with bending and affine regularisers, fitted through a
//!   basis that makes refits with new targets and a new `λ1` cost `O(n²)`;
//! - [`rpm`]: the softassign/annealing loop;
//! - [`dense`]: the forward and inverse displacement fields on pixel grids, the fold check,
//!   and sampling an image by a field.
//!
//! See `docs/pipelines/leaves/registration.md`.

pub mod dense;
pub mod rpm;
pub mod spline;

pub use dense::{densify, register, sample, Dense, Side};
pub use rpm::{rpm, Params, Rpm};
pub use spline::{Basis, Point, Tps};
