//! Thin-plate splines in the plane with the two regularisers of Chui & Rangarajan (2003, §4):
//! `λ1` on the bending energy and `λ2` pulling the affine part towards the identity.
//!
//! For control points `c_i` (`n ≥ 3`, not collinear) and targets `y_i` the spline is
//! `f(p) = [1 p] d + Σ_i w_i U(|p − c_i|)`, `U(r) = r² log r`, minimising
//! `|Y − P d − K w|² + λ1 wᵀ K w + λ2 |d − I|²` with `Pᵀ w = 0` (`P = [1 c]`, `K_ij = U(|c_i − c_j|)`).
//! With the QR factorisation `P = [Q1 Q2] [R; 0]` and `w = Q2 γ` (Wahba 1990; Chui's code):
//! `γ = (Q2ᵀ K Q2 + λ1 I)⁻¹ Q2ᵀ Y` and `d − I = (RᵀR + λ2 I)⁻¹ (Rᵀ Q1ᵀ (Y − K w) − RᵀR I)`.
//!
//! TPS-RPM refits the same control points to new targets hundreds of times with a new `λ1`
//! each temperature, so [`Basis`] does the `O(n³)` work once: it tridiagonalises
//! `Q2ᵀ K Q2 = H Θ Hᵀ` by Householder reflections and keeps `G = Q2 H`; a fit is then
//! `w = G (Θ + λ1 I)⁻¹ Gᵀ Y`, `O(n²)` with a tridiagonal solve. [`Basis::refit`] gives the
//! values at the control points without `w` or `K`: `K G = G Θ + Q1 A` with `A = Q1ᵀ K G`.

// The loop's helpers must be inlined into its AVX2 copy to be compiled for AVX2.
#![allow(clippy::inline_always)]
// Dense kernels index several arrays in lockstep.
#![allow(clippy::needless_range_loop)]

use std::ops::{Add, Mul};

use crate::error::{invalid, Result};

/// A point `(x, y)`: `x` along columns, `y` along rows.
pub type Point = [f64; 2];

/// `U(r) = r² log r` from the squared distance.
#[inline]
pub(crate) fn kernel(r2: f64) -> f64 {
    if r2 > 0.0 {
        0.5 * r2 * r2.ln()
    } else {
        0.0
    }
}

/// The fixed part of a fit for one set of control points (see the module notes).
pub struct Basis {
    ctrl: Vec<Point>,
    /// `K`, row-major `n × n`.
    k: Vec<f64>,
    /// `Q1`, row-major `n × 3`.
    q1: Vec<f64>,
    /// `R`, upper triangular `3 × 3`.
    r: [[f64; 3]; 3],
    /// `G = Q2 H`, row-major `n × (n − 3)`.
    g: Vec<f64>,
    /// Diagonal and sub-diagonal of `Θ`.
    diag: Vec<f64>,
    off: Vec<f64>,
    /// `A = Q1ᵀ K G`, row-major `3 × (n − 3)`.
    a: Vec<f64>,
}

/// A fit kept as `γ` (the kernel weights are `w = G γ`) and the affine part, with the
/// scratch of [`Basis::refit`].
pub struct Refit {
    gamma: Vec<Point>,
    lanes: [Vec<f64>; 2],
    thomas: Vec<f64>,
    d: [Point; 3],
}

/// A fitted spline.
#[derive(Clone, Debug, PartialEq)]
pub struct Tps {
    /// Control points `c_i`.
    pub ctrl: Vec<Point>,
    /// Kernel weights `w_i`.
    pub w: Vec<Point>,
    /// Affine part: `f(p) = d[0] + p.x d[1] + p.y d[2] + …`.
    pub d: [Point; 3],
}

impl Tps {
    /// The identity map (no control points).
    #[must_use]
    pub fn identity() -> Self {
        Self {
            ctrl: Vec::new(),
            w: Vec::new(),
            d: [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]],
        }
    }

    /// `f(p)`.
    #[must_use]
    pub fn eval(&self, p: Point) -> Point {
        let mut o = [
            self.d[0][0] + p[0] * self.d[1][0] + p[1] * self.d[2][0],
            self.d[0][1] + p[0] * self.d[1][1] + p[1] * self.d[2][1],
        ];
        for (c, w) in self.ctrl.iter().zip(&self.w) {
            let (dx, dy) = (p[0] - c[0], p[1] - c[1]);
            let u = kernel(dx * dx + dy * dy);
            o[0] += w[0] * u;
            o[1] += w[1] * u;
        }
        o
    }

    /// `f(p)` and its Jacobian `[[∂fx/∂x, ∂fx/∂y], [∂fy/∂x, ∂fy/∂y]]`.
    #[must_use]
    pub fn eval_jacobian(&self, p: Point) -> (Point, [[f64; 2]; 2]) {
        let mut o = [
            self.d[0][0] + p[0] * self.d[1][0] + p[1] * self.d[2][0],
            self.d[0][1] + p[0] * self.d[1][1] + p[1] * self.d[2][1],
        ];
        let mut j = [[self.d[1][0], self.d[2][0]], [self.d[1][1], self.d[2][1]]];
        for (c, w) in self.ctrl.iter().zip(&self.w) {
            let (dx, dy) = (p[0] - c[0], p[1] - c[1]);
            let r2 = dx * dx + dy * dy;
            if r2 > 0.0 {
                let l = r2.ln();
                let u = 0.5 * r2 * l;
                // ∇U = (p − c)(log r² + 1).
                let g = l + 1.0;
                o[0] += w[0] * u;
                o[1] += w[1] * u;
                j[0][0] += w[0] * g * dx;
                j[0][1] += w[0] * g * dy;
                j[1][0] += w[1] * g * dx;
                j[1][1] += w[1] * g * dy;
            }
        }
        (o, j)
    }

    /// The bending energy `wᵀ K w` summed over both coordinates.
    #[must_use]
    pub fn bending(&self) -> f64 {
        let mut e = 0.0;
        for (a, wa) in self.ctrl.iter().zip(&self.w) {
            for (b, wb) in self.ctrl.iter().zip(&self.w) {
                let (dx, dy) = (a[0] - b[0], a[1] - b[1]);
                e += kernel(dx * dx + dy * dy) * (wa[0] * wb[0] + wa[1] * wb[1]);
            }
        }
        e
    }
}

impl Basis {
    /// Prepares fits with control points `ctrl` (errors name `name`): at least 3, finite,
    /// not all on a line.
    pub fn new(name: &'static str, ctrl: &[Point]) -> Result<Self> {
        let n = ctrl.len();
        if n < 3 {
            return Err(invalid(
                name,
                format!("expected at least 3 points, got {n}"),
            ));
        }
        if let Some(i) = ctrl
            .iter()
            .position(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            return Err(invalid(
                name,
                format!(
                    "expected finite coordinates, found ({}, {}) at point {i}",
                    ctrl[i][0], ctrl[i][1]
                ),
            ));
        }
        let mut k = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..i {
                let (dx, dy) = (ctrl[i][0] - ctrl[j][0], ctrl[i][1] - ctrl[j][1]);
                let u = kernel(dx * dx + dy * dy);
                k[i * n + j] = u;
                k[j * n + i] = u;
            }
        }
        // Householder QR of P = [1 x y]: Q = P0 P1 P2 applied to the identity.
        let mut a: Vec<[f64; 3]> = ctrl.iter().map(|p| [1.0, p[0], p[1]]).collect();
        let scale = ctrl
            .iter()
            .fold(1.0f64, |s, p| s.max(p[0].abs()).max(p[1].abs()));
        let mut vs: Vec<Vec<f64>> = Vec::with_capacity(3);
        let mut r = [[0.0; 3]; 3];
        for col in 0..3 {
            let norm = (col..n).map(|i| a[i][col] * a[i][col]).sum::<f64>().sqrt();
            let alpha = if a[col][col] >= 0.0 { -norm } else { norm };
            let mut v: Vec<f64> = (0..n)
                .map(|i| if i < col { 0.0 } else { a[i][col] })
                .collect();
            v[col] -= alpha;
            let vn = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm <= 1e-9 * scale * (n as f64).sqrt() || vn == 0.0 {
                return Err(invalid(name, "expected points not all on one line"));
            }
            for x in &mut v {
                *x /= vn;
            }
            for c2 in col..3 {
                let s: f64 = (col..n).map(|i| v[i] * a[i][c2]).sum();
                for i in col..n {
                    a[i][c2] -= 2.0 * v[i] * s;
                }
            }
            vs.push(v);
        }
        for i in 0..3 {
            for j in i..3 {
                r[i][j] = a[i][j];
            }
        }
        // Explicit Q = P0 P1 P2 (n × n): rows of the identity times the reflectors.
        let mut q = vec![0.0; n * n];
        for i in 0..n {
            q[i * n + i] = 1.0;
        }
        for v in vs.iter().rev() {
            // Q ← P Q, P = I − 2 v vᵀ.
            let mut s = vec![0.0; n];
            for i in 0..n {
                if v[i] != 0.0 {
                    for j in 0..n {
                        s[j] += v[i] * q[i * n + j];
                    }
                }
            }
            for i in 0..n {
                if v[i] != 0.0 {
                    for j in 0..n {
                        q[i * n + j] -= 2.0 * v[i] * s[j];
                    }
                }
            }
        }
        let m = n - 3;
        let q1: Vec<f64> = (0..n)
            .flat_map(|i| (0..3).map(move |j| (i, j)))
            .map(|(i, j)| q[i * n + j])
            .collect();
        let mut g: Vec<f64> = (0..n)
            .flat_map(|i| (3..n).map(move |j| (i, j)))
            .map(|(i, j)| q[i * n + j])
            .collect();
        // S = Q2ᵀ K Q2 (m × m): the trailing block of P2 P1 P0 K P0 P1 P2.
        let mut pkp = k.clone();
        let mut p = vec![0.0; n];
        for (c, v) in vs.iter().enumerate() {
            reflect(&mut pkp, n, v, c, &mut p);
        }
        let mut s: Vec<f64> = (3..n)
            .flat_map(|i| pkp[i * n + 3..(i + 1) * n].iter().copied())
            .collect();
        let (diag, off) = tridiagonalise(&mut s, m, &mut g, n);
        // A = (Q1ᵀ K) G.
        let mut qk = vec![0.0; 3 * n];
        for i in 0..n {
            for l in 0..3 {
                axpy(
                    &mut qk[l * n..(l + 1) * n],
                    q1[i * 3 + l],
                    &k[i * n..(i + 1) * n],
                );
            }
        }
        let mut a = vec![0.0; 3 * m];
        for i in 0..n {
            for l in 0..3 {
                axpy(
                    &mut a[l * m..(l + 1) * m],
                    qk[l * n + i],
                    &g[i * m..(i + 1) * m],
                );
            }
        }
        Ok(Self {
            ctrl: ctrl.to_vec(),
            k,
            q1,
            r,
            g,
            diag,
            off,
            a,
        })
    }

    /// The number of control points.
    #[must_use]
    pub fn len(&self) -> usize {
        self.ctrl.len()
    }

    /// Always false (a basis has at least 3 points).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.ctrl.is_empty()
    }

    /// The spline through `targets` (one per control point) with regularisers `lambda1`
    /// (bending) and `lambda2` (affine part towards the identity), both `≥ 0`.
    #[must_use]
    pub fn fit(&self, targets: &[Point], lambda1: f64, lambda2: f64) -> Tps {
        let mut kw = vec![[0.0; 2]; self.ctrl.len()];
        self.solve(targets, lambda1, lambda2, &mut kw)
    }

    /// [`Basis::fit`], and `f(c_i)` for every control point written to `at` (the same values
    /// as [`Basis::at_controls`], from the `K w` the fit computes anyway).
    pub fn fit_at_controls(
        &self,
        targets: &[Point],
        lambda1: f64,
        lambda2: f64,
        at: &mut [Point],
    ) -> Tps {
        let t = self.solve(targets, lambda1, lambda2, at);
        for (a, p) in at.iter_mut().zip(&self.ctrl) {
            *a = [
                t.d[0][0] + p[0] * t.d[1][0] + p[1] * t.d[2][0] + a[0],
                t.d[0][1] + p[0] * t.d[1][1] + p[1] * t.d[2][1] + a[1],
            ];
        }
        t
    }

    /// The fit, with `K w` written to `kw`.
    fn solve(&self, targets: &[Point], lambda1: f64, lambda2: f64, kw: &mut [Point]) -> Tps {
        let n = self.ctrl.len();
        let m = n - 3;
        debug_assert_eq!(targets.len(), n);
        // b = Gᵀ Y, by rows of G (axpy), both coordinates.
        let (mut bx, mut by) = (vec![0.0; m], vec![0.0; m]);
        for i in 0..n {
            let gi = &self.g[i * m..(i + 1) * m];
            axpy(&mut bx, targets[i][0], gi);
            axpy(&mut by, targets[i][1], gi);
        }
        let mut b: Vec<Point> = bx.iter().zip(&by).map(|(&x, &y)| [x, y]).collect();
        tridiagonal_solve(&self.diag, &self.off, lambda1, &mut b, &mut vec![0.0; m]);
        let (gx, gy): (Vec<f64>, Vec<f64>) = b.iter().map(|p| (p[0], p[1])).unzip();
        // w = G γ.
        let (wx, wy): (Vec<f64>, Vec<f64>) = (0..n)
            .map(|i| {
                let gi = &self.g[i * m..(i + 1) * m];
                (dot(gi, &gx), dot(gi, &gy))
            })
            .unzip();
        let w: Vec<Point> = wx.iter().zip(&wy).map(|(&x, &y)| [x, y]).collect();
        // Q1ᵀ (Y − K w).
        let mut z = [[0.0; 2]; 3];
        for i in 0..n {
            let ki = &self.k[i * n..(i + 1) * n];
            kw[i] = [dot(ki, &wx), dot(ki, &wy)];
            let res = [targets[i][0] - kw[i][0], targets[i][1] - kw[i][1]];
            for a in 0..3 {
                let q = self.q1[i * 3 + a];
                z[a][0] += q * res[0];
                z[a][1] += q * res[1];
            }
        }
        let d = self.affine(&z, lambda2);
        Tps {
            ctrl: self.ctrl.clone(),
            w,
            d,
        }
    }

    /// The affine part from `z = Q1ᵀ (Y − K w)`.
    fn affine(&self, z: &[[f64; 2]; 3], lambda2: f64) -> [Point; 3] {
        let r = &self.r;
        // RᵀR + λ2 I and the right-hand side Rᵀ z − RᵀR I32.
        let mut rtr = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                rtr[i][j] = (0..3).map(|l| r[l][i] * r[l][j]).sum();
            }
        }
        let ident = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
        let mut rhs = [[0.0; 2]; 3];
        for i in 0..3 {
            for c in 0..2 {
                rhs[i][c] = (0..3)
                    .map(|l| r[l][i] * z[l][c] - rtr[i][l] * ident[l][c])
                    .sum();
            }
        }
        let mut a = rtr;
        for i in 0..3 {
            a[i][i] += lambda2;
        }
        let x = solve3(a, rhs);
        [
            [x[0][0] + ident[0][0], x[0][1] + ident[0][1]],
            [x[1][0] + ident[1][0], x[1][1] + ident[1][1]],
            [x[2][0] + ident[2][0], x[2][1] + ident[2][1]],
        ]
    }

    /// An empty [`Refit`] for this basis.
    #[must_use]
    pub fn refit_state(&self) -> Refit {
        let m = self.ctrl.len() - 3;
        Refit {
            gamma: vec![[0.0; 2]; m],
            lanes: [vec![0.0; m], vec![0.0; m]],
            thomas: vec![0.0; m],
            d: Tps::identity().d,
        }
    }

    /// The fit of [`Basis::fit`], kept in `state`, with `f(c_i)` written to `at`: two passes
    /// over `G` and none over `K` (`K w = G Θ γ + Q1 A γ`), for loops that need only the
    /// values at the control points until the end ([`Basis::spline`]). Equal to
    /// [`Basis::fit_at_controls`] up to rounding.
    #[inline(always)]
    pub fn refit(
        &self,
        targets: &[Point],
        lambda1: f64,
        lambda2: f64,
        state: &mut Refit,
        at: &mut [Point],
    ) {
        let n = self.ctrl.len();
        let m = n - 3;
        debug_assert_eq!(targets.len(), n);
        let [bx, by] = &mut state.lanes;
        bx.fill(0.0);
        by.fill(0.0);
        for i in 0..n {
            let gi = &self.g[i * m..(i + 1) * m];
            axpy(bx, targets[i][0], gi);
            axpy(by, targets[i][1], gi);
        }
        let gamma = &mut state.gamma;
        for (g, (&x, &y)) in gamma.iter_mut().zip(bx.iter().zip(by.iter())) {
            *g = [x, y];
        }
        tridiagonal_solve(&self.diag, &self.off, lambda1, gamma, &mut state.thomas);
        // Θ γ into the lanes, and A γ = Q1ᵀ K w.
        for i in 0..m {
            let mut tg = [self.diag[i] * gamma[i][0], self.diag[i] * gamma[i][1]];
            if i > 0 {
                tg[0] += self.off[i - 1] * gamma[i - 1][0];
                tg[1] += self.off[i - 1] * gamma[i - 1][1];
            }
            if i + 1 < m {
                tg[0] += self.off[i] * gamma[i + 1][0];
                tg[1] += self.off[i] * gamma[i + 1][1];
            }
            bx[i] = tg[0];
            by[i] = tg[1];
        }
        let mut ag = [[0.0; 2]; 3];
        for l in 0..3 {
            for (a, g) in self.a[l * m..(l + 1) * m].iter().zip(gamma.iter()) {
                ag[l][0] += a * g[0];
                ag[l][1] += a * g[1];
            }
        }
        // z = Q1ᵀ Y − A γ.
        let mut z = ag.map(|p| [-p[0], -p[1]]);
        for i in 0..n {
            for l in 0..3 {
                let q = self.q1[i * 3 + l];
                z[l][0] += q * targets[i][0];
                z[l][1] += q * targets[i][1];
            }
        }
        let d = self.affine(&z, lambda2);
        state.d = d;
        for i in 0..n {
            let gi = &self.g[i * m..(i + 1) * m];
            let (p, q) = (self.ctrl[i], &self.q1[i * 3..i * 3 + 3]);
            let kw = [dot(gi, bx), dot(gi, by)];
            for c in 0..2 {
                at[i][c] = d[0][c]
                    + p[0] * d[1][c]
                    + p[1] * d[2][c]
                    + (kw[c] + q[0] * ag[0][c] + q[1] * ag[1][c] + q[2] * ag[2][c]);
            }
        }
    }

    /// The spline of the last [`Basis::refit`] into `state`.
    #[must_use]
    pub fn spline(&self, state: &Refit) -> Tps {
        let m = self.ctrl.len() - 3;
        let (gx, gy): (Vec<f64>, Vec<f64>) = state.gamma.iter().map(|p| (p[0], p[1])).unzip();
        let w = (0..self.ctrl.len())
            .map(|i| {
                let gi = &self.g[i * m..(i + 1) * m];
                [dot(gi, &gx), dot(gi, &gy)]
            })
            .collect();
        Tps {
            ctrl: self.ctrl.clone(),
            w,
            d: state.d,
        }
    }

    /// `f(c_i)` for every control point of a spline fitted on this basis (`O(n²)` with `K`).
    #[must_use]
    pub fn at_controls(&self, tps: &Tps) -> Vec<Point> {
        let n = self.ctrl.len();
        let (wx, wy): (Vec<f64>, Vec<f64>) = tps.w.iter().map(|p| (p[0], p[1])).unzip();
        (0..n)
            .map(|i| {
                let p = self.ctrl[i];
                let ki = &self.k[i * n..(i + 1) * n];
                [
                    tps.d[0][0] + p[0] * tps.d[1][0] + p[1] * tps.d[2][0] + dot(ki, &wx),
                    tps.d[0][1] + p[0] * tps.d[1][1] + p[1] * tps.d[2][1] + dot(ki, &wy),
                ]
            })
            .collect()
    }
}

/// `Σ a_j b_j` over four interleaved partial sums.
#[inline]
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    dot_lanes::<f64, 4>(a, b)
}

/// `Σ a_j b_j` over `L` (a power of 2) interleaved partial sums, added pairwise: a fixed
/// order, so the same on every machine, and one that lets the compiler use vector registers.
#[inline]
pub(crate) fn dot_lanes<F, const L: usize>(a: &[F], b: &[F]) -> F
where
    F: Copy + Default + Add<Output = F> + Mul<Output = F>,
{
    let mut acc = [F::default(); L];
    let (ca, cb) = (a.chunks_exact(L), b.chunks_exact(L));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for l in 0..L {
            acc[l] = acc[l] + x[l] * y[l];
        }
    }
    let mut w = L;
    while w > 1 {
        w /= 2;
        for l in 0..w {
            acc[l] = acc[l] + acc[l + w];
        }
    }
    let mut s = acc[0];
    for (&x, &y) in ra.iter().zip(rb) {
        s = s + x * y;
    }
    s
}

/// `y += a x`.
#[inline]
pub(crate) fn axpy<F>(y: &mut [F], a: F, x: &[F])
where
    F: Copy + Add<Output = F> + Mul<Output = F>,
{
    for (p, &q) in y.iter_mut().zip(x) {
        *p = *p + a * q;
    }
}

/// `S ← P S P` for the symmetric row-major `m × m` matrix `s` and `P = I − 2 v vᵀ` (`|v| = 1`,
/// zero before `from`), on the block `from..m` only: the rest is what the callers drop or
/// already zero. `p` is scratch, `m` long.
fn reflect(s: &mut [f64], m: usize, v: &[f64], from: usize, p: &mut [f64]) {
    // p = 2 S v, q = p − (vᵀp) v, S −= v qᵀ + q vᵀ.
    let v = &v[from..m];
    for i in from..m {
        p[i] = 2.0 * dot(&s[i * m + from..(i + 1) * m], v);
    }
    let p = &mut p[from..m];
    let vp = dot(v, p);
    axpy(p, -vp, v);
    for (i, (&vi, &pi)) in v.iter().zip(p.iter()).enumerate() {
        let row = &mut s[(from + i) * m + from..(from + i + 1) * m];
        for ((x, &vj), &pj) in row.iter_mut().zip(v).zip(p.iter()) {
            *x -= vi * pj + pi * vj;
        }
    }
}

/// Householder tridiagonalisation of the symmetric row-major `m × m` matrix `s`
/// (overwritten): returns the diagonal and sub-diagonal of `Θ = Hᵀ S H` and replaces the
/// `rows × m` matrix `g` by `g H`.
fn tridiagonalise(s: &mut [f64], m: usize, g: &mut [f64], rows: usize) -> (Vec<f64>, Vec<f64>) {
    let mut v = vec![0.0; m];
    let mut p = vec![0.0; m];
    for k in 0..m.saturating_sub(2) {
        let norm = (k + 1..m)
            .map(|i| s[i * m + k] * s[i * m + k])
            .sum::<f64>()
            .sqrt();
        if norm == 0.0 {
            continue;
        }
        let alpha = if s[(k + 1) * m + k] >= 0.0 {
            -norm
        } else {
            norm
        };
        v.fill(0.0);
        for i in k + 1..m {
            v[i] = s[i * m + k];
        }
        v[k + 1] -= alpha;
        let vn = (k + 1..m).map(|i| v[i] * v[i]).sum::<f64>().sqrt();
        if vn == 0.0 {
            continue;
        }
        for i in k + 1..m {
            v[i] /= vn;
        }
        reflect(s, m, &v, k, &mut p);
        // G ← G P.
        for r in 0..rows {
            let row = &mut g[r * m..(r + 1) * m];
            let t = 2.0 * dot(&row[k + 1..], &v[k + 1..]);
            axpy(&mut row[k + 1..], -t, &v[k + 1..]);
        }
    }
    let diag = (0..m).map(|i| s[i * m + i]).collect();
    let off = (0..m.saturating_sub(1))
        .map(|i| s[(i + 1) * m + i])
        .collect();
    (diag, off)
}

/// Solves `(Θ + λ I) x = b` in place for the symmetric tridiagonal `Θ` (Thomas algorithm;
/// `Θ + λ I` is positive definite, so no pivoting is needed); `c` is scratch, `m` long.
fn tridiagonal_solve(diag: &[f64], off: &[f64], lambda: f64, b: &mut [[f64; 2]], c: &mut [f64]) {
    let m = diag.len();
    if m == 0 {
        return;
    }
    let mut piv = diag[0] + lambda;
    c[0] = if m > 1 { off[0] / piv } else { 0.0 };
    b[0] = [b[0][0] / piv, b[0][1] / piv];
    for i in 1..m {
        piv = diag[i] + lambda - off[i - 1] * c[i - 1];
        c[i] = if i + 1 < m { off[i] / piv } else { 0.0 };
        b[i] = [
            (b[i][0] - off[i - 1] * b[i - 1][0]) / piv,
            (b[i][1] - off[i - 1] * b[i - 1][1]) / piv,
        ];
    }
    for i in (0..m - 1).rev() {
        b[i] = [b[i][0] - c[i] * b[i + 1][0], b[i][1] - c[i] * b[i + 1][1]];
    }
}

/// Solves the 3 × 3 system `a x = b` (two right-hand sides) by Gaussian elimination with
/// partial pivoting.
fn solve3(mut a: [[f64; 3]; 3], mut b: [[f64; 2]; 3]) -> [[f64; 2]; 3] {
    for col in 0..3 {
        let piv = (col..3)
            .max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))
            .unwrap_or(col);
        a.swap(col, piv);
        b.swap(col, piv);
        for i in col + 1..3 {
            let f = a[i][col] / a[col][col];
            for j in col..3 {
                a[i][j] -= f * a[col][j];
            }
            b[i][0] -= f * b[col][0];
            b[i][1] -= f * b[col][1];
        }
    }
    let mut x = [[0.0; 2]; 3];
    for i in (0..3).rev() {
        for c in 0..2 {
            let s: f64 = (i + 1..3).map(|j| a[i][j] * x[j][c]).sum();
            x[i][c] = (b[i][c] - s) / a[i][i];
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn cloud(n: usize, seed: u64) -> Vec<Point> {
        let mut r = Rng::keyed(seed, 1, 2);
        let mut u = || (r.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        (0..n)
            .map(|_| [u() * 200.0 - 100.0, u() * 150.0 - 75.0])
            .collect()
    }

    #[test]
    fn interpolates_its_control_points_without_regularisation() {
        let c = cloud(40, 3);
        let t: Vec<Point> = c
            .iter()
            .map(|p| {
                [
                    p[0] + 8.0 * (p[1] / 30.0).sin(),
                    p[1] + 5.0 * (p[0] / 40.0).cos(),
                ]
            })
            .collect();
        let b = Basis::new("points", &c).unwrap();
        let f = b.fit(&t, 0.0, 0.0);
        for (p, q) in c.iter().zip(&t) {
            let e = f.eval(*p);
            assert!(
                (e[0] - q[0]).abs() < 1e-7 && (e[1] - q[1]).abs() < 1e-7,
                "{e:?} vs {q:?}"
            );
        }
        let at = b.at_controls(&f);
        for (a, q) in at.iter().zip(&t) {
            assert!((a[0] - q[0]).abs() < 1e-7 && (a[1] - q[1]).abs() < 1e-7);
        }
        // The values the fit leaves behind are those of a separate evaluation, to the bit.
        let mut at2 = vec![[0.0; 2]; c.len()];
        let g = b.fit_at_controls(&t, 0.3, 0.1, &mut at2);
        assert!(g == b.fit(&t, 0.3, 0.1) && at2 == b.at_controls(&g));
    }

    /// The refit without `K` gives the fit's values and spline up to rounding.
    #[test]
    fn refit_agrees_with_the_fit() {
        let c = cloud(40, 13);
        let t = cloud(40, 14);
        let b = Basis::new("points", &c).unwrap();
        let mut state = b.refit_state();
        let mut at = vec![[0.0; 2]; c.len()];
        let close = |p: &Point, q: &Point| (p[0] - q[0]).abs().max((p[1] - q[1]).abs()) < 1e-8;
        for (l1, l2) in [(0.0, 0.0), (0.3, 0.1), (50.0, 2.0)] {
            b.refit(&t, l1, l2, &mut state, &mut at);
            let f = b.fit(&t, l1, l2);
            let g = b.spline(&state);
            assert!(at.iter().zip(&b.at_controls(&f)).all(|(p, q)| close(p, q)));
            assert!(g.w.iter().zip(&f.w).all(|(p, q)| close(p, q)));
            assert!(g.d.iter().zip(&f.d).all(|(p, q)| close(p, q)));
        }
    }

    #[test]
    fn reproduces_an_affine_map_exactly_at_any_regularisation() {
        let c = cloud(30, 5);
        let aff = |p: Point| {
            [
                3.0 + 1.1 * p[0] - 0.2 * p[1],
                -7.0 + 0.3 * p[0] + 0.9 * p[1],
            ]
        };
        let t: Vec<Point> = c.iter().map(|&p| aff(p)).collect();
        let b = Basis::new("points", &c).unwrap();
        for lambda in [0.0, 1.0, 1e3] {
            let f = b.fit(&t, lambda, 0.0);
            for q in cloud(20, 9) {
                let (e, j) = f.eval_jacobian(q);
                let a = aff(q);
                assert!((e[0] - a[0]).abs() < 1e-7 && (e[1] - a[1]).abs() < 1e-7);
                assert!((j[0][0] - 1.1).abs() < 1e-9 && (j[1][1] - 0.9).abs() < 1e-9);
            }
            assert!(f.bending().abs() < 1e-6);
        }
    }

    /// The tridiagonal fast path agrees with a dense solve of the normal equations of the
    /// regularised problem: `(K + λ1 I) w + P d = Y`, `Pᵀ w = 0` (λ2 = 0).
    #[test]
    fn agrees_with_the_dense_regularised_system() {
        let c = cloud(25, 7);
        let t: Vec<Point> = cloud(25, 8);
        let n = c.len();
        let lambda = 0.7;
        let b = Basis::new("points", &c).unwrap();
        let f = b.fit(&t, lambda, 0.0);
        // Residual of the first block row: (K + λ I) w + P d − Y.
        for i in 0..n {
            let mut s = [0.0; 2];
            for j in 0..n {
                let kij = b.k[i * n + j] + if i == j { lambda } else { 0.0 };
                s[0] += kij * f.w[j][0];
                s[1] += kij * f.w[j][1];
            }
            for c2 in 0..2 {
                let v = s[c2] + f.d[0][c2] + c[i][0] * f.d[1][c2] + c[i][1] * f.d[2][c2] - t[i][c2];
                assert!(v.abs() < 1e-8, "row {i}: {v}");
            }
        }
        for c2 in 0..2 {
            let s0: f64 = f.w.iter().map(|w| w[c2]).sum();
            let s1: f64 = f.w.iter().zip(&c).map(|(w, p)| w[c2] * p[0]).sum();
            assert!(s0.abs() < 1e-9 && s1.abs() < 1e-7);
        }
    }

    #[test]
    fn lambda2_pulls_the_affine_part_to_the_identity() {
        let c = cloud(20, 11);
        let t: Vec<Point> = c.iter().map(|p| [2.0 * p[0], 2.0 * p[1]]).collect();
        let b = Basis::new("points", &c).unwrap();
        let loose = b.fit(&t, 0.0, 0.0);
        let tight = b.fit(&t, 0.0, 1e9);
        assert!((loose.d[1][0] - 2.0).abs() < 1e-9);
        assert!((tight.d[1][0] - 1.0).abs() < 1e-3, "{:?}", tight.d);
    }

    #[test]
    fn rejects_too_few_or_collinear_points() {
        let e = Basis::new("points", &[[0.0, 0.0], [1.0, 1.0]])
            .err()
            .unwrap();
        assert_eq!(e.to_string(), "points: expected at least 3 points, got 2");
        let line: Vec<Point> = (0..5).map(|i| [f64::from(i), 2.0 * f64::from(i)]).collect();
        assert!(Basis::new("points", &line).is_err());
    }
}
