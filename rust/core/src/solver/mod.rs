//! The sparse linear solvers of the gradient-domain engines ([`crate::poisson`],
//! [`crate::field`]): one preconditioned conjugate-gradient loop, one geometric multigrid and
//! one dense profile Cholesky factorisation.
//!
//! - [`pcg`]: conjugate gradients over any [`pcg::Operator`] and [`pcg::Preconditioner`],
//!   several right-hand sides at once, `f64` iterate, `f32` or `f64` work vectors;
//! - [`multigrid`]: Galerkin multigrid on masked pixel grids (bilinear transfers, multicolour
//!   Gauss–Seidel), used as the preconditioner and for full-multigrid first guesses;
//! - [`cholesky`]: the direct solver of the coarsest multigrid level and of small systems;
//! - [`laplacian`]: the masked 5-point pixel Laplacian, the fine operator of both engines;
//! - [`bands`]: the fixed row bands that make every parallel pass thread-count independent.
//!
//! See `docs/engines/solvers.md` for the algorithms, parameters and measurements.

pub(crate) mod bands;
pub(crate) mod cholesky;
pub(crate) mod laplacian;
pub(crate) mod multigrid;
pub(crate) mod pcg;
