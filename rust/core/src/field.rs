//! Smooth fields that interpolate given vectors: the displacement field of Sibbing, Pavić,
//! Kobbelt, "Image synthesis for branching structures", 2010, §5.3, which minimises
//! `E = Σ ‖4 d_uv − d_(u−1)v − d_(u+1)v − d_u(v−1) − d_u(v+1)‖²` over a region subject to
//! `d = d_l` at given pixels.
//!
//! At the region's border the literal 4-neighbour stencil reads pixels outside the region, so
//! `E` uses the graph Laplacian of the region instead: `(L d)_p = deg(p)·d_p − Σ d_q` over the
//! neighbours `q` of `p` inside the region (interior pixels see exactly the paper's stencil).
//! Its null space is the fields that are constant on each connected part, so `E` has a unique
//! minimiser once every part holds at least one constraint. Constants are reproduced exactly;
//! affine fields are not (border rows of `L` do not vanish on them), which is the price of a
//! well-posed energy without values outside the region.
//!
//! The constrained pixels are eliminated, so they are hit exactly. The normal equations
//! `(LᵀL)_FF d_F = −(LᵀL)_FC d_C` (13-point, symmetric positive definite) are solved per
//! component of `d` by conjugate gradients preconditioned with a Galerkin multigrid V-cycle
//! (bilinear interpolation between grids of halved resolution, symmetric Gauss–Seidel
//! smoothing, a dense Cholesky factor on the coarsest grid), all in `f64`.

// Lane loops index several arrays in lockstep; the index form is what vectorises.
#![allow(clippy::needless_range_loop)]

use rayon::prelude::*;

use crate::error::{invalid, Result};

/// Solver parameters of [`interpolate_field`].
#[derive(Clone, Copy, Debug)]
pub struct FieldParams {
    /// Stop when `‖b − A d‖ ≤ tol · ‖b‖` in every component (default `1e-10`: the system's
    /// condition number grows like the fourth power of the region's diameter).
    pub tol: f64,
    /// Most conjugate-gradient iterations per component (default 2000).
    pub max_iterations: usize,
}

impl Default for FieldParams {
    fn default() -> Self {
        Self {
            tol: 1e-10,
            max_iterations: 2000,
        }
    }
}

/// Output of [`interpolate_field`].
#[derive(Clone, Debug)]
pub struct Field {
    /// `h × w × d` field, NaN outside the region.
    pub values: Vec<f32>,
    /// Conjugate-gradient iterations (largest over components).
    pub iterations: usize,
    /// Largest relative residual of the normal equations over components.
    pub residual: f64,
}

/// A sparse row: (column, value) pairs, columns increasing.
type Row = Vec<(u32, f64)>;

/// A square sparse matrix in compressed rows, columns sorted.
#[derive(Clone, Debug, Default)]
struct Csr {
    ptr: Vec<usize>,
    col: Vec<u32>,
    val: Vec<f64>,
    /// Position of each row's diagonal entry in `col`/`val`.
    diag: Vec<usize>,
}

impl Csr {
    fn n(&self) -> usize {
        self.ptr.len() - 1
    }

    fn from_rows(rows: Vec<Vec<(u32, f64)>>) -> Self {
        let mut m = Self {
            ptr: vec![0],
            ..Self::default()
        };
        for (i, row) in rows.into_iter().enumerate() {
            let mut d = usize::MAX;
            for (j, v) in row {
                if j as usize == i {
                    d = m.col.len();
                }
                m.col.push(j);
                m.val.push(v);
            }
            m.diag.push(d);
            m.ptr.push(m.col.len());
        }
        m
    }

    fn row(&self, i: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        (self.ptr[i]..self.ptr[i + 1]).map(|k| (self.col[k] as usize, self.val[k]))
    }

    fn mul(&self, x: &[f64], y: &mut [f64]) {
        for (i, yi) in y.iter_mut().enumerate() {
            *yi = self.row(i).map(|(j, v)| v * x[j]).sum();
        }
    }

    /// One Gauss–Seidel sweep for `A x = b`, forward or backward.
    fn gauss_seidel(&self, x: &mut [f64], b: &[f64], forward: bool) {
        let n = self.n();
        for k in 0..n {
            let i = if forward { k } else { n - 1 - k };
            let d = self.val[self.diag[i]];
            if d <= 0.0 {
                continue;
            }
            let mut s = b[i];
            for (j, v) in self.row(i) {
                if j != i {
                    s -= v * x[j];
                }
            }
            x[i] = s / d;
        }
    }
}

/// One level: its operator, the grid position of each unknown, and (except on the coarsest)
/// the interpolation from the next level as rows of (coarse unknown, weight).
struct FLevel {
    a: Csr,
    h: usize,
    w: usize,
    pos: Vec<(usize, usize)>,
    p: Vec<Vec<(u32, f64)>>,
}

/// Coarse rows (or columns) a fine one interpolates from: coarse `i` sits on fine `2i`.
fn parents(t: usize) -> impl Iterator<Item = (usize, f64)> {
    let (a, b, w) = if t % 2 == 0 {
        (t / 2, usize::MAX, 1.0)
    } else {
        (t / 2, t / 2 + 1, 0.5)
    };
    [(a, w), (b, w)]
        .into_iter()
        .filter(|&(i, _)| i != usize::MAX)
}

/// Builds the coarse level of `f` (setting `f.p`), or `None` when it would not shrink.
fn coarsen(f: &mut FLevel) -> Option<FLevel> {
    // Accumulator window radius: coarse stencils of LᵀL reach 2 points; one to spare.
    const R: usize = 3;
    const S: usize = 2 * R + 1;
    let (hc, wc) = (f.h / 2 + 1, f.w / 2 + 1);
    let mut index = vec![u32::MAX; hc * wc];
    for &(y, x) in &f.pos {
        for (i, _) in parents(y) {
            for (j, _) in parents(x) {
                index[i * wc + j] = 0;
            }
        }
    }
    let mut pos = Vec::new();
    for (k, slot) in index.iter_mut().enumerate() {
        if *slot == 0 {
            *slot = pos.len() as u32;
            pos.push((k / wc, k % wc));
        }
    }
    if pos.len() >= f.pos.len() {
        return None;
    }
    f.p = f
        .pos
        .iter()
        .map(|&(y, x)| {
            let mut row = Vec::with_capacity(4);
            for (i, wy) in parents(y) {
                for (j, wx) in parents(x) {
                    row.push((index[i * wc + j], wy * wx));
                }
            }
            row
        })
        .collect();
    // Children of each coarse unknown, with weights.
    let mut children: Vec<Vec<(usize, f64)>> = vec![Vec::new(); pos.len()];
    for (fi, row) in f.p.iter().enumerate() {
        for &(c, wt) in row {
            children[c as usize].push((fi, wt));
        }
    }
    let fa = &f.a;
    let fp = &f.p;
    let rows: Vec<Vec<(u32, f64)>> = (0..pos.len())
        .into_par_iter()
        .map(|ci| {
            let (iy, ix) = pos[ci];
            let mut acc = [0f64; S * S];
            for &(fi, wfi) in &children[ci] {
                for (g, a) in fa.row(fi) {
                    for &(cj, wgj) in &fp[g] {
                        let (jy, jx) = pos[cj as usize];
                        let k = (jy + R - iy) * S + (jx + R - ix);
                        acc[k] += wfi * a * wgj;
                    }
                }
            }
            let mut row = Vec::new();
            for (k, &v) in acc.iter().enumerate() {
                if v != 0.0 {
                    let (jy, jx) = (iy + k / S - R, ix + k % S - R);
                    row.push((index[jy * wc + jx], v));
                }
            }
            row
        })
        .collect();
    let mut a = Csr::from_rows(rows);
    // Exact symmetry: copy each upper entry onto its mirror.
    for i in 0..a.n() {
        for k in a.ptr[i]..a.ptr[i + 1] {
            let j = a.col[k] as usize;
            if j > i {
                let v = a.val[k];
                if let Ok(m) = a.col[a.ptr[j]..a.ptr[j + 1]].binary_search(&(i as u32)) {
                    a.val[a.ptr[j] + m] = v;
                }
            }
        }
    }
    Some(FLevel {
        a,
        h: hc,
        w: wc,
        pos,
        p: Vec::new(),
    })
}

/// Dense regularised Cholesky factor of the coarsest operator.
struct Dense {
    n: usize,
    l: Vec<f64>,
    /// First column of each row of `l` that is not zero.
    first: Vec<usize>,
}

impl Dense {
    fn new(a: &Csr) -> Self {
        let n = a.n();
        let mut m = vec![0f64; n * n];
        let mut dmax = 0f64;
        for i in 0..n {
            for (j, v) in a.row(i) {
                m[i * n + j] = v;
            }
            dmax = dmax.max(m[i * n + i]);
        }
        let first = crate::multigrid::cholesky_in_place(&mut m, n, 1e-13 * dmax, 1e-14 * dmax);
        Self { n, l: m, first }
    }

    fn solve(&self, b: &[f64], x: &mut [f64]) {
        let n = self.n;
        for i in 0..n {
            let mut s = b[i];
            for k in self.first[i]..i {
                s -= self.l[i * n + k] * x[k];
            }
            x[i] = s / self.l[i * n + i];
        }
        for i in (0..n).rev() {
            let mut s = x[i];
            for k in i + 1..n {
                if self.first[k] <= i {
                    s -= self.l[k * n + i] * x[k];
                }
            }
            x[i] = s / self.l[i * n + i];
        }
    }
}

const COARSEST: usize = 400;

struct Multigrid {
    levels: Vec<FLevel>,
    dense: Dense,
}

impl Multigrid {
    fn new(fine: FLevel) -> Self {
        let mut levels = vec![fine];
        while levels.last().expect("fine level").a.n() > COARSEST {
            let last = levels.last_mut().expect("fine level");
            match coarsen(last) {
                Some(c) => levels.push(c),
                None => break,
            }
        }
        let dense = Dense::new(&levels.last().expect("fine level").a);
        Self { levels, dense }
    }

    /// `x = M⁻¹ b` by one symmetric V(1,1)-cycle from zero.
    fn cycle(&self, l: usize, b: &[f64], x: &mut [f64]) {
        let lev = &self.levels[l];
        if l + 1 == self.levels.len() {
            self.dense.solve(b, x);
            return;
        }
        x.fill(0.0);
        lev.a.gauss_seidel(x, b, true);
        let n = lev.a.n();
        let mut r = vec![0f64; n];
        lev.a.mul(x, &mut r);
        for (ri, bi) in r.iter_mut().zip(b) {
            *ri = bi - *ri;
        }
        let nc = self.levels[l + 1].a.n();
        let mut bc = vec![0f64; nc];
        for (fi, row) in lev.p.iter().enumerate() {
            for &(c, wt) in row {
                bc[c as usize] += wt * r[fi];
            }
        }
        let mut xc = vec![0f64; nc];
        self.cycle(l + 1, &bc, &mut xc);
        for (fi, row) in lev.p.iter().enumerate() {
            x[fi] += row.iter().map(|&(c, wt)| wt * xc[c as usize]).sum::<f64>();
        }
        lev.a.gauss_seidel(x, b, false);
    }
}

/// PCG for `A x = b`; returns (x, iterations, relative residual). When the recurrence has
/// drifted from the true residual it restarts from the true one.
fn pcg(mg: &Multigrid, b: &[f64], tol: f64, max_iterations: usize) -> (Vec<f64>, usize, f64) {
    let a = &mg.levels[0].a;
    let n = b.len();
    let dot = |u: &[f64], v: &[f64]| u.iter().zip(v).map(|(x, y)| x * y).sum::<f64>();
    let bn = dot(b, b).sqrt();
    let mut x = vec![0f64; n];
    if bn == 0.0 {
        return (x, 0, 0.0);
    }
    let mut r = b.to_vec();
    let mut z = vec![0f64; n];
    let mut q = vec![0f64; n];
    let mut it = 0;
    loop {
        let start = it;
        mg.cycle(0, &r, &mut z);
        let mut p = z.clone();
        let mut rz = dot(&r, &z);
        while it < max_iterations && dot(&r, &r).sqrt() > tol * bn {
            a.mul(&p, &mut q);
            let pq = dot(&p, &q);
            if pq <= 0.0 || rz <= 0.0 {
                break;
            }
            let alpha = rz / pq;
            for i in 0..n {
                x[i] += alpha * p[i];
                r[i] -= alpha * q[i];
            }
            it += 1;
            mg.cycle(0, &r, &mut z);
            let rz_new = dot(&r, &z);
            let beta = rz_new / rz;
            rz = rz_new;
            for i in 0..n {
                p[i] = z[i] + beta * p[i];
            }
        }
        a.mul(&x, &mut q);
        for i in 0..n {
            r[i] = b[i] - q[i];
        }
        let res = dot(&r, &r).sqrt() / bn;
        if res <= tol || it >= max_iterations || it == start {
            return (x, it, res);
        }
    }
}

/// The smooth field over `region` (`h × w`) that takes `values[k]` (`d` numbers each) at
/// `points[k]` (row, col) and minimises the energy of the module documentation.
pub fn interpolate_field(
    region: &[bool],
    h: usize,
    w: usize,
    points: &[[i64; 2]],
    values: &[f64],
    d: usize,
    params: &FieldParams,
) -> Result<Field> {
    if h == 0 || w == 0 || region.len() != h * w {
        return Err(invalid(
            "region",
            format!(
                "expected a non-empty {h}×{w} mask, got {} values",
                region.len()
            ),
        ));
    }
    if d == 0 || values.len() != points.len() * d {
        return Err(invalid(
            "values",
            format!(
                "expected {} rows of {d} values like points, got {} values",
                points.len(),
                values.len()
            ),
        ));
    }
    if !(params.tol.is_finite() && params.tol > 0.0) {
        return Err(invalid(
            "tol",
            format!("expected a positive tolerance, got {}", params.tol),
        ));
    }
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(invalid(
            "values",
            format!(
                "expected finite values, found {} in row {}",
                values[i],
                i / d
            ),
        ));
    }
    let mut index = vec![u32::MAX; h * w];
    let mut pos = Vec::new();
    for (p, _) in region.iter().enumerate().filter(|(_, &r)| r) {
        index[p] = pos.len() as u32;
        pos.push(p);
    }
    let n = pos.len();
    if n == 0 {
        return Err(invalid(
            "region",
            "expected at least one pixel set, got none",
        ));
    }
    // Constraints, checked against the region and each other.
    let mut fixed: Vec<Option<usize>> = vec![None; n];
    for (k, &[r, c]) in points.iter().enumerate() {
        if r < 0 || c < 0 || r >= h as i64 || c >= w as i64 {
            return Err(invalid(
                "points",
                format!("point {k} = ({r}, {c}) is outside the {h}×{w} region"),
            ));
        }
        let i = index[r as usize * w + c as usize];
        if i == u32::MAX {
            return Err(invalid(
                "points",
                format!("point {k} = ({r}, {c}) is not inside the region"),
            ));
        }
        match fixed[i as usize] {
            Some(j) if values[j * d..(j + 1) * d] != values[k * d..(k + 1) * d] => {
                return Err(invalid(
                    "values",
                    format!("points {j} and {k} are both ({r}, {c}) but have different values"),
                ));
            }
            Some(_) => {}
            None => fixed[i as usize] = Some(k),
        }
    }
    // Neighbours of each region pixel inside the region.
    let nbrs = |i: usize| {
        let p = pos[i];
        let (y, x) = (p / w, p % w);
        let mut out = [u32::MAX; 4];
        if y > 0 {
            out[0] = index[p - w];
        }
        if x > 0 {
            out[1] = index[p - 1];
        }
        if x + 1 < w {
            out[2] = index[p + 1];
        }
        if y + 1 < h {
            out[3] = index[p + w];
        }
        out
    };
    // Every connected part needs a constraint.
    let mut seen = vec![false; n];
    let mut stack = Vec::new();
    for s in 0..n {
        if seen[s] {
            continue;
        }
        seen[s] = true;
        stack.push(s);
        let mut anchored = false;
        while let Some(i) = stack.pop() {
            anchored |= fixed[i].is_some();
            for j in nbrs(i) {
                if j != u32::MAX && !seen[j as usize] {
                    seen[j as usize] = true;
                    stack.push(j as usize);
                }
            }
        }
        if !anchored {
            return Err(invalid(
                "points",
                format!(
                    "the connected part of region containing (row {}, col {}) has no point; every part needs at least one",
                    pos[s] / w,
                    pos[s] % w
                ),
            ));
        }
    }
    let deg: Vec<f64> = (0..n)
        .map(|i| nbrs(i).iter().filter(|&&j| j != u32::MAX).count() as f64)
        .collect();
    let mut free_index = vec![u32::MAX; n];
    let mut free = Vec::new();
    for i in 0..n {
        if fixed[i].is_none() {
            free_index[i] = free.len() as u32;
            free.push(i);
        }
    }
    // Rows of LᵀL over the free pixels; columns of constrained pixels go to the right side.
    let rows: Vec<(Row, Vec<f64>)> = free
        .par_iter()
        .map(|&i| {
            // (LᵀL)_iq = Σ_k L_ki L_kq over k ∈ {i} ∪ N(i).
            let mut entries: Vec<(usize, f64)> = Vec::with_capacity(16);
            let mut add = |q: usize, v: f64| {
                if let Some(e) = entries.iter_mut().find(|e| e.0 == q) {
                    e.1 += v;
                } else {
                    entries.push((q, v));
                }
            };
            let ni = nbrs(i);
            for k in std::iter::once(i as u32).chain(ni.iter().copied()) {
                if k == u32::MAX {
                    continue;
                }
                let k = k as usize;
                let lki = if k == i { deg[i] } else { -1.0 };
                add(k, lki * deg[k]);
                for q in nbrs(k) {
                    if q != u32::MAX {
                        add(q as usize, -lki);
                    }
                }
            }
            entries.sort_by_key(|e| e.0);
            let mut row = Vec::with_capacity(entries.len());
            let mut rhs = vec![0f64; d];
            for (q, v) in entries {
                if v == 0.0 {
                    continue;
                }
                match fixed[q] {
                    None => row.push((free_index[q], v)),
                    Some(k) => {
                        for c in 0..d {
                            rhs[c] -= v * values[k * d + c];
                        }
                    }
                }
            }
            (row, rhs)
        })
        .collect();
    let mut out = vec![f32::NAN; h * w * d];
    for (i, &p) in pos.iter().enumerate() {
        if let Some(k) = fixed[i] {
            for c in 0..d {
                out[p * d + c] = values[k * d + c] as f32;
            }
        }
    }
    if free.is_empty() {
        return Ok(Field {
            values: out,
            iterations: 0,
            residual: 0.0,
        });
    }
    let (arows, rhs): (Vec<_>, Vec<_>) = rows.into_iter().unzip();
    let a = Csr::from_rows(arows);
    let (y0, x0) = (
        free.iter().map(|&i| pos[i] / w).min().unwrap_or(0),
        free.iter().map(|&i| pos[i] % w).min().unwrap_or(0),
    );
    let fpos: Vec<(usize, usize)> = free
        .iter()
        .map(|&i| (pos[i] / w - y0, pos[i] % w - x0))
        .collect();
    let mg = Multigrid::new(FLevel {
        a,
        h: fpos.iter().map(|p| p.0).max().unwrap_or(0) + 1,
        w: fpos.iter().map(|p| p.1).max().unwrap_or(0) + 1,
        pos: fpos,
        p: Vec::new(),
    });
    let solved: Vec<(Vec<f64>, usize, f64)> = (0..d)
        .into_par_iter()
        .map(|c| {
            let b: Vec<f64> = rhs.iter().map(|r| r[c]).collect();
            pcg(&mg, &b, params.tol, params.max_iterations)
        })
        .collect();
    let (mut iterations, mut residual) = (0, 0f64);
    for (c, (x, it, res)) in solved.iter().enumerate() {
        iterations = iterations.max(*it);
        residual = residual.max(*res);
        for (fi, &i) in free.iter().enumerate() {
            out[pos[i] * d + c] = x[fi] as f32;
        }
    }
    Ok(Field {
        values: out,
        iterations,
        residual,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn disk(n: usize) -> Vec<bool> {
        let m = (n as f64 - 1.0) / 2.0;
        (0..n * n)
            .map(|i| {
                ((i / n) as f64 - m).powi(2) + ((i % n) as f64 - m).powi(2)
                    < (0.45 * n as f64).powi(2)
            })
            .collect()
    }

    #[test]
    fn constraints_are_hit_exactly_and_residual_is_small() {
        let n = 40;
        let pts = [[20, 20], [10, 15], [30, 25], [20, 5]];
        let vals = [1.0, -2.0, 0.5, 3.0, -1.0, 0.25, 2.0, 2.0];
        let f = interpolate_field(&disk(n), n, n, &pts, &vals, 2, &FieldParams::default()).unwrap();
        for (k, p) in pts.iter().enumerate() {
            let o = (p[0] as usize * n + p[1] as usize) * 2;
            assert_eq!(f.values[o].to_bits(), (vals[2 * k] as f32).to_bits());
            assert_eq!(
                f.values[o + 1].to_bits(),
                (vals[2 * k + 1] as f32).to_bits()
            );
        }
        assert!(f.residual <= 1e-10, "{}", f.residual);
        assert!(f.values[0].is_nan());
    }

    #[test]
    fn one_constraint_gives_a_constant() {
        let n = 30;
        let f = interpolate_field(
            &disk(n),
            n,
            n,
            &[[15, 3]],
            &[0.7],
            1,
            &FieldParams::default(),
        )
        .unwrap();
        for (v, r) in f.values.iter().zip(disk(n)) {
            if r {
                assert!((v - 0.7).abs() < 1e-6, "{v}");
            }
        }
    }

    #[test]
    fn galerkin_operators_are_symmetric_and_shrink() {
        // The Dirichlet pixel Laplacian of a disk as the fine operator.
        let n = 64;
        let region = disk(n);
        let mut index = vec![u32::MAX; n * n];
        let pos: Vec<(usize, usize)> = (0..n * n)
            .filter(|&p| region[p])
            .map(|p| (p / n, p % n))
            .collect();
        for (i, &(y, x)) in pos.iter().enumerate() {
            index[y * n + x] = i as u32;
        }
        let rows = pos
            .iter()
            .map(|&(y, x)| {
                let mut row = Vec::new();
                for (yy, xx) in [(y - 1, x), (y, x - 1), (y, x), (y, x + 1), (y + 1, x)] {
                    let j = index[yy * n + xx];
                    if yy == y && xx == x {
                        row.push((j, 4.0));
                    } else if j != u32::MAX {
                        row.push((j, -1.0));
                    }
                }
                row
            })
            .collect();
        let mg = Multigrid::new(FLevel {
            a: Csr::from_rows(rows),
            h: n,
            w: n,
            pos,
            p: Vec::new(),
        });
        assert!(mg.levels.len() >= 3);
        for pair in mg.levels.windows(2) {
            assert!(pair[1].a.n() * 3 < pair[0].a.n());
        }
        for lev in &mg.levels {
            for i in 0..lev.a.n() {
                assert!(lev.a.val[lev.a.diag[i]] > 0.0);
                for (j, v) in lev.a.row(i) {
                    let back = lev.a.row(j).find(|e| e.0 == i).map(|e| e.1);
                    assert_eq!(back, Some(v));
                }
            }
        }
    }

    #[test]
    fn errors_name_the_argument() {
        let r = vec![true, false, false, true];
        let p = FieldParams::default();
        // (1, 1) is not 4-connected to (0, 0): its part has no point.
        let e = interpolate_field(&r, 2, 2, &[[0, 0]], &[1.0], 1, &p).unwrap_err();
        assert!(e.to_string().starts_with("points:"), "{e}");
        let e = interpolate_field(&r, 2, 2, &[[1, 0]], &[1.0], 1, &p).unwrap_err();
        assert!(e.to_string().starts_with("points:"), "{e}");
        let e = interpolate_field(&r, 2, 2, &[[0, 0]], &[f64::NAN], 1, &p).unwrap_err();
        assert!(e.to_string().starts_with("values:"), "{e}");
        let e = interpolate_field(&[false; 4], 2, 2, &[], &[], 1, &p).unwrap_err();
        assert!(e.to_string().starts_with("region:"), "{e}");
    }
}
