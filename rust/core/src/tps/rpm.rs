//! TPS-RPM (Chui & Rangarajan, "A new point matching algorithm for non-rigid registration",
//! CVIU 89, 2003): soft correspondences with an outlier row and column, Sinkhorn balancing,
//! deterministic annealing, and a thin-plate spline refitted at every step.
//!
//! The spline `f` is defined on the first point set `x` (its control points) and maps it onto
//! the second, `y`. Both sets are centred on their centroids and divided by one common scale
//! (the larger RMS radius), so the temperatures and regularisers are scale-free; the result is
//! converted back to a plain [`Tps`] in the input coordinates (see [`to_input`]).
//!
//! At temperature `T`, with `v_i = f(x_i)` (values: [`Params::default`]; checked against
//! Chui & Rangarajan 2003 and Chui's `cMIX.m` in `docs/pipelines/leaves/registration.md`):
//! - `m_ij = exp(−|v_i − y_j|² / T) / √T` for real pairs (Chui's code), and the outlier
//!   column and row hold `exp(−k) / √T` (`k = Params::outlier`), so an outlier's best
//!   partner must come closer as `T` falls. Chui's constant
//!   `exp(−1) / √T_init` lets that radius grow as `T` falls, and random outliers then kept
//!   partners to the end and dragged the outline along (measured in the docs);
//! - Sinkhorn in scaling form (`r_i K_ij c_j`): real rows normalised over all `m + 1`
//!   columns, real columns over all `n + 1` rows, warm-started from the last update's column
//!   scalings, until every row sums to 1 within `tolerance` (at most `sinkhorn` sweeps);
//! - each point's inlier mass `ω_i = Σ_j m_ij` and Chui's target `ŷ_i = Σ_j m_ij y_j / ω_i`;
//!   the spline is fitted to `ŷ` weighted by `ω`, by majorisation: `inner` unweighted fits
//!   to `ω ŷ + (1 − ω) f(x)`, each from the last `f` (Chui's code fits `ŷ` unweighted, which
//!   lets a point that is almost all outlier pull the spline anywhere);
//! - `λ1 = λ1_init · n · T` and `λ2 = λ2_init · n · T` (the scaling of Chui's code, which
//!   makes the values independent of the number of points);
//! - `iterations` such updates per temperature (one while `T > coarse`), then `T ← rate · T`,
//!   until `T < T_final`.
//!
//! The kernel and its balancing are `f32` (twice the vector lanes; the balance is needed to
//! 10⁻² only), the spline `f64`; the loop is compiled for AVX2 as well and chosen at run time.

// The loop's helpers must be inlined into its AVX2 copy to be compiled for AVX2.
#![allow(clippy::inline_always)]

use std::ops::{Add, Mul, Neg, Sub};

use crate::cancel;
use crate::error::{invalid, Result};

use super::spline::{axpy, dot_lanes, Basis, Point, Refit, Tps};

/// Parameters of [`rpm`]; [`Params::default`] holds the values phloem uses.
#[derive(Clone, Debug, PartialEq)]
pub struct Params {
    /// Starting temperature in normalised units; `None` for the largest squared distance
    /// between the two (normalised) sets, where every pairing is equally likely.
    pub t_init: Option<f64>,
    /// `T_final = T_init / final_ratio`.
    pub final_ratio: f64,
    /// Annealing rate, `0 < rate < 1`.
    pub rate: f64,
    /// Correspondence/spline updates per temperature.
    pub iterations: usize,
    /// Temperatures above this (normalised units) get one update: the correspondences are
    /// still coarse there and follow the temperature without extra updates.
    pub coarse: f64,
    /// Sinkhorn sweeps per update, at most.
    pub sinkhorn: usize,
    /// Sinkhorn stops early once every real row sums to 1 within this.
    pub tolerance: f64,
    /// Outlier entry `exp(−k)/√T` (scaled with the temperature, so an outlier's best
    /// partner must come closer as `T` falls); 0 for Chui's constant `exp(−1)/√T_init`.
    pub outlier: f64,
    /// Refit the last spline on the mutual best matches only.
    pub polish: bool,
    /// `λ1_init` (bending).
    pub lambda1: f64,
    /// `λ2_init` (affine part towards the identity).
    pub lambda2: f64,
    /// Majorisation steps of the spline fit weighted by inlier mass, per update (each
    /// fits `ω ŷ + (1 − ω) f(x)` unweighted; see the module notes).
    pub inner: usize,
    /// The polish refit's `λ1` as a fraction of the last annealing one.
    pub polish_lambda: f64,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            t_init: None,
            final_ratio: 1e4,
            rate: 0.93,
            iterations: 5,
            coarse: 0.25,
            sinkhorn: 10,
            tolerance: 1e-2,
            outlier: 2.0,
            polish: true,
            lambda1: 1.0,
            lambda2: 0.1,
            inner: 1,
            polish_lambda: 1.0,
        }
    }
}

impl Params {
    fn check(&self) -> Result<()> {
        if !(self.rate > 0.0 && self.rate < 1.0) {
            return Err(invalid(
                "rate",
                format!("expected 0 < rate < 1, got {}", self.rate),
            ));
        }
        if !(self.final_ratio >= 1.0 && self.final_ratio.is_finite()) {
            return Err(invalid(
                "final_ratio",
                format!("expected a finite ratio >= 1, got {}", self.final_ratio),
            ));
        }
        if let Some(t) = self.t_init {
            if !(t > 0.0 && t.is_finite()) {
                return Err(invalid(
                    "t_init",
                    format!("expected a positive temperature, got {t}"),
                ));
            }
        }
        if self.iterations == 0 {
            return Err(invalid("iterations", "expected at least 1"));
        }
        for (name, v) in [
            ("lambda1", self.lambda1),
            ("lambda2", self.lambda2),
            ("coarse", self.coarse),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(invalid(
                    name,
                    format!("expected a finite value >= 0, got {v}"),
                ));
            }
        }
        Ok(())
    }
}

/// The normalisation of one registration: `p̃ = (p − centre) / scale` for each set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// Centroid of the first set.
    pub cx: Point,
    /// Centroid of the second set.
    pub cy: Point,
    /// The common scale.
    pub scale: f64,
}

/// What [`rpm`] found.
pub struct Rpm {
    /// The spline taking the first set onto the second, in input coordinates.
    pub tps: Tps,
    /// For each point of the first set, the point of the second it is matched with (the
    /// largest entry of its row, unless that is the outlier column).
    pub matches: Vec<Option<usize>>,
    /// The normalisation.
    pub frame: Frame,
    /// The control-point basis in normalised coordinates.
    pub basis: Basis,
    /// The last targets `ŷ` (normalised), one per point of `ctrl`.
    pub targets: Vec<Point>,
    /// The control points of `tps` and `basis` (input coordinates): all of the first set, or
    /// the matched ones after polishing.
    pub ctrl: Vec<Point>,
    /// `λ1` of the last fit (normalised units).
    pub lambda1: f64,
    /// `λ2` of the last fit.
    pub lambda2: f64,
    /// Temperatures visited.
    pub temperatures: usize,
}

fn centroid(p: &[Point]) -> Point {
    let n = p.len() as f64;
    let s = p.iter().fold([0.0, 0.0], |a, q| [a[0] + q[0], a[1] + q[1]]);
    [s[0] / n, s[1] / n]
}

fn rms(p: &[Point], c: Point) -> f64 {
    (p.iter()
        .map(|q| (q[0] - c[0]).powi(2) + (q[1] - c[1]).powi(2))
        .sum::<f64>()
        / p.len() as f64)
        .sqrt()
}

fn check_points(name: &'static str, p: &[Point]) -> Result<()> {
    if p.len() < 3 {
        return Err(invalid(
            name,
            format!("expected at least 3 points, got {}", p.len()),
        ));
    }
    if let Some(i) = p
        .iter()
        .position(|q| !(q[0].is_finite() && q[1].is_finite()))
    {
        return Err(invalid(
            name,
            format!(
                "expected finite coordinates, found ({}, {}) at point {i}",
                p[i][0], p[i][1]
            ),
        ));
    }
    Ok(())
}

/// A spline fitted in normalised coordinates (`p̃ = (p − c_in)/s` to `q̃ = (q − c_out)/s`)
/// as one in input coordinates, with control points `ctrl` (the input-coordinate ones).
///
/// `U(r/s) = (U(r) − r² ln s)/s²` and, because `Σ w = 0` and `Σ w c = 0`, the `r² ln s` terms
/// add up to a constant, so the map is again a thin-plate spline: `w = w̃/s`, the linear part
/// unchanged, and the constant absorbs the shifts.
#[must_use]
pub fn to_input(t: &Tps, ctrl: &[Point], c_in: Point, c_out: Point, s: f64) -> Tps {
    let w: Vec<Point> = t.w.iter().map(|w| [w[0] / s, w[1] / s]).collect();
    let ln = s.ln();
    let mut d0 = [0.0; 2];
    for c in 0..2 {
        let k: f64 =
            t.w.iter()
                .zip(ctrl)
                .map(|(w, p)| w[c] * (p[0] * p[0] + p[1] * p[1]))
                .sum();
        d0[c] = s * t.d[0][c] - c_in[0] * t.d[1][c] - c_in[1] * t.d[2][c] + c_out[c] - ln / s * k;
    }
    Tps {
        ctrl: ctrl.to_vec(),
        w,
        d: [d0, t.d[1], t.d[2]],
    }
}

/// What [`exp_neg`] needs of a float type.
trait Real:
    'static
    + Copy
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Neg<Output = Self>
{
    /// `1.5 · 2^p` for `p` mantissa bits: adding it rounds to an integer.
    const ROUND: Self;
    const LOG2_E: Self;
    const LN_2: Self;
    /// Taylor coefficients of `e^t`, highest degree first.
    const TAYLOR: &'static [Self];
    /// Larger `e` give `exp(−CLAMP)`.
    const CLAMP: Self;
    /// `2^k` from `kb = k + ROUND`: the low mantissa bits of `kb` hold `k` (two's
    /// complement), and `2^k`'s bits are `(k + bias) << p`.
    fn two_pow(kb: Self) -> Self;
}

impl Real for f64 {
    const ROUND: f64 = 6_755_399_441_055_744.0;
    const LOG2_E: f64 = std::f64::consts::LOG2_E;
    const LN_2: f64 = std::f64::consts::LN_2;
    const TAYLOR: &'static [f64] = &[
        1.984_126_984_126_984e-4,
        1.388_888_888_888_889e-3,
        8.333_333_333_333_333e-3,
        4.166_666_666_666_666_4e-2,
        0.166_666_666_666_666_66,
        0.5,
        1.0,
        1.0,
    ];
    // Far below anything that matters next to the outlier entries.
    const CLAMP: f64 = 700.0;
    fn two_pow(kb: f64) -> f64 {
        f64::from_bits(kb.to_bits().wrapping_add(1023) << 52)
    }
}

impl Real for f32 {
    const ROUND: f32 = 12_582_912.0;
    const LOG2_E: f32 = std::f32::consts::LOG2_E;
    const LN_2: f32 = std::f32::consts::LN_2;
    const TAYLOR: &'static [f32] = &[
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ];
    // Far below the outlier entry at `f32` precision, and far enough above the smallest
    // normal number that the balancing products never become subnormal (slow).
    const CLAMP: f32 = 60.0;
    fn two_pow(kb: f32) -> f32 {
        f32::from_bits(kb.to_bits().wrapping_add(127) << 23)
    }
}

/// `exp(−e)` for `e ≥ 0`, branch-free so that a row of kernel entries vectorises: `2^k`
/// from the exponent bits times a Taylor polynomial on `|t| ≤ ln 2 / 2` (degree 7 in `f64`,
/// relative error below 10⁻⁸; degree 6 in `f32`); `e` is clamped to `F::CLAMP`.
#[inline]
fn exp_neg<F: Real>(e: F) -> F {
    let x = -(if e < F::CLAMP { e } else { F::CLAMP }) * F::LOG2_E;
    let kb = x + F::ROUND;
    let k = kb - F::ROUND;
    let t = (x - k) * F::LN_2;
    let mut p = F::TAYLOR[0];
    for &c in &F::TAYLOR[1..] {
        p = p * t + c;
    }
    p * F::two_pow(kb)
}

/// `Σ a_j b_j` in `f32`, eight lanes (one AVX2 register).
#[inline]
fn dot(a: &[f32], b: &[f32]) -> f32 {
    dot_lanes::<f32, 8>(a, b)
}

/// The soft correspondences: the real block of the matrix is `r_i K_ij c_j` (Sinkhorn in
/// scaling form: `K` is filled once per update and each sweep is two passes over it); the
/// outlier column is `r_i o` and the outlier row `o c_j` (neither is normalised itself).
struct Soft {
    m: usize,
    k: Vec<f32>,
    r: Vec<f32>,
    c: Vec<f32>,
    /// `Σ_j K_ij c_j`: row `i`'s real mass is `r_i` times it.
    inl: Vec<f32>,
    col: Vec<f32>,
    /// The second set's coordinates, and times `c`.
    y: [Vec<f32>; 2],
    cy: [Vec<f32>; 2],
}

impl Soft {
    fn new(n: usize, ys: &[Point]) -> Self {
        let m = ys.len();
        Self {
            m,
            k: vec![0.0; n * m],
            r: vec![1.0; n],
            c: vec![1.0; m],
            inl: vec![0.0; n],
            col: vec![0.0; m],
            y: [0, 1].map(|a| ys.iter().map(|p| p[a] as f32).collect()),
            cy: [vec![0.0; m], vec![0.0; m]],
        }
    }

    /// One update at temperature `t` with outlier entry `o`, the first set at `v`: the
    /// kernel, balanced, then each point's inlier mass `ω_i` and target `ŷ_i`.
    #[inline(always)]
    fn update(
        &mut self,
        v: &[Point],
        t: f64,
        o: f64,
        params: &Params,
        weights: &mut [f64],
        targets: &mut [Point],
    ) {
        let m = self.m;
        let (inv_t, norm, o) = ((1.0 / t) as f32, (1.0 / t.sqrt()) as f32, o as f32);
        let [yx, yy] = &self.y;
        for (row, p) in self.k.chunks_exact_mut(m).zip(v) {
            let p = [p[0] as f32, p[1] as f32];
            for ((k, &a), &b) in row.iter_mut().zip(yx).zip(yy) {
                let (dx, dy) = (p[0] - a, p[1] - b);
                *k = norm * exp_neg((dx * dx + dy * dy) * inv_t);
            }
        }
        // Warm start: the column scalings of the last update (the matrix moves little
        // between updates), so a few sweeps suffice.
        for (s, row) in self.inl.iter_mut().zip(self.k.chunks_exact(m)) {
            *s = dot(row, &self.c);
        }
        for sweep in 0..params.sinkhorn {
            for (r, s) in self.r.iter_mut().zip(&self.inl) {
                *r = 1.0 / (s + o);
            }
            self.col.fill(o);
            for (row, &r) in self.k.chunks_exact(m).zip(&self.r) {
                axpy(&mut self.col, r, row);
            }
            for (c, col) in self.c.iter_mut().zip(&self.col) {
                *c = 1.0 / col;
            }
            let mut worst = 0.0f32;
            for ((s, row), r) in self.inl.iter_mut().zip(self.k.chunks_exact(m)).zip(&self.r) {
                *s = dot(row, &self.c);
                worst = worst.max((r * (*s + o) - 1.0).abs());
            }
            // Balanced enough: further sweeps would not move the targets visibly.
            if sweep + 1 == params.sinkhorn || f64::from(worst) < params.tolerance {
                break;
            }
        }
        for (cy, y) in self.cy.iter_mut().zip(&self.y) {
            for ((cy, c), y) in cy.iter_mut().zip(&self.c).zip(y) {
                *cy = c * y;
            }
        }
        for (i, row) in self.k.chunks_exact(m).enumerate() {
            let inl = self.inl[i];
            // The row's inlier mass ω and Chui's target, the mass-weighted mean of the
            // partners.
            weights[i] = f64::from(self.r[i] * inl).clamp(0.0, 1.0);
            targets[i] = if inl > 0.0 {
                [
                    f64::from(dot(row, &self.cy[0]) / inl),
                    f64::from(dot(row, &self.cy[1]) / inl),
                ]
            } else {
                v[i]
            };
        }
    }

    /// Row `i`'s largest real entry `r_i K_ij c_j`: `(j, value)`.
    fn best_column(&self, i: usize) -> (usize, f32) {
        let row = &self.k[i * self.m..(i + 1) * self.m];
        let (j, v) =
            row.iter()
                .zip(&self.c)
                .enumerate()
                .fold((0, f32::NEG_INFINITY), |b, (j, (&k, &c))| {
                    if k * c > b.1 {
                        (j, k * c)
                    } else {
                        b
                    }
                });
        (j, self.r[i] * v)
    }

    /// Column `j`'s largest real entry: its row (the column scaling `c_j` is common to all).
    fn best_row(&self, j: usize) -> usize {
        (0..self.r.len())
            .fold((self.r.len(), f32::NEG_INFINITY), |b, i| {
                let a = self.r[i] * self.k[i * self.m + j];
                if a > b.1 {
                    (i, a)
                } else {
                    b
                }
            })
            .0
    }
}

/// The annealing loop and its state.
struct Anneal<'a> {
    basis: &'a Basis,
    params: &'a Params,
    t_init: f64,
    t_final: f64,
    soft: Soft,
    /// `f(x_i)`.
    v: Vec<Point>,
    /// The targets of the last fit.
    fitted: Vec<Point>,
    weights: Vec<f64>,
    targets: Vec<Point>,
    refit: Refit,
    l1: f64,
    l2: f64,
    temps: usize,
}

impl<'a> Anneal<'a> {
    fn new(basis: &'a Basis, params: &'a Params, xs: &[Point], ys: &[Point], t_init: f64) -> Self {
        Self {
            basis,
            params,
            t_init,
            t_final: t_init / params.final_ratio,
            soft: Soft::new(xs.len(), ys),
            v: xs.to_vec(),
            fitted: xs.to_vec(),
            weights: vec![1.0; xs.len()],
            targets: xs.to_vec(),
            refit: basis.refit_state(),
            l1: 0.0,
            l2: 0.0,
            temps: 0,
        }
    }

    /// The whole loop, compiled for the baseline and for AVX2 and chosen at run time. No
    /// fused multiply-adds are used, so both give bit-identical results.
    fn run(&mut self) -> Result<()> {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2, checked just above.
            return unsafe { self.run_avx2() };
        }
        self.run_any()
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn run_avx2(&mut self) -> Result<()> {
        self.run_any()
    }

    #[inline(always)]
    fn run_any(&mut self) -> Result<()> {
        let params = self.params;
        let n = self.v.len() as f64;
        let k = params.outlier;
        let mut t = self.t_init;
        loop {
            self.temps += 1;
            let o = if k > 0.0 {
                (-k).exp() / t.sqrt()
            } else {
                (-1.0f64).exp() / self.t_init.sqrt()
            };
            let updates = if t > params.coarse {
                1
            } else {
                params.iterations
            };
            for _ in 0..updates {
                cancel::check()?;
                self.soft
                    .update(&self.v, t, o, params, &mut self.weights, &mut self.targets);
                self.l1 = params.lambda1 * n * t;
                self.l2 = params.lambda2 * n * t;
                // The fit weighted by inlier mass, by majorisation: each step fits
                // `ω ŷ + (1 − ω) f(x)` unweighted, so the spline need not follow a point in
                // proportion to the mass it gives the outlier column.
                for _ in 0..params.inner.max(1) {
                    for (((f, &w), y), v) in self
                        .fitted
                        .iter_mut()
                        .zip(&self.weights)
                        .zip(&self.targets)
                        .zip(&self.v)
                    {
                        *f = [w * y[0] + (1.0 - w) * v[0], w * y[1] + (1.0 - w) * v[1]];
                    }
                    self.basis
                        .refit(&self.fitted, self.l1, self.l2, &mut self.refit, &mut self.v);
                }
            }
            t *= params.rate;
            if t < self.t_final {
                return Ok(());
            }
        }
    }
}

/// Registers the point set `x` (named `x_name` in errors) onto `y` by TPS-RPM.
pub fn rpm(
    x: &[Point],
    y: &[Point],
    params: &Params,
    names: (&'static str, &'static str),
) -> Result<Rpm> {
    params.check()?;
    check_points(names.0, x)?;
    check_points(names.1, y)?;
    let (cx, cy) = (centroid(x), centroid(y));
    let scale = rms(x, cx).max(rms(y, cy));
    if scale <= 0.0 {
        return Err(invalid(names.0, "expected points that are not all equal"));
    }
    let xs: Vec<Point> = x
        .iter()
        .map(|p| [(p[0] - cx[0]) / scale, (p[1] - cx[1]) / scale])
        .collect();
    let ys: Vec<Point> = y
        .iter()
        .map(|p| [(p[0] - cy[0]) / scale, (p[1] - cy[1]) / scale])
        .collect();
    let basis = Basis::new(names.0, &xs)?;
    let n = xs.len();
    let d2 = |a: Point, b: Point| (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
    let t_init = params.t_init.unwrap_or_else(|| {
        xs.iter()
            .flat_map(|a| ys.iter().map(move |b| d2(*a, *b)))
            .fold(0.0, f64::max)
    });
    let mut run = Anneal::new(&basis, params, &xs, &ys, t_init);
    run.run()?;
    let Anneal {
        soft,
        fitted,
        refit,
        mut l1,
        l2,
        temps,
        ..
    } = run;
    let mut tps = basis.spline(&refit);
    // The targets the last spline was fitted to (densify refits to them).
    let mut targets = fitted;
    // The last matrix: a row's match is its largest real entry if that holds over a third
    // of the row's mass: with the outlier entry of `Params::outlier`, an exact pair still
    // leaves about half its mass to the outlier column at the end, so "beats the outlier
    // entry" would reject every pair; a third accepts pairs closer than about `√T_final` and
    // no point split between two partners.
    let matches: Vec<Option<usize>> = (0..n)
        .map(|i| {
            let (j, v) = soft.best_column(i);
            (v > 1.0 / 3.0).then_some(j)
        })
        .collect();
    let frame = Frame { cx, cy, scale };
    // Polish: the annealed spline still bends towards the targets of points that ended up
    // outliers (their soft targets pulled at them on the way down). Refit it on the mutual
    // best matches alone, each point's target its partner, with the last bending penalty.
    let mut basis = basis;
    let mut ctrl_in: Vec<Point> = x.to_vec();
    if params.polish {
        // Mutual best: the column's largest real entry is in the row (the outlier row is
        // left out for the reason the matches use a third of the mass).
        let pairs: Vec<(usize, usize)> = matches
            .iter()
            .enumerate()
            .filter_map(|(i, m): (usize, &Option<usize>)| {
                m.filter(|&j| soft.best_row(j) == i).map(|j| (i, j))
            })
            .collect();
        let sub: Vec<Point> = pairs.iter().map(|&(i, _)| xs[i]).collect();
        if let Ok(b) = Basis::new(names.0, &sub) {
            targets = pairs.iter().map(|&(_, j)| ys[j]).collect();
            l1 *= params.polish_lambda;
            tps = b.fit(&targets, l1, l2);
            ctrl_in = pairs.iter().map(|&(i, _)| x[i]).collect();
            basis = b;
        }
    }
    Ok(Rpm {
        tps: to_input(&tps, &ctrl_in, cx, cy, scale),
        matches,
        frame,
        basis,
        targets,
        ctrl: ctrl_in,
        lambda1: l1,
        lambda2: l2,
        temperatures: temps,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::rng::Rng;

    /// A leaf-like outline (pointed ellipse) of `n` points, about 300 × 160 px, plus a
    /// midrib, centred near (250, 200).
    pub(crate) fn leaf(n: usize) -> Vec<Point> {
        let rib = n / 5;
        let outline = n - rib;
        let mut p: Vec<Point> = (0..outline)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / outline as f64;
                // Narrower towards the tip (x > 0): a leaf, not an ellipse.
                let w = 80.0 * (1.0 - 0.35 * a.cos()) * a.sin();
                [250.0 + 150.0 * a.cos(), 200.0 + w]
            })
            .collect();
        p.extend((0..rib).map(|k| {
            [
                120.0 + 260.0 * (k as f64 + 0.5) / rib as f64,
                200.0 + 6.0 * ((k as f64) * 0.7).sin(),
            ]
        }));
        p
    }

    /// A smooth non-rigid warp: rotation, scaling, a bend and a bulge.
    pub(crate) fn warp(p: Point) -> Point {
        let (x, y) = (p[0] - 250.0, p[1] - 200.0);
        let (c, s) = (0.2f64.cos(), 0.2f64.sin());
        let (xr, yr) = (1.1 * (c * x - s * y), 0.95 * (s * x + c * y));
        [
            260.0 + xr + 12.0 * (yr / 60.0).sin(),
            190.0 + yr + 18.0 * (xr / 150.0).powi(2) + 6.0 * (xr / 70.0).sin(),
        ]
    }

    fn mean_error(r: &Rpm, x: &[Point], truth: &[Point]) -> f64 {
        x.iter()
            .zip(truth)
            .map(|(p, q)| {
                let e = r.tps.eval(*p);
                ((e[0] - q[0]).powi(2) + (e[1] - q[1]).powi(2)).sqrt()
            })
            .sum::<f64>()
            / x.len() as f64
    }

    /// A shuffled copy, so that the order of the points says nothing.
    fn shuffled(p: &[Point], seed: u64) -> Vec<Point> {
        let mut q = p.to_vec();
        let mut r = Rng::keyed(seed, 0, 0);
        for i in (1..q.len()).rev() {
            q.swap(i, r.below(i as u64 + 1) as usize);
        }
        q
    }

    #[test]
    fn recovers_a_known_smooth_warp_of_a_leaf_outline() {
        let x = leaf(100);
        let truth: Vec<Point> = x.iter().map(|&p| warp(p)).collect();
        let y = shuffled(&truth, 4);
        let r = rpm(&x, &y, &Params::default(), ("x", "y")).unwrap();
        let e = mean_error(&r, &x, &truth);
        assert!(e <= 2.0, "mean keypoint error {e:.3} px");
        // The matches name the right partners.
        let right = r
            .matches
            .iter()
            .zip(&truth)
            .filter(|(m, q)| {
                m.is_some_and(|j| (y[j][0] - q[0]).abs() + (y[j][1] - q[1]).abs() < 1e-9)
            })
            .count();
        // Points whose row keeps under a third of its mass stay unmatched, not mismatched.
        assert!(right >= 80, "{right} of 100 matches right");
    }

    #[test]
    fn is_robust_to_ten_percent_outliers() {
        let x0 = leaf(100);
        let truth: Vec<Point> = x0.iter().map(|&p| warp(p)).collect();
        // Ten random points added to each set (inside the leaf's box), several draws.
        for seed in 7..13 {
            let mut rng = Rng::keyed(seed, 0, 0);
            let mut u = || (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
            let mut x = x0.clone();
            let mut y = truth.clone();
            for _ in 0..10 {
                x.push([100.0 + 300.0 * u(), 100.0 + 200.0 * u()]);
                y.push([100.0 + 320.0 * u(), 90.0 + 220.0 * u()]);
            }
            let y = shuffled(&y, seed + 100);
            let r = rpm(&x, &y, &Params::default(), ("x", "y")).unwrap();
            let e = mean_error(&r, &x0, &truth);
            assert!(e <= 2.0, "seed {seed}: mean inlier error {e:.3} px");
            // The added points end as outliers, not as partners that bend the spline.
            let kept = r.matches[100..].iter().filter(|m| m.is_some()).count();
            assert!(kept <= 2, "seed {seed}: {kept} of 10 outliers matched");
        }
    }

    #[test]
    fn fast_exp_agrees_with_the_library() {
        for k in 0..4000 {
            let e = f64::from(k) * 0.01;
            let (a, b) = (exp_neg(e), (-e).exp());
            assert!((a - b).abs() <= 1e-8 * b, "exp(-{e}) = {b}, got {a}");
        }
        assert!(exp_neg(1e6) >= 0.0 && exp_neg(1e6) < 1e-300);
    }

    #[test]
    fn fast_exp_in_f32_agrees_with_the_library() {
        let mut worst = 0.0f64;
        for k in 0..6000 {
            let e = k as f32 * 0.01;
            let (a, b) = (f64::from(exp_neg(e)), (-f64::from(e)).exp());
            // Rounding `log2 e` and `e · log2 e` to `f32` costs up to `e · 2⁻²⁴` relative
            // each; the rest is the polynomial.
            let bound = 2e-7 + f64::from(e) * 2f64.powi(-23);
            worst = worst.max((a - b).abs() / b / bound);
        }
        assert!(worst <= 1.0, "error {worst:.2} times the bound");
        // Clamped, and still a normal number.
        assert!(
            exp_neg(1e6f32).is_normal() && exp_neg(1e6f32).to_bits() == exp_neg(60.0f32).to_bits()
        );
    }

    /// The loop compiled for AVX2 gives the portable loop's state to the bit.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_avx2_loop_equals_the_portable_one() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        let x: Vec<Point> = leaf(60)
            .iter()
            .map(|p| [p[0] / 100.0 - 2.5, p[1] / 100.0 - 2.0])
            .collect();
        let y: Vec<Point> = x
            .iter()
            .map(|&p| [p[0] * 1.1 + 0.05 * p[1], p[1] * 0.9 + 0.1 * p[0] * p[0]])
            .collect();
        let basis = Basis::new("x", &x).unwrap();
        let params = Params::default();
        let mut a = Anneal::new(&basis, &params, &x, &y, 4.0);
        let mut b = Anneal::new(&basis, &params, &x, &y, 4.0);
        a.run_any().unwrap();
        // SAFETY: the CPU supports AVX2, checked above.
        unsafe { b.run_avx2() }.unwrap();
        assert!(a.temps > 100 && a.v == b.v && a.soft.k == b.soft.k && a.soft.c == b.soft.c);
    }

    #[test]
    fn input_coordinates_agree_with_the_normalised_spline() {
        let x = leaf(40);
        let y: Vec<Point> = x.iter().map(|&p| warp(p)).collect();
        let r = rpm(&x, &y, &Params::default(), ("x", "y")).unwrap();
        let fr = r.frame;
        let t = r.basis.fit(&r.targets, r.lambda1, r.lambda2);
        for p in [[100.0, 120.0], [250.0, 200.0], [400.0, 300.0]] {
            let pn = [(p[0] - fr.cx[0]) / fr.scale, (p[1] - fr.cx[1]) / fr.scale];
            let qn = t.eval(pn);
            let q = r.tps.eval(p);
            let back = [qn[0] * fr.scale + fr.cy[0], qn[1] * fr.scale + fr.cy[1]];
            assert!(
                (q[0] - back[0]).abs() < 1e-6 && (q[1] - back[1]).abs() < 1e-6,
                "{q:?} {back:?}"
            );
        }
    }

    #[test]
    fn rejects_bad_parameters_in_one_line() {
        let x = leaf(20);
        let e = |p: Params| rpm(&x, &x, &p, ("x", "y")).err().unwrap().to_string();
        assert_eq!(
            e(Params {
                rate: 1.0,
                ..Params::default()
            }),
            "rate: expected 0 < rate < 1, got 1"
        );
        assert!(e(Params {
            lambda1: -1.0,
            ..Params::default()
        })
        .starts_with("lambda1:"));
        let few = rpm(&x, &x[..2], &Params::default(), ("x", "y"))
            .err()
            .unwrap();
        assert_eq!(few.to_string(), "y: expected at least 3 points, got 2");
    }
}
