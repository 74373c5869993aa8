//! phloem-core: the pure-Rust engines under every phloem pipeline.
//!
//! Nothing here knows about Python. Images are `H×W×C` `f32` arrays in row-major
//! (C-contiguous) order, masks are `H×W` `bool`, and every stochastic routine takes a
//! `seed` and returns the same result whatever the number of rayon threads.
//!
//! Engines so far:
//! - [`patch`]: nearest-neighbour fields by PatchMatch (Barnes et al. 2009), PatchMatch seeded
//!   by PCA kd-tree search (He & Sun 2012), and exact search;
//! - [`emd`]: exact earth mover's distance between small histograms and its sliding-window map
//!   (the colour term of Assa & Cohen-Or, Eq. 1);
//! - [`distance`]: the SIMD patch-distance kernels that [`patch`], [`knn`] and [`tbn`] share;
//! - [`knn`]: k nearest patches inside one exemplar and the k-coherence candidate sets of
//!   Tong et al. 2002;
//! - [`vote`]: weighted patch voting, the M-step of texture optimisation (Kwatra et al. 2005)
//!   and of image completion (Wexler et al. 2007);
//! - [`maxflow`]: exact s-t max-flow / min-cut on grid graphs (a dual shortest path for planar
//!   problems, Schmidt, Töppe & Cremers 2009; otherwise Boykov & Kolmogorov 2004);
//! - [`seams`]: graph-cut seams between overlapping images (Kwatra et al. 2003; Luo et al.);
//! - [`poisson`]: Poisson image editing (Pérez et al. 2003) with normal or mixed gradients and
//!   fixed pixels, solved by multigrid-preconditioned conjugate gradients;
//! - [`field`]: smooth fields that interpolate given vectors (Sibbing et al. 2010, §5.3);
//! - [`shapes`]: boundary-patch shape synthesis of binary shapes and label maps, layered or
//!   joint (Rosenberger et al. 2009), and the shape similarity of its Eq. 3.9.
//! - [`tbn`]: texture-by-numbers (Fan et al. 2012 as in Laitoch 2018, §3.3–3.4): pyramid of
//!   reference images, k-coherence discrete solver, smart initialisation with chamfer 3-4
//!   distance maps.
//! - [`mvc`]: mean value coordinates for arbitrary planar polygons, inside and outside
//!   (Hormann & Floater 2006), and the contour-to-contour image warp and multi-source colour
//!   transfer they define (Argudo et al. 2017, §5.2).
//! - [`tps`]: thin-plate splines and non-rigid point registration by TPS-RPM (Chui &
//!   Rangarajan 2003) with dense forward and inverse warps (Assa & Cohen-Or, §3).
//! - [`strokes`]: pieces of an object fetched along strokes and their compositing energy
//!   (Luo, Lin, Shen & Chen).
//! - [`crossings`]: proper crossings of candidate polylines with existing segments, the
//!   planarity test of branching growth (Sibbing et al. 2010, §4.4).
//! - [`colonisation`]: the density map of branching growth, its local update, and the
//!   density and guidance maxima along rays (Sibbing et al. 2010, §4.4–4.5).
//! - [`resample`]: polylines resampled to a constant edge length, the first step of branching
//!   synthesis (Sibbing et al. 2010, §4.1).
//! - [`bending`]: the bending model's history distances and heading-change bins over every
//!   candidate of a growth step (Sibbing et al. 2010, §4.2).
//! - [`growth`]: the choice of a growth step's best valid candidates from their bending
//!   quality, density, guidance, the frame and the planarity test (Sibbing et al. 2010, §4.4).
//! - [`deform`]: where each pixel of a deformed fragment comes from (Sibbing et al. 2010, §5.3).
//! - [`correction`]: guided quilting, the start of texture correction after a warp (Assa &
//!   Cohen-Or §3, after Fang & Hart 2007).

pub mod bending;
pub mod cancel;
pub mod colonisation;
pub mod correction;
pub mod crossings;
pub mod deform;
pub mod distance;
pub mod emd;
pub mod error;
pub mod field;
pub mod growth;
pub mod image;
pub(crate) mod kdtree;
pub mod knn;
pub mod maxflow;
pub mod mvc;
pub mod patch;
pub mod poisson;
pub mod resample;
pub mod rng;
pub mod seams;
pub mod shapes;
pub(crate) mod solver;
pub mod strokes;
pub mod tbn;
pub mod tps;
pub mod vote;

pub use error::{Error, Result};
pub use image::Image;
