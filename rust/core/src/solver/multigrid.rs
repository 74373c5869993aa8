//! Geometric multigrid on masked pixel grids: the preconditioner (and first guess) of the
//! Poisson solves in [`crate::poisson`] and the preconditioner of the smooth fields in
//! [`crate::field`].
//!
//! Every level is an odd-sized `h × w` grid whose border (a frame one cell wide) holds no
//! unknowns, so stencils never leave the grid. The finest level is the 5-point pixel
//! Laplacian of a masked region (diagonal = number of neighbours, −1 to each neighbour that is
//! an unknown; Dirichlet and Neumann conditions live in the diagonal). Coarse point `i` sits on
//! fine point `2i − 1`; prolongation `P` is bilinear interpolation restricted to the fine
//! unknowns, restriction is `Pᵀ`, and coarse operators are Galerkin products `Pᵀ A P`, which
//! stay 9-point (Wesseling, *An Introduction to Multigrid Methods*, 1992, §6.2; Dendy's
//! `BoxMG`). Galerkin coarsening needs no rule for irregular boundaries, holes, one-pixel-wide
//! strands or pinned pixels: the coarse operators inherit them from the fine one. A coarse
//! operator can be singular where `P` loses rank on thin strands, but the coarse equations are
//! always consistent (their right-hand sides lie in the range of `Pᵀ`), and the smoother and
//! the regularised coarsest solve handle that.
//!
//! The smoother is multicolour Gauss–Seidel: red–black on the 5-point level, four colours on the
//! 9-point levels. Points of one colour are independent, so rows are updated in parallel (each
//! band of rows gets copies of the two rows that border it) and the result does not depend on
//! the number of threads. Pre-smoothing runs the colours forward and post-smoothing backward,
//! which makes the V-cycle a symmetric operator, as preconditioned conjugate gradients needs.
//!
//! Vectors hold `L` independent right-hand sides per point (`[f32; L]`), so the three colour
//! channels of an image are smoothed in one sweep with SIMD lanes.

// Lane loops index several arrays in lockstep; the index form is what vectorises.
#![allow(clippy::needless_range_loop)]

use rayon::prelude::*;

use super::bands::{rows_mut, BAND, PARALLEL_CELLS};
use super::cholesky::Cholesky;
use super::pcg::Preconditioner;

/// Coarsening stops once a level has at most this many unknowns; it is solved densely.
const COARSEST: usize = 64;

/// The operator of one level.
pub(crate) enum Stencil {
    /// The pixel Laplacian: `diag[p]·x_p − Σ x_q` over the 4 neighbours; `diag` is 0 off the
    /// unknowns and `x` is kept 0 there.
    Five(Vec<f32>),
    /// Nine coefficients per point over its 3×3 neighbourhood (row-major, centre at 4); zero
    /// rows and columns off the unknowns.
    Nine(Vec<[f32; 9]>),
}

/// One level of the hierarchy.
pub(crate) struct Level {
    pub h: usize,
    pub w: usize,
    pub stencil: Stencil,
    /// `1 / diagonal` at the unknowns, 0 elsewhere.
    pub inv: Vec<f32>,
    /// Number of unknowns.
    pub n: usize,
    /// The row of an unknown whose neighbourhood is all unknowns (the fast path of coarsening).
    interior: [f32; 9],
    /// Per cell: an unknown (off the frame) whose row is exactly `interior`.
    is_interior: Vec<bool>,
}

impl Level {
    /// The finest level from a per-cell diagonal (0 off the unknowns).
    pub fn five(h: usize, w: usize, diag: Vec<f32>) -> Self {
        debug_assert!(h % 2 == 1 && w % 2 == 1 && diag.len() == h * w);
        let inv: Vec<f32> = diag
            .iter()
            .map(|&d| if d > 0.0 { 1.0 / d } else { 0.0 })
            .collect();
        let n = diag.iter().filter(|&&d| d > 0.0).count();
        // Interior rows: diagonal 4 and all four neighbours unknown.
        let mut is_interior = vec![false; h * w];
        rows_mut(&mut is_interior, w, |y, row| {
            if y == 0 || y == h - 1 {
                return;
            }
            let o = y * w;
            let (up, cur, dn) = (&diag[o - w..o], &diag[o..o + w], &diag[o + w..o + 2 * w]);
            for x in 1..w - 1 {
                #[allow(clippy::float_cmp)]
                let four = cur[x] == 4.0;
                row[x] = four && cur[x - 1] > 0.0 && cur[x + 1] > 0.0 && up[x] > 0.0 && dn[x] > 0.0;
            }
        });
        Self {
            h,
            w,
            stencil: Stencil::Five(diag),
            inv,
            n,
            interior: [0.0, -1.0, 0.0, -1.0, 4.0, -1.0, 0.0, -1.0, 0.0],
            is_interior,
        }
    }

    /// Coefficient `k` (3×3 row-major offset, 4 = centre) of row `p`.
    #[inline]
    fn coef(&self, p: usize, k: usize) -> f32 {
        match &self.stencil {
            Stencil::Nine(a) => a[p][k],
            Stencil::Five(d) => {
                if d[p] == 0.0 {
                    return 0.0;
                }
                match k {
                    4 => d[p],
                    1 | 3 | 5 | 7 => {
                        let q = (p + k / 3 * self.w + k % 3) - self.w - 1;
                        if d[q] > 0.0 {
                            -1.0
                        } else {
                            0.0
                        }
                    }
                    _ => 0.0,
                }
            }
        }
    }

    /// Row `p` of the operator as 9 coefficients over the 3×3 neighbourhood.
    #[inline]
    fn row9(&self, p: usize) -> [f32; 9] {
        match &self.stencil {
            Stencil::Nine(a) => a[p],
            Stencil::Five(d) => {
                let w = self.w;
                let off = |q: usize| if d[q] > 0.0 { -1.0 } else { 0.0 };
                [
                    0.0,
                    off(p - w),
                    0.0,
                    off(p - 1),
                    d[p],
                    off(p + 1),
                    0.0,
                    off(p + w),
                    0.0,
                ]
            }
        }
    }

    /// The Galerkin coarse level `Pᵀ A P`.
    fn coarsen(&self) -> Self {
        let (hf, wf) = (self.h, self.w);
        let hc = (hf / 2 + 2) | 1;
        let wc = (wf / 2 + 2) | 1;
        // Where the 3×3 fine points under a coarse point all carry the interior stencil, the
        // coarse row is a constant: compute it once.
        let interior = galerkin_row(2, 2, |_, _| Some(self.interior));
        let flags = &self.is_interior;
        let row_at = |fy: usize, fx: usize| {
            if fy == 0 || fy >= hf - 1 || fx == 0 || fx >= wf - 1 {
                return None;
            }
            let f = fy * wf + fx;
            (self.inv[f] > 0.0).then(|| self.row9(f))
        };
        let mut a = vec![[0f32; 9]; hc * wc];
        let mut fast = vec![false; hc * wc];
        let row = |i: usize, (out, fast): (&mut [[f32; 9]], &mut [bool])| {
            if i == 0 || 2 * i >= hf {
                return;
            }
            for (j, cell) in out.iter_mut().enumerate().take(wc - 1).skip(1) {
                if 2 * j >= wf {
                    break;
                }
                let o = (2 * i - 1) * wf + 2 * j - 1;
                let all = [
                    o - wf - 1,
                    o - wf,
                    o - wf + 1,
                    o - 1,
                    o,
                    o + 1,
                    o + wf - 1,
                    o + wf,
                    o + wf + 1,
                ]
                .iter()
                .all(|&f| flags[f]);
                fast[j] = all;
                *cell = if all {
                    interior
                } else {
                    galerkin_row(i, j, row_at)
                };
            }
        };
        if hc * wc >= PARALLEL_CELLS / 4 {
            a.par_chunks_mut(wc)
                .zip(fast.par_chunks_mut(wc))
                .enumerate()
                .for_each(|(i, r)| row(i, r));
        } else {
            a.chunks_mut(wc)
                .zip(fast.chunks_mut(wc))
                .enumerate()
                .for_each(|(i, r)| row(i, r));
        }
        // The two halves of each symmetric pair were summed in different orders; make the
        // stored operator exactly symmetric so the V-cycle is too.
        for p in 0..hc * wc {
            for k in 5..9 {
                let q = p + k / 3 * wc + k % 3 - wc - 1;
                if q < a.len() {
                    a[q][8 - k] = a[p][k];
                }
            }
        }
        let inv: Vec<f32> = a
            .iter()
            .map(|s| if s[4] > 0.0 { 1.0 / s[4] } else { 0.0 })
            .collect();
        let n = inv.iter().filter(|&&v| v > 0.0).count();
        // Rows that are exactly the interior stencil (exact comparison on purpose: the fast
        // path must give the bits the slow one would). A row computed the slow way that
        // happens to equal it is left unflagged: the slow path then gives the same bits.
        #[allow(clippy::float_cmp)]
        let is_interior = fast
            .iter()
            .zip(&a)
            .map(|(&f, row)| f && *row == interior)
            .collect();
        Self {
            h: hc,
            w: wc,
            stencil: Stencil::Nine(a),
            inv,
            n,
            interior,
            is_interior,
        }
    }
}

/// Row `(i, j)` of the Galerkin product `Pᵀ A P`, from the fine rows `row_at(fy, fx)` (`None`
/// off the unknowns). Coarse `i` sits on fine `2i − 1`.
fn galerkin_row(i: usize, j: usize, row_at: impl Fn(usize, usize) -> Option<[f32; 9]>) -> [f32; 9] {
    // Parents of fine row/column t: (first coarse index, its weight, weight of the next).
    let par = |t: usize| -> (usize, f64, f64) {
        if t % 2 == 1 {
            (t.div_ceil(2), 1.0, 0.0)
        } else {
            (t / 2, 0.5, 0.5)
        }
    };
    let mut acc = [0f64; 9];
    for fy in (2 * i - 2)..=(2 * i) {
        let wy = if fy == 2 * i - 1 { 1.0 } else { 0.5 };
        for fx in (2 * j - 2)..=(2 * j) {
            let Some(st) = row_at(fy, fx) else { continue };
            let wfi = wy * if fx == 2 * j - 1 { 1.0 } else { 0.5 };
            for (k, &c) in st.iter().enumerate() {
                if c == 0.0 {
                    continue;
                }
                let v = wfi * f64::from(c);
                let (jy, ay, by) = par(fy + k / 3 - 1);
                let (jx, ax, bx) = par(fx + k % 3 - 1);
                let (ky, kx) = (jy + 1 - i, jx + 1 - j);
                acc[ky * 3 + kx] += v * ay * ax;
                if bx != 0.0 {
                    acc[ky * 3 + kx + 1] += v * ay * bx;
                }
                if by != 0.0 {
                    acc[ky * 3 + 3 + kx] += v * by * ax;
                    if bx != 0.0 {
                        acc[ky * 3 + 3 + kx + 1] += v * by * bx;
                    }
                }
            }
        }
    }
    acc.map(|v| v as f32)
}

/// A dense Cholesky factor of the coarsest level (regularised: the level may be singular).
struct Coarsest {
    /// Grid index of each unknown.
    cells: Vec<usize>,
    factor: Cholesky,
}

impl Coarsest {
    fn new(lev: &Level) -> Self {
        let cells: Vec<usize> = (0..lev.h * lev.w).filter(|&p| lev.inv[p] > 0.0).collect();
        let n = cells.len();
        let mut pos = vec![usize::MAX; lev.h * lev.w];
        for (i, &p) in cells.iter().enumerate() {
            pos[p] = i;
        }
        let mut m = vec![0f64; n * n];
        let mut dmax = 0f64;
        for (i, &p) in cells.iter().enumerate() {
            for k in 0..9 {
                let c = lev.coef(p, k);
                if c != 0.0 {
                    let q = p + k / 3 * lev.w + k % 3 - lev.w - 1;
                    m[i * n + pos[q]] = f64::from(c);
                }
            }
            dmax = dmax.max(m[i * n + i]);
        }
        // A singular coarse operator comes with consistent right-hand sides, and any solution
        // gives the same prolonged correction; the shift only makes the factor exist.
        let factor = Cholesky::new(m, n, 1e-9 * dmax, 1e-12 * dmax);
        Self { cells, factor }
    }

    fn solve<const L: usize>(&self, b: &[[f32; L]], x: &mut [[f32; L]]) {
        let mut y: Vec<[f64; L]> = self.cells.iter().map(|&p| b[p].map(f64::from)).collect();
        self.factor.solve(&mut y);
        for (v, &p) in y.iter().zip(&self.cells) {
            x[p] = v.map(|t| t as f32);
        }
    }
}

/// The hierarchy: levels from fine to coarse and the factor of the coarsest.
pub(crate) struct Hierarchy {
    pub levels: Vec<Level>,
    coarsest: Coarsest,
}

/// Per-level vectors of one V-cycle.
pub(crate) struct Work<const L: usize> {
    x: Vec<Vec<[f32; L]>>,
    b: Vec<Vec<[f32; L]>>,
    r: Vec<Vec<[f32; L]>>,
}

impl Hierarchy {
    /// Coarsens `fine` until a level has at most a few hundred unknowns.
    pub fn new(fine: Level) -> Self {
        let mut levels = vec![fine];
        loop {
            let last = levels.last().expect("at least the fine level");
            if last.n <= COARSEST || last.h <= 3 && last.w <= 3 {
                break;
            }
            let next = last.coarsen();
            levels.push(next);
        }
        let coarsest = Coarsest::new(levels.last().expect("at least the fine level"));
        Self { levels, coarsest }
    }

    /// Zeroed work vectors for `L` lanes.
    pub fn work<const L: usize>(&self) -> Work<L> {
        // Level 0's `x` and `b` are the caller's vectors, and its residual is restricted as it
        // is computed (`restrict_residual_five`).
        let z = |fine: bool| {
            self.levels
                .iter()
                .enumerate()
                .map(|(i, l)| {
                    if i == 0 && !fine {
                        Vec::new()
                    } else {
                        vec![[0f32; L]; l.h * l.w]
                    }
                })
                .collect::<Vec<_>>()
        };
        Work {
            x: z(false),
            b: z(false),
            r: z(false),
        }
    }

    /// `z = M⁻¹ r`: one symmetric V(1,1)-cycle from a zero guess. `r` and `z` live on the fine
    /// grid and are 0 off the unknowns. Returns `⟨r, z⟩` per lane, summed in `f64` over bands
    /// of [`BAND`] rows in a fixed order (computed in the last smoothing sweep).
    pub fn vcycle<const L: usize>(
        &self,
        ws: &mut Work<L>,
        r: &[[f32; L]],
        z: &mut [[f32; L]],
    ) -> [f64; L] {
        let lev = &self.levels[0];
        if self.levels.len() == 1 {
            self.coarsest.solve(r, z);
            return dot_bands(r, z, lev.w);
        }
        let coarse = &self.levels[1];
        let mut bc = std::mem::take(&mut ws.b[1]);
        let mut xc = std::mem::take(&mut ws.x[1]);
        if matches!(lev.stencil, Stencil::Five(_)) {
            // The first sweeps from zero in one pass, and the residual restricted as it is
            // computed: the same values as the general path, fewer passes over the fine grid.
            presmooth_five(lev, r, z);
            restrict_residual_five(lev, coarse, z, r, &mut bc);
        } else {
            smooth(lev, z, r, true);
            residual(lev, z, r, &mut ws.r[0]);
            restrict(lev, coarse, &ws.r[0], &mut bc);
        }
        self.cycle(ws, 1, &bc, &mut xc);
        prolong_add(lev, coarse, &xc, z);
        ws.b[1] = bc;
        ws.x[1] = xc;
        let parts = postsmooth(lev, z, r, true);
        let mut s = [0f64; L];
        for p in &parts {
            for c in 0..L {
                s[c] += p[c];
            }
        }
        s
    }

    /// A first guess for `A x = b` on the fine level by nested iteration (full multigrid):
    /// `b` restricted to every level, the coarsest solved exactly, and going up, each level
    /// starts from the prolonged solution of the one below and takes one V-cycle on its
    /// residual (level 1 one symmetric Gauss–Seidel sweep); the fine level gets the prolonged
    /// solution of level 1 (the caller's first preconditioned step smooths it). `b` is 0 off
    /// the unknowns; so is the result.
    pub fn full_multigrid<const L: usize>(
        &self,
        ws: &mut Work<L>,
        b: &[[f32; L]],
        x: &mut [[f32; L]],
    ) {
        let nl = self.levels.len();
        if nl == 1 {
            self.coarsest.solve(b, x);
            return;
        }
        // Right-hand sides of levels 1.. (index l − 1).
        let mut bs: Vec<Vec<[f32; L]>> = Vec::with_capacity(nl - 1);
        for l in 1..nl {
            let (fine, coarse) = (&self.levels[l - 1], &self.levels[l]);
            let mut bc = vec![[0f32; L]; coarse.h * coarse.w];
            restrict(fine, coarse, if l == 1 { b } else { &bs[l - 2] }, &mut bc);
            bs.push(bc);
        }
        let last = &self.levels[nl - 1];
        let mut xl = vec![[0f32; L]; last.h * last.w];
        self.coarsest.solve(&bs[nl - 2], &mut xl);
        for l in (1..nl - 1).rev() {
            let (lev, coarse) = (&self.levels[l], &self.levels[l + 1]);
            let mut xf = vec![[0f32; L]; lev.h * lev.w];
            prolong_add(lev, coarse, &xl, &mut xf);
            let mut r = vec![[0f32; L]; lev.h * lev.w];
            full_residual(lev, &xf, &bs[l - 1], &mut r);
            let mut e = vec![[0f32; L]; lev.h * lev.w];
            if l == 1 {
                // Level 1 only smooths: a V-cycle there buys no accuracy for its cost.
                smooth(lev, &mut e, &r, true);
                postsmooth(lev, &mut e, &r, false);
            } else {
                self.cycle(ws, l, &r, &mut e);
            }
            for (xv, ev) in xf.iter_mut().zip(&e) {
                for c in 0..L {
                    xv[c] += ev[c];
                }
            }
            xl = xf;
        }
        x.fill([0.0; L]);
        prolong_add(&self.levels[0], &self.levels[1], &xl, x);
    }

    fn cycle<const L: usize>(
        &self,
        ws: &mut Work<L>,
        l: usize,
        b: &[[f32; L]],
        x: &mut [[f32; L]],
    ) {
        let lev = &self.levels[l];
        if l + 1 == self.levels.len() {
            self.coarsest.solve(b, x);
            return;
        }
        smooth(lev, x, b, true);
        residual(lev, x, b, &mut ws.r[l]);
        let coarse = &self.levels[l + 1];
        let mut bc = std::mem::take(&mut ws.b[l + 1]);
        let mut xc = std::mem::take(&mut ws.x[l + 1]);
        restrict(lev, coarse, &ws.r[l], &mut bc);
        self.cycle(ws, l + 1, &bc, &mut xc);
        prolong_add(lev, coarse, &xc, x);
        ws.b[l + 1] = bc;
        ws.x[l + 1] = xc;
        postsmooth(lev, x, b, false);
    }
}

/// One V-cycle of a hierarchy as the preconditioner of [`super::pcg::pcg`], and full
/// multigrid as its first guess.
pub(crate) struct VCycle<'a, const L: usize> {
    mg: &'a Hierarchy,
    ws: Work<L>,
}

impl<'a, const L: usize> VCycle<'a, L> {
    pub fn new(mg: &'a Hierarchy) -> Self {
        Self { mg, ws: mg.work() }
    }
}

impl<const L: usize> Preconditioner<f32, L> for VCycle<'_, L> {
    fn apply(&mut self, r: &[[f32; L]], z: &mut [[f32; L]]) -> [f64; L] {
        self.mg.vcycle(&mut self.ws, r, z)
    }

    fn first_guess(&mut self, b: &[[f32; L]], x: &mut [[f32; L]]) -> bool {
        self.mg.full_multigrid(&mut self.ws, b, x);
        true
    }
}

/// `⟨u, v⟩` per lane and band of [`BAND`] rows, in `f64`.
fn dot_bands<const L: usize>(u: &[[f32; L]], v: &[[f32; L]], w: usize) -> [f64; L] {
    let mut s = [0f64; L];
    for (a, b) in u.chunks(BAND * w).zip(v.chunks(BAND * w)) {
        let mut t = [0f64; L];
        for (x, y) in a.iter().zip(b) {
            for c in 0..L {
                t[c] += f64::from(x[c]) * f64::from(y[c]);
            }
        }
        for c in 0..L {
            s[c] += t[c];
        }
    }
    s
}

/// Colours of a level: 2 (red–black) for the 5-point operator, 4 for the 9-point ones.
fn colours(lev: &Level) -> usize {
    match lev.stencil {
        Stencil::Five(_) => 2,
        Stencil::Nine(_) => 4,
    }
}

/// One multicolour Gauss–Seidel sweep forward from a zero `x` (which it overwrites).
fn smooth<const L: usize>(lev: &Level, x: &mut [[f32; L]], b: &[[f32; L]], pre: bool) {
    debug_assert!(pre);
    let nc = colours(lev);
    for colour in 0..nc {
        // The first step from zero also writes the zeros of the other colours.
        sweep(lev, x, b, colour, colour == 0, false);
    }
}

/// One multicolour Gauss–Seidel sweep backward from the current `x`. With `dot`, also returns
/// `⟨b, x⟩` of the result per band of [`BAND`] rows (summed row-major within the band, as the
/// last colour finishes each row); otherwise an empty vector.
fn postsmooth<const L: usize>(
    lev: &Level,
    x: &mut [[f32; L]],
    b: &[[f32; L]],
    dot: bool,
) -> Vec<[f64; L]> {
    let nc = colours(lev);
    for step in 0..nc - 1 {
        sweep(lev, x, b, nc - 1 - step, false, false);
    }
    sweep(lev, x, b, 0, false, dot)
}

/// Updates the points of one colour in place, bands of rows in parallel. With `dot`, returns
/// `⟨b, x⟩` per band after the update (all colours but this one must be final); otherwise an
/// empty vector.
fn sweep<const L: usize>(
    lev: &Level,
    x: &mut [[f32; L]],
    b: &[[f32; L]],
    colour: usize,
    zero: bool,
    dot: bool,
) -> Vec<[f64; L]> {
    let (h, w) = (lev.h, lev.w);
    let band_rows = |y0: usize, band: &mut [[f32; L]], above: &[[f32; L]], below: &[[f32; L]]| {
        let rows = band.len() / w;
        let mut acc = [0f64; L];
        for yy in 0..rows {
            let y = y0 + yy;
            if y == 0 || y == h - 1 {
                // Zeros: nothing to update, nothing to add to the dot product.
                continue;
            }
            let (before, rest) = band.split_at_mut(yy * w);
            let (cur, after) = rest.split_at_mut(w);
            let up = if yy == 0 {
                above
            } else {
                &before[before.len() - w..]
            };
            let down = if yy + 1 == rows { below } else { &after[..w] };
            let o = y * w;
            update_row(lev, &mut *cur, up, down, &b[o..o + w], y, colour, zero);
            if dot {
                for (xv, bv) in cur.iter().zip(&b[o..o + w]) {
                    for c in 0..L {
                        acc[c] += f64::from(bv[c]) * f64::from(xv[c]);
                    }
                }
            }
        }
        acc
    };
    let parts = bands_mut(x, h, w, zero, band_rows);
    if dot {
        parts
    } else {
        Vec::new()
    }
}

/// Row `y` (`cur`, with the rows `up` and `down` around it and right-hand side `b`) of a sweep
/// over `colour`; `zero`: from a zero iterate (the row is overwritten).
#[inline]
fn update_row<const L: usize>(
    lev: &Level,
    cur: &mut [[f32; L]],
    up: &[[f32; L]],
    down: &[[f32; L]],
    b: &[[f32; L]],
    y: usize,
    colour: usize,
    zero: bool,
) {
    let w = lev.w;
    let inv = &lev.inv[y * w..(y + 1) * w];
    match &lev.stencil {
        Stencil::Five(_) if zero => {
            let start = if (1 + y) % 2 == colour { 1 } else { 2 };
            cur.fill([0.0; L]);
            for xi in (start..w - 1).step_by(2) {
                cur[xi] = b[xi].map(|t| t * inv[xi]);
            }
        }
        Stencil::Nine(_) if zero => {
            cur.fill([0.0; L]);
            if y % 2 != colour / 2 {
                return;
            }
            let start = if colour % 2 == 1 { 1 } else { 2 };
            for xi in (start..w - 1).step_by(2) {
                cur[xi] = b[xi].map(|t| t * inv[xi]);
            }
        }
        Stencil::Five(_) => {
            let start = if (1 + y) % 2 == colour { 1 } else { 2 };
            let (up, down) = (&up[..w], &down[..w]);
            for xi in (start..w - 1).step_by(2) {
                let bb = b[xi];
                let (l, r, u, d) = (cur[xi - 1], cur[xi + 1], up[xi], down[xi]);
                let mut v = [0f32; L];
                for c in 0..L {
                    v[c] = inv[xi] * (bb[c] + l[c] + r[c] + u[c] + d[c]);
                }
                cur[xi] = v;
            }
        }
        Stencil::Nine(a) => {
            if y % 2 != colour / 2 {
                return;
            }
            let a = &a[y * w..(y + 1) * w];
            let (up, down) = (&up[..w], &down[..w]);
            let start = if colour % 2 == 1 { 1 } else { 2 };
            for xi in (start..w - 1).step_by(2) {
                if inv[xi] == 0.0 {
                    continue;
                }
                let s = &a[xi];
                let mut v = b[xi];
                for k in [0, 1, 2] {
                    let n = up[xi + k - 1];
                    let m = down[xi + k - 1];
                    for c in 0..L {
                        v[c] -= s[k] * n[c] + s[k + 6] * m[c];
                    }
                }
                let (l, r) = (cur[xi - 1], cur[xi + 1]);
                for c in 0..L {
                    v[c] -= s[3] * l[c] + s[5] * r[c];
                }
                cur[xi] = v.map(|t| t * inv[xi]);
            }
        }
    }
}

/// Calls `f(first_row, band, row_above, row_below)` on bands of [`BAND`] rows, in parallel on
/// large grids, and returns the results in band order. The bordering rows are copies taken before any band runs (empty when `no_halo`
/// or at the grid edge).
fn bands_mut<T: Copy + Send + Sync, R: Send>(
    x: &mut [T],
    h: usize,
    w: usize,
    no_halo: bool,
    f: impl Fn(usize, &mut [T], &[T], &[T]) -> R + Sync,
) -> Vec<R> {
    let nb = h.div_ceil(BAND);
    let halos: Vec<(Vec<T>, Vec<T>)> = if no_halo {
        Vec::new()
    } else {
        (0..nb)
            .map(|i| {
                let y0 = i * BAND;
                let y1 = (y0 + BAND).min(h);
                let above = if y0 > 0 {
                    x[(y0 - 1) * w..y0 * w].to_vec()
                } else {
                    Vec::new()
                };
                let below = if y1 < h {
                    x[y1 * w..(y1 + 1) * w].to_vec()
                } else {
                    Vec::new()
                };
                (above, below)
            })
            .collect()
    };
    let empty: &[T] = &[];
    let run = |(i, band): (usize, &mut [T])| {
        let (a, b) = halos
            .get(i)
            .map_or((empty, empty), |(a, b)| (a.as_slice(), b.as_slice()));
        f(i * BAND, band, a, b)
    };
    if h * w >= PARALLEL_CELLS {
        x.par_chunks_mut(BAND * w).enumerate().map(run).collect()
    } else {
        x.chunks_mut(BAND * w).enumerate().map(run).collect()
    }
}

/// `r = b − A x` after pre-smoothing, 0 off the unknowns. The colour updated last has a zero
/// residual (its equations were just solved), so only the others are computed.
fn residual<const L: usize>(lev: &Level, x: &[[f32; L]], b: &[[f32; L]], r: &mut [[f32; L]]) {
    let (h, w) = (lev.h, lev.w);
    rows_mut(r, w, |y, out| {
        out.fill([0.0; L]);
        if y == 0 || y == h - 1 {
            return;
        }
        let o = y * w;
        match &lev.stencil {
            Stencil::Five(d) => {
                // Colour 1 (x + y odd) was updated last.
                for xi in ((2 - y % 2)..w - 1).step_by(2) {
                    let p = o + xi;
                    if d[p] == 0.0 {
                        continue;
                    }
                    let (c0, l, rr, u, dn) = (x[p], x[p - 1], x[p + 1], x[p - w], x[p + w]);
                    let mut v = b[p];
                    for c in 0..L {
                        v[c] -= d[p] * c0[c] - (l[c] + rr[c] + u[c] + dn[c]);
                    }
                    out[xi] = v;
                }
            }
            Stencil::Nine(a) => {
                for xi in 1..w - 1 {
                    let p = o + xi;
                    // Colour 3 (odd row, odd column) was updated last.
                    if lev.inv[p] == 0.0 || (y % 2 == 1 && xi % 2 == 1) {
                        continue;
                    }
                    let s = &a[p];
                    let mut v = b[p];
                    for k in 0..9 {
                        let q = x[p + k / 3 * w + k % 3 - w - 1];
                        for c in 0..L {
                            v[c] -= s[k] * q[c];
                        }
                    }
                    out[xi] = v;
                }
            }
        }
    });
}

/// The two red–black sweeps of pre-smoothing from a zero iterate on the 5-point level, in one
/// pass: colour 0 (`x + y` even) gets `b / d`, colour 1 then
/// `(b + Σ_neighbours b_q / d_q) / d` — the values of [`smooth`], read from `b` alone, so rows
/// need no halo.
fn presmooth_five<const L: usize>(lev: &Level, b: &[[f32; L]], x: &mut [[f32; L]]) {
    let (h, w) = (lev.h, lev.w);
    let inv = &lev.inv;
    rows_mut(x, w, |y, out| {
        out.fill([0.0; L]);
        if y == 0 || y == h - 1 {
            return;
        }
        let o = y * w;
        let (bu, bc, bd) = (&b[o - w..o], &b[o..o + w], &b[o + w..o + 2 * w]);
        let (iu, ic, id) = (&inv[o - w..o], &inv[o..o + w], &inv[o + w..o + 2 * w]);
        // Colour 0 where x + y is even.
        for xi in ((2 - y % 2)..w - 1).step_by(2) {
            out[xi] = bc[xi].map(|t| t * ic[xi]);
        }
        for xi in ((1 + y % 2)..w - 1).step_by(2) {
            let (l, r) = (bc[xi - 1], bc[xi + 1]);
            let (u, d) = (bu[xi], bd[xi]);
            let (il, ir, iuu, idd) = (ic[xi - 1], ic[xi + 1], iu[xi], id[xi]);
            let bb = bc[xi];
            let mut v = [0f32; L];
            for c in 0..L {
                v[c] = ic[xi] * (bb[c] + l[c] * il + r[c] * ir + u[c] * iuu + d[c] * idd);
            }
            out[xi] = v;
        }
    });
}

/// `bc = Pᵀ (b − A x)` on the 5-point level right after [`presmooth_five`]: the residual is zero
/// on colour 1 (just solved), so each coarse point gathers the residual of its fine centre
/// and, weighted ¼, of its four corners. The residual of each fine row is computed once per
/// band of coarse rows (plus one shared row at the band's top) and never stored whole.
fn restrict_residual_five<const L: usize>(
    fine: &Level,
    coarse: &Level,
    x: &[[f32; L]],
    b: &[[f32; L]],
    bc: &mut [[f32; L]],
) {
    let Stencil::Five(d) = &fine.stencil else {
        unreachable!("restrict_residual_five on a 9-point level")
    };
    let (hf, wf, hc, wc) = (fine.h, fine.w, coarse.h, coarse.w);
    // Residual at fine (y, 2k) for y even (its colour-0 points), into `out[k]`.
    let even_row = |y: usize, out: &mut [[f32; L]]| {
        out.fill([0.0; L]);
        if y == 0 || y >= hf - 1 {
            return;
        }
        let o = y * wf;
        for (k, cell) in out.iter_mut().enumerate() {
            let xi = 2 * k;
            if xi == 0 || xi >= wf - 1 {
                continue;
            }
            *cell = res_at(d, x, b, o + xi, wf);
        }
    };
    let band = |(bi, rows): (usize, &mut [[f32; L]])| {
        let i0 = bi * BAND;
        let mut top = vec![[0f32; L]; wc];
        let mut bot = vec![[0f32; L]; wc];
        if i0 >= 1 {
            even_row(2 * i0 - 2, &mut top);
        } else {
            // Coarse row 0 is a border row: it restricts nothing.
            even_row(0, &mut top);
        }
        for (ii, out) in rows.chunks_mut(wc).enumerate() {
            let i = i0 + ii;
            out.fill([0.0; L]);
            if i == 0 {
                continue;
            }
            if i >= hc - 1 || 2 * i >= hf {
                continue;
            }
            even_row(2 * i, &mut bot);
            let o = (2 * i - 1) * wf;
            for j in 1..wc - 1 {
                if 2 * j >= wf {
                    break;
                }
                if coarse.inv[i * wc + j] == 0.0 {
                    continue;
                }
                let centre = res_at(d, x, b, o + 2 * j - 1, wf);
                let (a, bb, cc, dd) = (top[j - 1], top[j], bot[j - 1], bot[j]);
                // The order of `restrict` (its zero terms dropped): the same sums.
                let mut v = [0f32; L];
                for c in 0..L {
                    v[c] += 0.25 * a[c];
                    v[c] += 0.25 * bb[c];
                    v[c] += centre[c];
                    v[c] += 0.25 * cc[c];
                    v[c] += 0.25 * dd[c];
                }
                out[j] = v;
            }
            std::mem::swap(&mut top, &mut bot);
        }
    };
    if bc.len() >= PARALLEL_CELLS / 4 {
        bc.par_chunks_mut(BAND * wc).enumerate().for_each(band);
    } else {
        bc.chunks_mut(BAND * wc).enumerate().for_each(band);
    }
}

/// The residual `b − A x` of the 5-point level at unknown-or-not cell `p` (0 off the unknowns).
#[inline]
fn res_at<const L: usize>(
    d: &[f32],
    x: &[[f32; L]],
    b: &[[f32; L]],
    p: usize,
    w: usize,
) -> [f32; L] {
    let dp = d[p];
    if dp == 0.0 {
        return [0.0; L];
    }
    let (c0, l, rr, u, dn) = (x[p], x[p - 1], x[p + 1], x[p - w], x[p + w]);
    let mut v = b[p];
    for c in 0..L {
        v[c] -= dp * c0[c] - (l[c] + rr[c] + u[c] + dn[c]);
    }
    v
}

/// `r = b − A x` at every unknown (0 elsewhere), for any `x` that is 0 off the unknowns.
fn full_residual<const L: usize>(lev: &Level, x: &[[f32; L]], b: &[[f32; L]], r: &mut [[f32; L]]) {
    let (h, w) = (lev.h, lev.w);
    rows_mut(r, w, |y, out| {
        out.fill([0.0; L]);
        if y == 0 || y == h - 1 {
            return;
        }
        let o = y * w;
        for xi in 1..w - 1 {
            let p = o + xi;
            if lev.inv[p] == 0.0 {
                continue;
            }
            let mut v = b[p];
            match &lev.stencil {
                Stencil::Five(d) => {
                    let (c0, l, rr, u, dn) = (x[p], x[p - 1], x[p + 1], x[p - w], x[p + w]);
                    for c in 0..L {
                        v[c] -= d[p] * c0[c] - (l[c] + rr[c] + u[c] + dn[c]);
                    }
                }
                Stencil::Nine(a) => {
                    let s = &a[p];
                    for k in 0..9 {
                        let q = x[p + k / 3 * w + k % 3 - w - 1];
                        for c in 0..L {
                            v[c] -= s[k] * q[c];
                        }
                    }
                }
            }
            out[xi] = v;
        }
    });
}

/// `bc = Pᵀ rf`.
fn restrict<const L: usize>(fine: &Level, coarse: &Level, rf: &[[f32; L]], bc: &mut [[f32; L]]) {
    let (hc, wc, wf) = (coarse.h, coarse.w, fine.w);
    rows_mut(bc, wc, |i, out| {
        out.fill([0.0; L]);
        if i == 0 || i >= hc - 1 {
            return;
        }
        for (j, cell) in out.iter_mut().enumerate().take(wc - 1).skip(1) {
            if coarse.inv[i * wc + j] == 0.0 {
                continue;
            }
            let mut v = [0f32; L];
            for (fy, wy) in [(2 * i - 2, 0.5f32), (2 * i - 1, 1.0), (2 * i, 0.5)] {
                let o = fy * wf;
                for (fx, wx) in [(2 * j - 2, 0.5f32), (2 * j - 1, 1.0), (2 * j, 0.5)] {
                    let q = rf[o + fx];
                    let wt = wy * wx;
                    for c in 0..L {
                        v[c] += wt * q[c];
                    }
                }
            }
            *cell = v;
        }
    });
}

/// `xf += P xc` on the fine unknowns.
fn prolong_add<const L: usize>(fine: &Level, coarse: &Level, xc: &[[f32; L]], xf: &mut [[f32; L]]) {
    let (hf, wf, wc) = (fine.h, fine.w, coarse.w);
    rows_mut(xf, wf, |y, out| {
        if y == 0 || y == hf - 1 {
            return;
        }
        // The coarse row interpolated to fine row y (on the fly), then along it.
        let (r0, r1) = if y % 2 == 1 {
            let r = y.div_ceil(2) * wc;
            (r, r)
        } else {
            (y / 2 * wc, (y / 2 + 1) * wc)
        };
        let (c0, c1) = (&xc[r0..r0 + wc], &xc[r1..r1 + wc]);
        let t = |k: usize| -> [f32; L] {
            if y % 2 == 1 {
                c0[k]
            } else {
                let (a, b) = (c0[k], c1[k]);
                std::array::from_fn(|c| 0.5 * (a[c] + b[c]))
            }
        };
        let inv = &fine.inv[y * wf..(y + 1) * wf];
        // Fine column 2k − 1 takes coarse column k, fine column 2k the mean of k and k + 1.
        let mut tk = t(1);
        let mut k = 1;
        loop {
            let xi = 2 * k - 1;
            if xi >= wf - 1 {
                break;
            }
            if inv[xi] != 0.0 {
                for c in 0..L {
                    out[xi][c] += tk[c];
                }
            }
            if xi + 1 >= wf - 1 {
                break;
            }
            let tn = t(k + 1);
            if inv[xi + 1] != 0.0 {
                let v: [f32; L] = std::array::from_fn(|c| 0.5 * (tk[c] + tn[c]));
                for c in 0..L {
                    out[xi + 1][c] += v[c];
                }
            }
            tk = tn;
            k += 1;
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Coarse rows (or columns) a fine row interpolates from, with weights.
    fn parents(t: usize) -> impl Iterator<Item = (usize, f64)> {
        let (a, b, w) = if t % 2 == 1 {
            (t.div_ceil(2), usize::MAX, 1.0)
        } else {
            (t / 2, t / 2 + 1, 0.5)
        };
        [(a, w), (b, w)]
            .into_iter()
            .filter(|&(i, _)| i != usize::MAX)
    }

    /// A disk of unknowns with Dirichlet all round, on an odd grid.
    fn disk(n: usize) -> Level {
        let c = n as f32 / 2.0;
        let diag = (0..n * n)
            .map(|p| {
                let (y, x) = ((p / n) as f32, (p % n) as f32);
                if (y - c).powi(2) + (x - c).powi(2) < (0.4 * n as f32).powi(2) {
                    4.0
                } else {
                    0.0
                }
            })
            .collect();
        Level::five(n, n, diag)
    }

    fn dense(lev: &Level) -> Vec<Vec<f64>> {
        let m = lev.h * lev.w;
        let mut a = vec![vec![0f64; m]; m];
        for p in 0..m {
            for k in 0..9 {
                let c = lev.coef(p, k);
                if c != 0.0 {
                    a[p][p + k / 3 * lev.w + k % 3 - lev.w - 1] = f64::from(c);
                }
            }
        }
        a
    }

    #[test]
    fn galerkin_levels_are_symmetric_and_match_the_explicit_product() {
        let h = Hierarchy::new(disk(41));
        assert!(h.levels.len() >= 2);
        let (f, c) = (&h.levels[0], &h.levels[1]);
        let a = dense(f);
        let ac = dense(c);
        // Build P explicitly.
        let (mf, mc) = (f.h * f.w, c.h * c.w);
        let mut p = vec![vec![0f64; mc]; mf];
        for y in 1..f.h - 1 {
            for x in 1..f.w - 1 {
                if f.inv[y * f.w + x] == 0.0 {
                    continue;
                }
                for (i, wy) in parents(y) {
                    for (j, wx) in parents(x) {
                        p[y * f.w + x][i * c.w + j] = wy * wx;
                    }
                }
            }
        }
        for i in 0..mc {
            for j in 0..mc {
                let mut s = 0.0;
                for u in 0..mf {
                    if p[u][i] == 0.0 {
                        continue;
                    }
                    for v in 0..mf {
                        s += p[u][i] * a[u][v] * p[v][j];
                    }
                }
                assert!(
                    (s - ac[i][j]).abs() < 1e-5,
                    "({i},{j}): {s} vs {}",
                    ac[i][j]
                );
                assert_eq!(ac[i][j].to_bits(), ac[j][i].to_bits());
            }
        }
    }

    #[test]
    fn vcycle_is_a_symmetric_operator() {
        let h = Hierarchy::new(disk(61));
        let lev = &h.levels[0];
        let m = lev.h * lev.w;
        let mut ws = h.work::<1>();
        let vec_at = |seed: u64| {
            let mut s = seed;
            (0..m)
                .map(|p| {
                    s = s.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
                    [if lev.inv[p] > 0.0 {
                        (s >> 40) as f32 / (1u64 << 24) as f32 - 0.5
                    } else {
                        0.0
                    }]
                })
                .collect::<Vec<_>>()
        };
        let (u, v) = (vec_at(1), vec_at(2));
        let (mut mu, mut mv) = (vec![[0f32; 1]; m], vec![[0f32; 1]; m]);
        h.vcycle(&mut ws, &u, &mut mu);
        h.vcycle(&mut ws, &v, &mut mv);
        let dot = |a: &[[f32; 1]], b: &[[f32; 1]]| -> f64 {
            a.iter()
                .zip(b)
                .map(|(x, y)| f64::from(x[0]) * f64::from(y[0]))
                .sum()
        };
        let (a, b) = (dot(&v, &mu), dot(&u, &mv));
        assert!((a - b).abs() < 1e-4 * a.abs().max(b.abs()), "{a} vs {b}");
        assert!(dot(&u, &mu) > 0.0);
    }
}
