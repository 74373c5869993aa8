//! The masked 5-point pixel Laplacian, `(A x)_p = d_p x_p − Σ_{q ∈ N_p} x_q` at the cells with
//! `d_p > 0` (0 elsewhere): the fine operator of the Poisson solves and, applied twice, of the
//! smooth-field energy.
//!
//! Grids are framed: the first and last row and column have `d = 0`, so the stencil never
//! leaves the grid. Vectors are kept 0 where `d = 0`, which is how a neighbour outside the
//! region drops out of the sum while its place on the diagonal still counts (Dirichlet).

// Lane loops index several arrays in lockstep; the index form is what vectorises.
#![allow(clippy::needless_range_loop)]

use super::bands::{bands, sum_lanes, BAND};
use super::pcg::{Operator, Real};

/// `q = A p` for the diagonal `diag` on a grid of rows `w` long; returns `⟨p, q⟩` per lane.
pub(crate) fn apply<T: Real, const L: usize>(
    diag: &[f32],
    w: usize,
    p: &[[T; L]],
    q: &mut [[T; L]],
) -> [f64; L] {
    let h = diag.len() / w;
    let parts = bands(q, w, |bi, qb| {
        let mut dot = [0f64; L];
        for (k, out) in qb.chunks_mut(w).enumerate() {
            let y = bi * BAND + k;
            if y == 0 || y == h - 1 {
                out.fill([T::ZERO; L]);
                continue;
            }
            let o = y * w;
            let (up, cur, dn) = (&p[o - w..o], &p[o..o + w], &p[o + w..o + 2 * w]);
            let d = &diag[o..o + w];
            out[0] = [T::ZERO; L];
            out[w - 1] = [T::ZERO; L];
            for xi in 1..w - 1 {
                if d[xi] == 0.0 {
                    out[xi] = [T::ZERO; L];
                    continue;
                }
                let (c0, l, r, u, dn) = (cur[xi], cur[xi - 1], cur[xi + 1], up[xi], dn[xi]);
                let dx = T::of_f32(d[xi]);
                let mut v = [T::ZERO; L];
                for c in 0..L {
                    v[c] = dx * c0[c] - (l[c] + r[c] + u[c] + dn[c]);
                    let (a, b): (f64, f64) = (c0[c].into(), v[c].into());
                    dot[c] += a * b;
                }
                out[xi] = v;
            }
        }
        dot
    });
    sum_lanes(&parts)
}

/// The residual `r = b − A x` in `f64`, stored in `T`; returns `‖r‖²` per lane.
pub(crate) fn residual<T: Real, const L: usize>(
    diag: &[f32],
    w: usize,
    b: &[[f64; L]],
    x: &[[f64; L]],
    r: &mut [[T; L]],
) -> [f64; L] {
    let parts = bands(r, w, |bi, rb| {
        let mut s = [0f64; L];
        for (k, out) in rb.iter_mut().enumerate() {
            let i = bi * BAND * w + k;
            let d = f64::from(diag[i]);
            if d == 0.0 {
                *out = [T::ZERO; L];
                continue;
            }
            let (c0, l, rr, u, dn) = (x[i], x[i - 1], x[i + 1], x[i - w], x[i + w]);
            let mut v = [T::ZERO; L];
            for c in 0..L {
                let t = b[i][c] - (d * c0[c] - (l[c] + rr[c] + u[c] + dn[c]));
                s[c] += t * t;
                v[c] = T::of_f64(t);
            }
            *out = v;
        }
        s
    });
    sum_lanes(&parts)
}

/// The operator of [`apply`] and [`residual`] for [`super::pcg::pcg`].
pub(crate) struct Laplacian<'a> {
    /// Per cell: the diagonal, 0 off the unknowns.
    pub diag: &'a [f32],
    /// Row length of the grid.
    pub w: usize,
}

impl<T: Real, const L: usize> Operator<T, L> for Laplacian<'_> {
    fn apply(&mut self, p: &[[T; L]], q: &mut [[T; L]]) -> [f64; L] {
        apply(self.diag, self.w, p, q)
    }

    fn residual(&mut self, b: &[[f64; L]], x: &[[f64; L]], r: &mut [[T; L]]) -> [f64; L] {
        residual(self.diag, self.w, b, x, r)
    }
}
