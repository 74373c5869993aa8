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

#[cfg(test)]
mod tests {
    use super::cholesky::Cholesky;
    use super::laplacian::Laplacian;
    use super::multigrid::{Hierarchy, Level, VCycle};
    use super::pcg::pcg;

    /// PCG preconditioned by the multigrid (with its full-multigrid start) agrees with a dense
    /// direct solve of the same masked Laplacian: a ring with Dirichlet cells and a hole.
    #[test]
    fn pcg_with_multigrid_matches_a_dense_direct_solve() {
        let n = 33;
        let c = 16.0f32;
        let inside = |p: usize| {
            let (y, x) = ((p / n) as f32 - c, (p % n) as f32 - c);
            let r2 = y * y + x * x;
            (9.0..196.0).contains(&r2)
        };
        let diag: Vec<f32> = (0..n * n)
            .map(|p| if inside(p) { 4.0 } else { 0.0 })
            .collect();
        let cells: Vec<usize> = (0..n * n).filter(|&p| diag[p] > 0.0).collect();
        let b: Vec<[f64; 2]> = (0..n * n)
            .map(|p| {
                if diag[p] > 0.0 {
                    [((p * 7919) % 101) as f64 / 101.0 - 0.5, 1.0]
                } else {
                    [0.0; 2]
                }
            })
            .collect();
        let mg = Hierarchy::new(Level::five(n, n, diag.clone()));
        assert!(mg.levels.len() >= 2);
        let scale = [0, 1].map(|c| b.iter().map(|v| v[c] * v[c]).sum::<f64>().sqrt());
        let it = pcg::<f32, 2>(
            &mut Laplacian { diag: &diag, w: n },
            &mut VCycle::new(&mg),
            &b,
            n,
            scale,
            1e-10,
            100,
        )
        .unwrap();
        assert!(
            it.residual <= 1e-10 && it.iterations <= 20,
            "{}",
            it.residual
        );
        // The dense matrix over the unknowns, factored.
        let m = cells.len();
        let mut a = vec![0f64; m * m];
        for (i, &p) in cells.iter().enumerate() {
            a[i * m + i] = 4.0;
            for (j, &q) in cells.iter().enumerate() {
                if [p.abs_diff(q) == 1 && p / n == q / n, p.abs_diff(q) == n].contains(&true) {
                    a[i * m + j] = -1.0;
                }
            }
        }
        let mut x: Vec<[f64; 2]> = cells.iter().map(|&p| b[p]).collect();
        Cholesky::new(a, m, 0.0, 0.0).solve(&mut x);
        for (i, &p) in cells.iter().enumerate() {
            for c in 0..2 {
                assert!(
                    (it.x[p][c] - x[i][c]).abs() < 1e-8,
                    "{p}: {:?} vs {:?}",
                    it.x[p],
                    x[i]
                );
            }
        }
    }
}
