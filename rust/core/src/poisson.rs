//! Poisson image editing: seamless cloning with normal or mixed gradients (Pérez, Gangnet,
//! Blake, "Poisson image editing", SIGGRAPH 2003, Eqs. 7, 11–13), with the extra constraints
//! of the photometric correction in Sibbing, Pavić, Kobbelt, "Image synthesis for branching
//! structures", 2010, §5.3: chosen pixels keep their source colours (there, the border of a new
//! fragment where it has no neighbouring fragment).
//!
//! The region Ω is the mask placed at `offset` in the destination (pixels landing outside it
//! are clipped). For each pixel `p` in Ω and each 4-neighbour `q` inside the destination,
//! the discrete equation (Pérez Eq. 7) is
//! `|N_p| f_p − Σ_{q∈N_p∩Ω} f_q = Σ_{q∈N_p∩∂Ω} f*_q + Σ_{q∈N_p} v_pq`, with
//! - `v_pq = g_p − g_q` (normal cloning, `g` the source) or the one of `g_p − g_q` and
//!   `f*_p − f*_q` with the larger magnitude (mixed gradients, Eq. 13), per channel;
//! - `f*_q` the destination value where `q` is outside Ω (Dirichlet), the source value where
//!   `q` is a `fixed` pixel (Dirichlet, the §5.3 constraint);
//! - neighbours outside the destination dropped from `N_p` (Neumann: zero normal derivative);
//! - with guidance `labels`, `v_pq = 0` where `p` and `q` carry different labels (a custom
//!   guidance field: the source's own gradients inside each label, none across; pasting
//!   several fragments at once, their level differences are spread out instead of kept).
//!
//! Source values are read with the source's edge replicated, so a gradient across the
//! source's border is zero.
//!
//! A connected part of Ω with no Dirichlet neighbour (it fills a whole connected region of
//! the destination) determines `f` only up to a constant; it keeps the mean of the source
//! over it. Solving with one pixel pinned gives an exact solution of the singular system
//! (its right-hand side sums to zero), which is then shifted to that mean.
//!
//! The unknown is the correction `h = f − g`, which is smooth (harmonic in normal mode). Its
//! first guess comes from full multigrid; it is then refined by conjugate gradients
//! (`solver::pcg`) in `f64`, preconditioned by one V-cycle of the Galerkin multigrid
//! (`solver::multigrid`, `f32`), for up to four channels at once. The stopping test is
//! the relative residual `‖b − A f‖ / ‖b‖` of the system above in every channel. The result is
//! bit-identical for any number of threads.

// Lane loops index several arrays in lockstep; the index form is what vectorises.
#![allow(clippy::needless_range_loop)]

use rayon::prelude::*;

use crate::error::{invalid, Result};
use crate::image::Image;
use crate::solver::bands::{bands, rows_mut, sum_lanes, BAND};
use crate::solver::laplacian::Laplacian;
use crate::solver::multigrid::{Hierarchy, Level, VCycle};
use crate::solver::pcg::{pcg, Solution};

/// Which guidance field drives the blend.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Mode {
    /// Source gradients (Pérez Eq. 11).
    #[default]
    Normal,
    /// Per edge and channel the larger-magnitude gradient of source and destination (Eq. 13).
    Mixed,
}

/// Solver parameters of [`seamless`].
#[derive(Clone, Copy, Debug)]
pub struct BlendParams {
    /// Guidance field (default [`Mode::Normal`]).
    pub mode: Mode,
    /// Stop when the relative residual of every channel is at most this (default `1e-6`).
    pub tol: f64,
    /// Most conjugate-gradient iterations (default 200); the result is returned either way
    /// and [`Blended::residual`] says how far it got.
    pub max_iterations: usize,
}

impl Default for BlendParams {
    fn default() -> Self {
        Self {
            mode: Mode::Normal,
            tol: 1e-6,
            max_iterations: 200,
        }
    }
}

/// The images of a blend.
#[derive(Clone, Copy, Debug)]
pub struct BlendInput<'a> {
    /// Source `h × w × C`: its gradients are pasted.
    pub src: Image<'a>,
    /// Destination `H × W × C`.
    pub dst: Image<'a>,
    /// `h × w` region to paste, in source coordinates.
    pub mask: &'a [bool],
    /// (row, col) of the source's top-left pixel in the destination; may be negative.
    pub offset: (i64, i64),
    /// Optional `h × w` pixels of the mask that keep their source values.
    pub fixed: Option<&'a [bool]>,
    /// Optional `h × w` guidance labels in source coordinates (read with the source's edge
    /// replicated): the source gradient between two 4-neighbours counts only where their
    /// labels are equal, and is zero across labels.
    pub labels: Option<&'a [i32]>,
}

/// Output of [`seamless`].
#[derive(Clone, Debug)]
pub struct Blended {
    /// `H × W × C` result: the destination with the region replaced.
    pub image: Vec<f32>,
    /// Conjugate-gradient iterations (the largest over channel groups).
    pub iterations: usize,
    /// Largest relative residual `‖b − A f‖ / ‖b‖` over channels, of the `f64` solution.
    pub residual: f64,
    /// Number of unknowns (region pixels that are neither fixed nor pinned).
    pub unknowns: usize,
}

// Cell kinds on the working grid.
const OUT: u8 = 0; // outside the destination: Neumann
const DST: u8 = 1; // destination pixel outside the region: Dirichlet, destination value
const FIX: u8 = 2; // fixed (or pinned) region pixel: Dirichlet, source value
const UNK: u8 = 3; // unknown

/// The region on a framed, odd-sized grid over its bounding box in the destination.
struct Grid {
    h: usize,
    w: usize,
    /// Destination (row, col) of grid cell (0, 0).
    y0: i64,
    x0: i64,
    kind: Vec<u8>,
    /// For pinned components: per cell the component index (`u32::MAX` elsewhere).
    comp: Vec<u32>,
    /// Number of pinned components.
    ncomp: usize,
}

impl Grid {
    fn new(input: &BlendInput<'_>) -> Result<Self> {
        let (sh, sw) = (input.src.h, input.src.w);
        let (dh, dw) = (input.dst.h as i64, input.dst.w as i64);
        let (oy, ox) = input.offset;
        if !input.mask.iter().any(|&m| m) {
            return Err(invalid("mask", "expected at least one pixel set, got none"));
        }
        // Source rows and columns that land inside the destination.
        let rows = (-oy).clamp(0, sh as i64) as usize..(dh - oy).clamp(0, sh as i64) as usize;
        let cols = (-ox).clamp(0, sw as i64) as usize..(dw - ox).clamp(0, sw as i64) as usize;
        let (mut y0, mut y1, mut x0, mut x1) = (i64::MAX, i64::MIN, i64::MAX, i64::MIN);
        if !cols.is_empty() {
            for sy in rows.clone() {
                let row = &input.mask[sy * sw + cols.start..sy * sw + cols.end];
                if let Some(first) = row.iter().position(|&m| m) {
                    let last = row.iter().rposition(|&m| m).unwrap_or(first);
                    let y = sy as i64 + oy;
                    y0 = y0.min(y);
                    y1 = y1.max(y);
                    x0 = x0.min((cols.start + first) as i64 + ox);
                    x1 = x1.max((cols.start + last) as i64 + ox);
                }
            }
        }
        if y0 == i64::MAX {
            return Err(invalid(
                "mask",
                format!(
                    "no pixel of the mask lands inside the {dh}×{dw} destination at offset ({oy}, {ox})"
                ),
            ));
        }
        let h = ((y1 - y0 + 3) as usize) | 1;
        let w = ((x1 - x0 + 3) as usize) | 1;
        let (gy0, gx0) = (y0 - 1, x0 - 1);
        // Grid columns inside the destination.
        let gcols = (-gx0).clamp(0, w as i64) as usize..(dw - gx0).clamp(0, w as i64) as usize;
        let mut kind = vec![OUT; h * w];
        for (gy, row) in kind.chunks_mut(w).enumerate() {
            let y = gy as i64 + gy0;
            if !(0..dh).contains(&y) {
                continue;
            }
            row[gcols.clone()].fill(DST);
            if !(0..sh as i64).contains(&(y - oy)) {
                continue;
            }
            let sy = (y - oy) as usize;
            for sx in cols.clone() {
                if input.mask[sy * sw + sx] {
                    let gx = (sx as i64 + ox - gx0) as usize;
                    let fixed = input.fixed.is_some_and(|f| f[sy * sw + sx]);
                    row[gx] = if fixed { FIX } else { UNK };
                }
            }
        }
        let mut grid = Self {
            h,
            w,
            y0: gy0,
            x0: gx0,
            kind,
            comp: Vec::new(),
            ncomp: 0,
        };
        grid.pin_floating_components();
        Ok(grid)
    }

    /// Pins the first pixel (in raster order) of every connected set of unknowns that has no
    /// Dirichlet neighbour, remembering the set so its mean can be restored.
    ///
    /// Works on runs of unknowns along rows: runs in adjacent rows that overlap are joined
    /// (union–find), and a run is grounded when a cell at its ends or above or below it is
    /// Dirichlet. Cost is in runs, plus a byte scan of the rows around them.
    fn pin_floating_components(&mut self) {
        let (h, w) = (self.h, self.w);
        let kind = &self.kind;
        let dirichlet = |k: u8| k == DST || k == FIX;
        // Runs (row, first, end) in raster order; row_runs[y]..row_runs[y + 1] index row y's.
        let mut runs: Vec<(usize, usize, usize)> = Vec::new();
        let mut row_runs = vec![0usize; h + 1];
        for y in 1..h - 1 {
            let row = &kind[y * w..(y + 1) * w];
            let mut x = 1;
            while x < w - 1 {
                if row[x] == UNK {
                    let s = x;
                    while row[x] == UNK {
                        x += 1;
                    }
                    runs.push((y, s, x));
                } else {
                    x += 1;
                }
            }
            row_runs[y + 1] = runs.len();
        }
        row_runs[h] = runs.len();
        let mut grounded: Vec<bool> = runs
            .iter()
            .map(|&(y, s, e)| {
                let o = y * w;
                dirichlet(kind[o + s - 1])
                    || dirichlet(kind[o + e])
                    || kind[o - w + s..o - w + e].iter().any(|&k| dirichlet(k))
                    || kind[o + w + s..o + w + e].iter().any(|&k| dirichlet(k))
            })
            .collect();
        let mut parent: Vec<usize> = (0..runs.len()).collect();
        for y in 2..h - 1 {
            let (mut a, a_end) = (row_runs[y - 1], row_runs[y]);
            let (mut b, b_end) = (row_runs[y], row_runs[y + 1]);
            while a < a_end && b < b_end {
                let (_, sa, ea) = runs[a];
                let (_, sb, eb) = runs[b];
                if sa < eb && sb < ea {
                    let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
                    if ra != rb {
                        // The earlier run stays the root.
                        let (lo, hi) = (ra.min(rb), ra.max(rb));
                        parent[hi] = lo;
                        grounded[lo] |= grounded[hi];
                    }
                }
                if ea <= eb {
                    a += 1;
                } else {
                    b += 1;
                }
            }
        }
        let mut index = vec![u32::MAX; runs.len()];
        for i in 0..runs.len() {
            let root = find(&mut parent, i);
            if grounded[root] {
                continue;
            }
            let (y, s, e) = runs[i];
            if index[root] == u32::MAX {
                // The component's first run in raster order: pin its first cell.
                index[root] = self.ncomp as u32;
                self.ncomp += 1;
                self.kind[y * w + s] = FIX;
            }
            if self.comp.is_empty() {
                self.comp = vec![u32::MAX; h * w];
            }
            self.comp[y * w + s..y * w + e].fill(index[root]);
        }
    }

    fn diag(&self) -> Vec<f32> {
        let (h, w) = (self.h, self.w);
        let kind = &self.kind;
        let mut d = vec![0f32; h * w];
        rows_mut(&mut d, w, |y, row| {
            if y == 0 || y == h - 1 {
                return;
            }
            let o = y * w;
            let (up, cur, dn) = (&kind[o - w..o], &kind[o..o + w], &kind[o + w..o + 2 * w]);
            for x in 1..w - 1 {
                if cur[x] == UNK {
                    row[x] = f32::from(
                        u8::from(up[x] != OUT)
                            + u8::from(dn[x] != OUT)
                            + u8::from(cur[x - 1] != OUT)
                            + u8::from(cur[x + 1] != OUT),
                    );
                }
            }
        });
        d
    }
}

/// The root of `i` in a union–find forest, halving the path on the way.
fn find(parent: &mut [usize], mut i: usize) -> usize {
    while parent[i] != i {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    i
}

/// Source and destination values on the grid for channels `c0..c0 + L`.
struct Values<const L: usize> {
    /// Source, its edge replicated beyond its border.
    g: Vec<[f32; L]>,
    /// Destination (0 outside it). Normal cloning reads it only at Dirichlet destination
    /// cells, so only those are filled then.
    d: Vec<[f32; L]>,
    /// Guidance labels on the grid (empty without labels).
    lab: Vec<i32>,
}

impl<const L: usize> Values<L> {
    fn new(input: &BlendInput<'_>, grid: &Grid, c0: usize, mode: Mode) -> Self {
        let (h, w) = (grid.h, grid.w);
        let (s, dst) = (&input.src, &input.dst);
        let (oy, ox) = input.offset;
        let nc = L.min(s.c - c0);
        let mut g = vec![[0f32; L]; h * w];
        let mut d = vec![[0f32; L]; h * w];
        rows_mut(&mut g, w, |gy, row| {
            let sy = (gy as i64 + grid.y0 - oy).clamp(0, s.h as i64 - 1) as usize;
            for (gx, v) in row.iter_mut().enumerate() {
                let sx = (gx as i64 + grid.x0 - ox).clamp(0, s.w as i64 - 1) as usize;
                let px = &s.pixel(sy, sx)[c0..];
                // A lane loop, not a slice copy: a copy of runtime length is a memmove call.
                for c in 0..L {
                    if c < nc {
                        v[c] = px[c];
                    }
                }
            }
        });
        rows_mut(&mut d, w, |gy, row| {
            let y = gy as i64 + grid.y0;
            if !(0..dst.h as i64).contains(&y) {
                return;
            }
            let kind = &grid.kind[gy * w..(gy + 1) * w];
            for (gx, v) in row.iter_mut().enumerate() {
                if mode == Mode::Normal && kind[gx] != DST {
                    continue;
                }
                let x = gx as i64 + grid.x0;
                if (0..dst.w as i64).contains(&x) {
                    v[..nc].copy_from_slice(&dst.pixel(y as usize, x as usize)[c0..c0 + nc]);
                }
            }
        });
        let lab = input.labels.map_or_else(Vec::new, |l| {
            let mut lab = vec![0i32; h * w];
            rows_mut(&mut lab, w, |gy, row| {
                let sy = (gy as i64 + grid.y0 - oy).clamp(0, s.h as i64 - 1) as usize;
                for (gx, v) in row.iter_mut().enumerate() {
                    let sx = (gx as i64 + grid.x0 - ox).clamp(0, s.w as i64 - 1) as usize;
                    *v = l[sy * s.w + sx];
                }
            });
            lab
        });
        Self { g, d, lab }
    }

    /// Whether the guidance between grid cells `p` and `q` is cut (different labels).
    #[inline]
    fn cut(&self, p: usize, q: usize) -> bool {
        !self.lab.is_empty() && self.lab[p] != self.lab[q]
    }

    /// Right-hand side of the row of unknown `p` for the cell kinds `kind`, as `(b_f, b_h)`:
    /// the system for `f` and for the correction `h = f − g`.
    #[inline]
    fn rhs(&self, kind: &[u8], w: usize, mode: Mode, p: usize) -> ([f64; L], [f64; L]) {
        let (mut bf, mut bh) = ([0f64; L], [0f64; L]);
        let (gp, fp) = (self.g[p], self.d[p]);
        for q in [p - w, p - 1, p + 1, p + w] {
            let kq = kind[q];
            if kq == OUT {
                continue;
            }
            let (gq, fq) = (self.g[q], self.d[q]);
            let cut = self.cut(p, q);
            for c in 0..L {
                // `g_p − g_q` is what the unknown `h = f − g` carries; the guidance may differ.
                let gd = f64::from(gp[c]) - f64::from(gq[c]);
                let gs = if cut { 0.0 } else { gd };
                let v = match mode {
                    Mode::Normal => gs,
                    Mode::Mixed => {
                        let ds = f64::from(fp[c]) - f64::from(fq[c]);
                        if ds.abs() > gs.abs() {
                            ds
                        } else {
                            gs
                        }
                    }
                };
                bf[c] += v;
                bh[c] += v - gd;
                if kq != UNK {
                    let val = if kq == FIX { gq[c] } else { fq[c] };
                    bf[c] += f64::from(val);
                    bh[c] += f64::from(val) - f64::from(gq[c]);
                }
            }
        }
        (bf, bh)
    }
}

/// Blends `src` into `dst` over `mask` (see the module documentation).
pub fn seamless(input: &BlendInput<'_>, params: &BlendParams) -> Result<Blended> {
    let (src, dst) = (&input.src, &input.dst);
    if src.c != dst.c {
        return Err(invalid(
            "dst",
            format!("expected {} channels like src, got {}", src.c, dst.c),
        ));
    }
    like_src("mask", input.mask.len(), src)?;
    if let Some(f) = input.fixed {
        like_src("fixed", f.len(), src)?;
        if let Some(i) = (0..f.len()).find(|&i| f[i] && !input.mask[i]) {
            return Err(invalid(
                "fixed",
                format!(
                    "pixel (row {}, col {}) is fixed but not in the mask",
                    i / src.w,
                    i % src.w
                ),
            ));
        }
    }
    if let Some(l) = input.labels {
        like_src("labels", l.len(), src)?;
    }
    if !(params.tol.is_finite() && params.tol > 0.0) {
        return Err(invalid(
            "tol",
            format!("expected a positive tolerance, got {}", params.tol),
        ));
    }
    src.check_finite("src")?;
    let setup = || -> Result<_> {
        let grid = Grid::new(input)?;
        let diag = grid.diag();
        let mg = Hierarchy::new(Level::five(grid.h, grid.w, diag.clone()));
        Ok((grid, diag, mg))
    };
    // The copy of the destination into the output is memory-bound and the setup mostly
    // sequential: run them side by side. Errors keep their order.
    let (setup, out) = rayon::join(setup, || copy_finite(dst, "dst"));
    let (grid, diag, mg) = setup?;
    let mut out = out?;
    crate::cancel::check()?;
    let (mut iterations, mut residual) = (0, 0.0f64);
    let c = src.c;
    match c {
        1 => {
            let (i, r) = solve_group::<1>(input, params, &grid, &diag, &mg, 0, &mut out)?;
            (iterations, residual) = (i, r);
        }
        2 => {
            let (i, r) = solve_group::<2>(input, params, &grid, &diag, &mg, 0, &mut out)?;
            (iterations, residual) = (i, r);
        }
        // RGB as three lanes, not four with one idle: a quarter less memory traffic.
        3 => {
            let (i, r) = solve_group::<3>(input, params, &grid, &diag, &mg, 0, &mut out)?;
            (iterations, residual) = (i, r);
        }
        _ => {
            for c0 in (0..c).step_by(4) {
                let (i, r) = solve_group::<4>(input, params, &grid, &diag, &mg, c0, &mut out)?;
                iterations = iterations.max(i);
                residual = residual.max(r);
            }
        }
    }
    Ok(Blended {
        image: out,
        iterations,
        residual,
        unknowns: mg.levels[0].n,
    })
}

/// Fails (naming `name`) unless `len` is one value per pixel of `src`.
fn like_src(name: &'static str, len: usize, src: &Image<'_>) -> Result<()> {
    if len == src.h * src.w {
        return Ok(());
    }
    Err(invalid(
        name,
        format!("expected {}×{} values like src, got {len}", src.h, src.w),
    ))
}

/// A copy of `img`'s values, failing (naming `name`) at the first non-finite one.
///
/// One pass in parallel chunks: each chunk is copied straight into the new vector's
/// uninitialised capacity (no zeroing pass first) and checked while it is in cache.
fn copy_finite(img: &Image<'_>, name: &'static str) -> Result<Vec<f32>> {
    const CHUNK: usize = 1 << 15;
    let n = img.data.len();
    let mut out: Vec<f32> = Vec::with_capacity(n);
    let bad: Option<usize> = out.spare_capacity_mut()[..n]
        .par_chunks_mut(CHUNK)
        .zip(img.data.par_chunks(CHUNK))
        .enumerate()
        .filter_map(|(i, (o, d))| {
            let mut any = false;
            for (o, &v) in o.iter_mut().zip(d) {
                o.write(v);
                any |= !v.is_finite();
            }
            any.then(|| i * CHUNK + d.iter().position(|v| !v.is_finite()).unwrap_or(0))
        })
        .min();
    // SAFETY: the chunks above cover 0..n and every element was written.
    unsafe { out.set_len(n) };
    if let Some(i) = bad {
        let p = i / img.c;
        return Err(invalid(
            name,
            format!(
                "expected finite values, found {} at pixel (row {}, col {})",
                img.data[i],
                p / img.w,
                p % img.w
            ),
        ));
    }
    Ok(out)
}

/// Solves channels `c0..c0 + L` and writes them into `out`; returns (iterations, residual),
/// or `Err(Error::Cancelled)` from the solver.
fn solve_group<const L: usize>(
    input: &BlendInput<'_>,
    params: &BlendParams,
    grid: &Grid,
    diag: &[f32],
    mg: &Hierarchy,
    c0: usize,
    out: &mut [f32],
) -> Result<(usize, f64)> {
    let vals = Values::<L>::new(input, grid, c0, params.mode);
    let (h, w) = (grid.h, grid.w);
    let mut b = vec![[0f64; L]; h * w];
    let parts = bands(&mut b, w, |bi, band| {
        let mut s = [0f64; L];
        let kind = &grid.kind;
        for (k, cell) in band.iter_mut().enumerate() {
            let p = bi * BAND * w + k;
            if kind[p] != UNK {
                continue;
            }
            if params.mode == Mode::Normal
                && kind[p - w] == UNK
                && kind[p - 1] == UNK
                && kind[p + 1] == UNK
                && kind[p + w] == UNK
                && !(vals.cut(p, p - w) || vals.cut(p, p - 1) || vals.cut(p, p + 1))
                && !vals.cut(p, p + w)
            {
                // All neighbours unknown: b_h is 0 and b_f the Laplacian of g (the sums of
                // `Values::rhs`, in its order).
                let g = &vals.g;
                let (gp, gu, gl, gr, gd) = (g[p], g[p - w], g[p - 1], g[p + 1], g[p + w]);
                for c in 0..L {
                    let gpc = f64::from(gp[c]);
                    let f = (((gpc - f64::from(gu[c])) + (gpc - f64::from(gl[c])))
                        + (gpc - f64::from(gr[c])))
                        + (gpc - f64::from(gd[c]));
                    s[c] += f * f;
                }
                continue;
            }
            {
                let (f, hh) = vals.rhs(kind, w, params.mode, p);
                for c in 0..L {
                    s[c] += f[c] * f[c];
                }
                *cell = hh;
            }
        }
        s
    });
    let scale = sum_lanes(&parts).map(|s| if s > 0.0 { s.sqrt() } else { 1.0 });
    crate::cancel::check()?;
    let Solution {
        mut x,
        iterations: it,
        mut residual,
    } = pcg(
        &mut Laplacian { diag, w },
        &mut VCycle::new(mg),
        &b,
        w,
        scale,
        params.tol,
        params.max_iterations,
    )?;
    // Pinned components keep the source's mean: shift their correction to mean zero.
    if grid.ncomp > 0 {
        let mut sum = vec![([0f64; L], 0usize); grid.ncomp];
        for p in 0..h * w {
            let k = grid.comp[p];
            if k != u32::MAX {
                for c in 0..L {
                    sum[k as usize].0[c] += x[p][c];
                }
                sum[k as usize].1 += 1;
            }
        }
        for p in 0..h * w {
            let k = grid.comp[p];
            if k != u32::MAX {
                let (m, n) = sum[k as usize];
                for c in 0..L {
                    x[p][c] -= m[c] / n as f64;
                }
            }
        }
    }
    if grid.ncomp > 0 {
        // The solve had one pixel per pinned component as Dirichlet; measure the user's system.
        // (Otherwise the residual of h is that of f = g + h, already measured.)
        residual = final_residual(&vals, grid, params.mode, &x);
    }
    // f = g + h on the region, destination rows in parallel. Grid rows 1..h − 1 that hold
    // region cells lie inside the destination.
    let (dw, nc) = (input.dst.w, input.dst.c);
    let lanes = L.min(nc - c0);
    let write_row = |gy: usize, row: &mut [f32]| {
        for gx in 1..w - 1 {
            let p = gy * w + gx;
            if grid.kind[p] < FIX {
                continue;
            }
            let o = (gx as i64 + grid.x0) as usize * nc + c0;
            for c in 0..lanes {
                row[o + c] = (f64::from(vals.g[p][c]) + x[p][c]) as f32;
            }
        }
    };
    let first = (grid.y0 + 1).max(0) as usize;
    let last = ((grid.y0 + h as i64 - 1) as usize).min(input.dst.h);
    let rows = out
        .chunks_mut(dw * nc)
        .enumerate()
        .take(last)
        .skip(first)
        .map(|(y, row)| ((y as i64 - grid.y0) as usize, row));
    if h * w >= 16 * 1024 {
        rows.collect::<Vec<_>>()
            .into_par_iter()
            .for_each(|(gy, row)| write_row(gy, row));
    } else {
        rows.for_each(|(gy, row)| write_row(gy, row));
    }
    Ok((it, residual))
}

/// Largest relative residual over lanes of `f = g + h` in the system of the user's problem
/// (pinned pixels counted as unknowns again).
fn final_residual<const L: usize>(
    vals: &Values<L>,
    grid: &Grid,
    mode: Mode,
    h: &[[f64; L]],
) -> f64 {
    let w = grid.w;
    let kind: Vec<u8> = if grid.ncomp > 0 {
        (0..grid.kind.len())
            .map(|p| {
                if grid.comp[p] == u32::MAX {
                    grid.kind[p]
                } else {
                    UNK
                }
            })
            .collect()
    } else {
        grid.kind.clone()
    };
    let f = |p: usize| -> [f64; L] {
        match kind[p] {
            UNK | FIX => std::array::from_fn(|c| f64::from(vals.g[p][c]) + h[p][c]),
            _ => vals.d[p].map(f64::from),
        }
    };
    let row = |gy: usize| {
        let (mut rr, mut bb) = ([0f64; L], [0f64; L]);
        for gx in 0..w {
            let p = gy * w + gx;
            if kind[p] != UNK {
                continue;
            }
            let (bf, _) = vals.rhs(&kind, w, mode, p);
            let fp = f(p);
            let mut af = [0f64; L];
            for q in [p - w, p - 1, p + 1, p + w] {
                match kind[q] {
                    OUT => {}
                    UNK => {
                        let fq = f(q);
                        for c in 0..L {
                            af[c] += fp[c] - fq[c];
                        }
                    }
                    _ => {
                        for c in 0..L {
                            af[c] += fp[c];
                        }
                    }
                }
            }
            for c in 0..L {
                rr[c] += (bf[c] - af[c]).powi(2);
                bb[c] += bf[c] * bf[c];
            }
        }
        (rr, bb)
    };
    let sums: Vec<([f64; L], [f64; L])> = if grid.h * w >= 16 * 1024 {
        (0..grid.h).into_par_iter().map(row).collect()
    } else {
        (0..grid.h).map(row).collect()
    };
    let (mut rr, mut bb) = ([0f64; L], [0f64; L]);
    for (r, b) in &sums {
        for c in 0..L {
            rr[c] += r[c];
            bb[c] += b[c];
        }
    }
    (0..L)
        .map(|c| {
            if bb[c] > 0.0 {
                (rr[c] / bb[c]).sqrt()
            } else {
                rr[c].sqrt()
            }
        })
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(h: usize, w: usize, c: usize, f: impl Fn(usize, usize, usize) -> f32) -> Vec<f32> {
        (0..h * w * c)
            .map(|i| f(i / c / w, i / c % w, i % c))
            .collect()
    }

    fn disk(n: usize, r: f32) -> Vec<bool> {
        let m = (n as f32 - 1.0) / 2.0;
        (0..n * n)
            .map(|i| ((i / n) as f32 - m).powi(2) + ((i % n) as f32 - m).powi(2) < r * r)
            .collect()
    }

    fn blend(
        src: &[f32],
        sh: usize,
        dst: &[f32],
        dh: usize,
        c: usize,
        mask: &[bool],
        off: (i64, i64),
        mode: Mode,
    ) -> Blended {
        let input = BlendInput {
            src: Image::new("src", src, sh, sh, c).unwrap(),
            dst: Image::new("dst", dst, dh, dh, c).unwrap(),
            mask,
            offset: off,
            fixed: None,
            labels: None,
        };
        seamless(
            &input,
            &BlendParams {
                mode,
                ..BlendParams::default()
            },
        )
        .unwrap()
    }

    #[test]
    fn residual_is_below_tolerance_on_a_textured_disk() {
        let (sh, dh) = (70, 100);
        let src = img(sh, sh, 3, |y, x, c| {
            ((y * 7 + x * 13 + c * 5) % 17) as f32 / 17.0
        });
        let dst = img(dh, dh, 3, |y, x, c| {
            (y as f32 * 0.01 + x as f32 * 0.02 + c as f32 * 0.1).sin()
        });
        for mode in [Mode::Normal, Mode::Mixed] {
            let b = blend(&src, sh, &dst, dh, 3, &disk(sh, 30.0), (10, 20), mode);
            assert!(b.residual < 1e-6, "{mode:?}: residual {}", b.residual);
            assert!(b.iterations <= 15, "{mode:?}: {} iterations", b.iterations);
        }
    }

    #[test]
    fn self_blend_is_the_identity() {
        let dh = 50;
        let dst = img(dh, dh, 2, |y, x, c| {
            ((y * 3 + x * 5 + c) % 11) as f32 / 11.0
        });
        let src: Vec<f32> = (0..30 * 30 * 2)
            .map(|i| {
                let (y, x, c) = (i / 2 / 30, i / 2 % 30, i % 2);
                dst[((y + 5) * dh + x + 12) * 2 + c]
            })
            .collect();
        let b = blend(
            &src,
            30,
            &dst,
            dh,
            2,
            &disk(30, 14.0),
            (5, 12),
            Mode::Normal,
        );
        assert_eq!(b.image, dst);
        assert_eq!(b.iterations, 0);
    }

    #[test]
    fn whole_destination_keeps_the_source_mean() {
        // The mask covers all of dst: no Dirichlet pixel, the solution is src shifted to its mean.
        let n = 20;
        let src = img(n, n, 1, |y, x, _| (y * x) as f32 / 400.0);
        let dst = img(n, n, 1, |_, _, _| 0.5);
        let b = blend(
            &src,
            n,
            &dst,
            n,
            1,
            &vec![true; n * n],
            (0, 0),
            Mode::Normal,
        );
        for (o, s) in b.image.iter().zip(&src) {
            assert!((o - s).abs() < 1e-5, "{o} vs {s}");
        }
        assert!(b.residual < 1e-6);
    }

    /// The user's system solved by Gauss–Seidel, straight from its definition: for every mask
    /// pixel `p`, `Σ_q (f_p − f_q) = Σ_q v_pq` over the 4-neighbours `q` inside `dst`, with
    /// `v_pq = g_p − g_q` between equal labels and 0 across, `f_q = dst` outside the mask.
    fn brute_force(g: &[f32], d: &[f32], n: usize, mask: &[bool], lab: &[i32]) -> Vec<f64> {
        let mut f: Vec<f64> = d.iter().map(|&v| f64::from(v)).collect();
        for _ in 0..20_000 {
            for p in 0..n * n {
                if !mask[p] {
                    continue;
                }
                let (y, x) = (p / n, p % n);
                let (mut deg, mut sum) = (0.0, 0.0);
                for (qy, qx) in [
                    (y.wrapping_sub(1), x),
                    (y + 1, x),
                    (y, x.wrapping_sub(1)),
                    (y, x + 1),
                ] {
                    if qy >= n || qx >= n {
                        continue;
                    }
                    let q = qy * n + qx;
                    deg += 1.0;
                    let v = if lab[p] == lab[q] {
                        f64::from(g[p]) - f64::from(g[q])
                    } else {
                        0.0
                    };
                    sum += f[q] + v;
                }
                f[p] = sum / deg;
            }
        }
        f
    }

    #[test]
    fn labels_cut_the_guidance_as_the_brute_force_solve_does() {
        let n = 16;
        let src = img(n, n, 1, |y, x, _| ((y * 7 + x * 13) % 17) as f32 / 17.0);
        let dst = img(n, n, 1, |y, x, _| 0.2 + 0.01 * (y + 2 * x) as f32);
        // Three labels in blocks, one of them also outside the mask; the mask touches the
        // border on the left (Neumann there).
        let lab: Vec<i32> = (0..n * n)
            .map(|i| i32::from(i / n >= 8) + i32::from(i % n >= 10))
            .collect();
        let mask: Vec<bool> = (0..n * n)
            .map(|i| (1..n - 2).contains(&(i / n)) && i % n < n - 3)
            .collect();
        let input = BlendInput {
            src: Image::new("src", &src, n, n, 1).unwrap(),
            dst: Image::new("dst", &dst, n, n, 1).unwrap(),
            mask: &mask,
            offset: (0, 0),
            fixed: None,
            labels: Some(&lab),
        };
        let params = BlendParams {
            tol: 1e-10,
            ..BlendParams::default()
        };
        let b = seamless(&input, &params).unwrap();
        let want = brute_force(&src, &dst, n, &mask, &lab);
        for (p, (o, e)) in b.image.iter().zip(&want).enumerate() {
            assert!((f64::from(*o) - e).abs() < 1e-5, "pixel {p}: {o} vs {e}");
        }
        // Without labels the same solve keeps every source gradient: a different image.
        let plain = seamless(
            &BlendInput {
                labels: None,
                ..input
            },
            &params,
        )
        .unwrap();
        assert!(plain
            .image
            .iter()
            .zip(&b.image)
            .any(|(a, c)| (a - c).abs() > 0.01));
    }

    #[test]
    fn a_step_between_labels_is_removed() {
        // Two flat halves with a step between them, pasted into a flat destination: with the
        // halves labelled apart the guidance is zero everywhere and the paste is flat.
        let n = 12;
        let src = img(
            n,
            n,
            2,
            |_, x, c| if x < 6 { 0.1 } else { 0.9 + 0.01 * c as f32 },
        );
        let dst = vec![0.4f32; n * n * 2];
        let lab: Vec<i32> = (0..n * n).map(|i| i32::from(i % n >= 6)).collect();
        let mask: Vec<bool> = (0..n * n)
            .map(|i| (2..n - 2).contains(&(i / n)) && (2..n - 2).contains(&(i % n)))
            .collect();
        let b = seamless(
            &BlendInput {
                src: Image::new("src", &src, n, n, 2).unwrap(),
                dst: Image::new("dst", &dst, n, n, 2).unwrap(),
                mask: &mask,
                offset: (0, 0),
                fixed: None,
                labels: Some(&lab),
            },
            &BlendParams::default(),
        )
        .unwrap();
        for v in &b.image {
            assert!((v - 0.4).abs() < 1e-5, "{v}");
        }
    }

    #[test]
    fn errors_name_the_argument() {
        let src = vec![0.0f32; 16];
        let dst = vec![0.0f32; 64];
        let mask = vec![true; 16];
        let input = BlendInput {
            src: Image::new("src", &src, 4, 4, 1).unwrap(),
            dst: Image::new("dst", &dst, 8, 8, 1).unwrap(),
            mask: &mask,
            offset: (100, 0),
            fixed: None,
            labels: None,
        };
        let e = seamless(&input, &BlendParams::default()).unwrap_err();
        assert!(e.to_string().starts_with("mask:"), "{e}");
        let none = vec![false; 16];
        let e = seamless(
            &BlendInput {
                mask: &none,
                offset: (0, 0),
                ..input
            },
            &BlendParams::default(),
        )
        .unwrap_err();
        assert!(e.to_string().starts_with("mask:"), "{e}");
        let mut fixed = vec![false; 16];
        fixed[3] = true;
        let part: Vec<bool> = (0..16).map(|i| i != 3).collect();
        let e = seamless(
            &BlendInput {
                mask: &part,
                fixed: Some(&fixed),
                offset: (0, 0),
                ..input
            },
            &BlendParams::default(),
        )
        .unwrap_err();
        assert!(e.to_string().starts_with("fixed:"), "{e}");
        let short = vec![0i32; 15];
        let e = seamless(
            &BlendInput {
                labels: Some(&short),
                offset: (0, 0),
                ..input
            },
            &BlendParams::default(),
        )
        .unwrap_err();
        assert!(e.to_string().starts_with("labels:"), "{e}");
    }
}
