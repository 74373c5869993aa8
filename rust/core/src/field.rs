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
//! The constrained pixels `C` are eliminated, so they are hit exactly. The normal equations
//! `(LᵀL)_FF d_F = −(LᵀL)_FC d_C` over the free pixels `F` (13-point, symmetric positive
//! definite) are solved per component of `d`: small systems by a direct Cholesky factor, larger
//! ones by conjugate gradients in `f64` preconditioned with `B²`, `B` one V-cycle of the
//! multigrid of `L_FF` (the Laplacian with the constrained pixels as Dirichlet values, which is
//! positive definite because every part holds a constraint). `(LᵀL)_FF = L_FF² + L_CFᵀ L_CF`
//! differs from `L_FF²` by a matrix of rank at most `|C|`, so the iteration count grows with
//! the number of constraints, not with the size of the region.

// Lane loops index several arrays in lockstep; the index form is what vectorises.
#![allow(clippy::needless_range_loop)]

use rayon::prelude::*;

use crate::error::{invalid, Result};
use crate::solver::bands;
use crate::solver::cholesky::Cholesky;
use crate::solver::laplacian;
use crate::solver::multigrid::{Hierarchy, Level, VCycle};
use crate::solver::pcg::{pcg, Operator, Preconditioner, Solution};

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
    let mut out = vec![f32::NAN; h * w * d];
    for (i, &p) in pos.iter().enumerate() {
        if let Some(k) = fixed[i] {
            for c in 0..d {
                out[p * d + c] = values[k * d + c] as f32;
            }
        }
    }
    let free: Vec<usize> = (0..n).filter(|&i| fixed[i].is_none()).collect();
    if free.is_empty() {
        return Ok(Field {
            values: out,
            iterations: 0,
            residual: 0.0,
        });
    }
    let grid = Grid::new(&pos, w, &deg, &fixed);
    let (gn, gw) = (grid.h * grid.w, grid.w);
    let scale = |b: &[[f64; 1]]| {
        let bb = bands::dot(b, b, gw)[0];
        if bb > 0.0 {
            bb.sqrt()
        } else {
            1.0
        }
    };
    let solved: Result<Vec<Solution<1>>> = if free.len() <= DIRECT {
        // Small systems: the exact factor as the preconditioner, so CG takes one step.
        let (factor, rhs) = normal_equations(&free, &deg, &fixed, nbrs, values, d);
        let cells: Vec<usize> = free.iter().map(|&i| grid.cell[i]).collect();
        (0..d)
            .into_par_iter()
            .map(|c| {
                let mut b = vec![[0f64; 1]; gn];
                for (j, &g) in cells.iter().enumerate() {
                    b[g] = [rhs[j * d + c]];
                }
                let mut direct = Direct {
                    factor: &factor,
                    cells: &cells,
                    w: gw,
                    y: vec![[0.0; 1]; cells.len()],
                };
                let s = scale(&b);
                let (tol, max) = (params.tol, params.max_iterations);
                pcg(&mut Normal::new(&grid), &mut direct, &b, gw, [s], tol, max)
            })
            .collect()
    } else {
        let mg = Hierarchy::new(Level::five(grid.h, grid.w, grid.deg_free.clone()));
        (0..d)
            .into_par_iter()
            .map(|c| {
                // The right-hand side −(LᵀL)_FC d_C = −(L_F· L d̃_C), d̃_C = d on C, 0 elsewhere.
                let mut v = vec![[0f64; 1]; gn];
                for (i, f) in fixed.iter().enumerate() {
                    if let Some(k) = f {
                        v[grid.cell[i]] = [values[k * d + c]];
                    }
                }
                let mut op = Normal::new(&grid);
                let mut b = vec![[0f64; 1]; gn];
                op.apply(&v, &mut b);
                for t in &mut b {
                    t[0] = -t[0];
                }
                let s = scale(&b);
                let (tol, max) = (params.tol, params.max_iterations);
                pcg(&mut op, &mut SquaredVCycle::new(&mg), &b, gw, [s], tol, max)
            })
            .collect()
    };
    let solved = solved?;
    let (mut iterations, mut residual) = (0, 0f64);
    for (c, s) in solved.iter().enumerate() {
        iterations = iterations.max(s.iterations);
        residual = residual.max(s.residual);
        for &i in &free {
            out[pos[i] * d + c] = s.x[grid.cell[i]][0] as f32;
        }
    }
    Ok(Field {
        values: out,
        iterations,
        residual,
    })
}

/// Systems with at most this many free pixels are factored directly.
const DIRECT: usize = 400;

/// The region on a framed, odd-sized grid over its bounding box (the layout of the solvers).
struct Grid {
    h: usize,
    w: usize,
    /// Grid cell of each region pixel.
    cell: Vec<usize>,
    /// `deg` at the region's pixels, 0 elsewhere: the diagonal of `L`.
    deg_region: Vec<f32>,
    /// `deg` at the free pixels, 0 elsewhere: the diagonal of `L_FF`.
    deg_free: Vec<f32>,
}

impl Grid {
    fn new(pos: &[usize], w: usize, deg: &[f64], fixed: &[Option<usize>]) -> Self {
        let (mut y0, mut y1, mut x0, mut x1) = (usize::MAX, 0, usize::MAX, 0);
        for &p in pos {
            let (y, x) = (p / w, p % w);
            y0 = y0.min(y);
            y1 = y1.max(y);
            x0 = x0.min(x);
            x1 = x1.max(x);
        }
        let (gh, gw) = ((y1 - y0 + 3) | 1, (x1 - x0 + 3) | 1);
        let cell: Vec<usize> = pos
            .iter()
            .map(|&p| (p / w - y0 + 1) * gw + p % w - x0 + 1)
            .collect();
        let mut deg_region = vec![0f32; gh * gw];
        let mut deg_free = vec![0f32; gh * gw];
        for (i, &g) in cell.iter().enumerate() {
            deg_region[g] = deg[i] as f32;
            if fixed[i].is_none() {
                deg_free[g] = deg[i] as f32;
            }
        }
        Self {
            h: gh,
            w: gw,
            cell,
            deg_region,
            deg_free,
        }
    }
}

/// The normal operator `(LᵀL)_FF = L_F· L_·F` on grid vectors that are 0 off the free pixels,
/// applied as two Laplacian passes.
struct Normal<'a> {
    grid: &'a Grid,
    /// `L p` over the whole region.
    t: Vec<[f64; 1]>,
    /// `A x` of [`Operator::residual`].
    ax: Vec<[f64; 1]>,
}

impl<'a> Normal<'a> {
    fn new(grid: &'a Grid) -> Self {
        let n = grid.h * grid.w;
        Self {
            grid,
            t: vec![[0.0; 1]; n],
            ax: vec![[0.0; 1]; n],
        }
    }
}

impl Operator<f64, 1> for Normal<'_> {
    fn apply(&mut self, p: &[[f64; 1]], q: &mut [[f64; 1]]) -> [f64; 1] {
        let g = self.grid;
        laplacian::apply(&g.deg_region, g.w, p, &mut self.t);
        laplacian::apply(&g.deg_free, g.w, &self.t, q);
        bands::dot(p, q, g.w)
    }

    fn residual(&mut self, b: &[[f64; 1]], x: &[[f64; 1]], r: &mut [[f64; 1]]) -> [f64; 1] {
        let g = self.grid;
        let mut ax = std::mem::take(&mut self.ax);
        laplacian::apply(&g.deg_region, g.w, x, &mut self.t);
        laplacian::apply(&g.deg_free, g.w, &self.t, &mut ax);
        for ((ri, bi), ai) in r.iter_mut().zip(b).zip(&ax) {
            ri[0] = bi[0] - ai[0];
        }
        self.ax = ax;
        bands::dot(r, r, g.w)
    }
}

/// `B²` for `B` one V-cycle of the multigrid of `L_FF` (in `f32`): symmetric positive definite,
/// and close to `(LᵀL)_FF⁻¹` up to a perturbation of rank at most `|C|`.
struct SquaredVCycle<'a> {
    vcycle: VCycle<'a, 1>,
    w: usize,
    r: Vec<[f32; 1]>,
    t: Vec<[f32; 1]>,
    z: Vec<[f32; 1]>,
}

impl<'a> SquaredVCycle<'a> {
    fn new(mg: &'a Hierarchy) -> Self {
        let lev = &mg.levels[0];
        let n = lev.h * lev.w;
        Self {
            vcycle: VCycle::new(mg),
            w: lev.w,
            r: vec![[0.0; 1]; n],
            t: vec![[0.0; 1]; n],
            z: vec![[0.0; 1]; n],
        }
    }
}

impl Preconditioner<f64, 1> for SquaredVCycle<'_> {
    fn apply(&mut self, r: &[[f64; 1]], z: &mut [[f64; 1]]) -> [f64; 1] {
        for (a, b) in self.r.iter_mut().zip(r) {
            a[0] = b[0] as f32;
        }
        self.vcycle.apply(&self.r, &mut self.t);
        self.vcycle.apply(&self.t, &mut self.z);
        for (a, b) in z.iter_mut().zip(&self.z) {
            a[0] = f64::from(b[0]);
        }
        bands::dot(r, z, self.w)
    }
}

/// The exact solve of small systems: the Cholesky factor of `(LᵀL)_FF` on the free cells.
struct Direct<'a> {
    factor: &'a Cholesky,
    /// Grid cell of each free pixel, in the factor's order.
    cells: &'a [usize],
    w: usize,
    y: Vec<[f64; 1]>,
}

impl Preconditioner<f64, 1> for Direct<'_> {
    fn apply(&mut self, r: &[[f64; 1]], z: &mut [[f64; 1]]) -> [f64; 1] {
        for (y, &g) in self.y.iter_mut().zip(self.cells) {
            *y = r[g];
        }
        self.factor.solve(&mut self.y);
        z.fill([0.0]);
        for (y, &g) in self.y.iter().zip(self.cells) {
            z[g] = *y;
        }
        bands::dot(r, z, self.w)
    }
}

/// The Cholesky factor of `(LᵀL)_FF` over the free pixels `free` (raster order, so the profile
/// is a band a few grid rows wide), and the right-hand sides `−(LᵀL)_FC d_C` (`d` per row).
fn normal_equations(
    free: &[usize],
    deg: &[f64],
    fixed: &[Option<usize>],
    nbrs: impl Fn(usize) -> [u32; 4],
    values: &[f64],
    d: usize,
) -> (Cholesky, Vec<f64>) {
    let nf = free.len();
    let mut fidx = vec![usize::MAX; deg.len()];
    for (j, &i) in free.iter().enumerate() {
        fidx[i] = j;
    }
    let mut m = vec![0f64; nf * nf];
    let mut rhs = vec![0f64; nf * d];
    let mut dmax = 0f64;
    let with = |k: usize| {
        std::iter::once(k as u32)
            .chain(nbrs(k))
            .filter(|&j| j != u32::MAX)
    };
    let mut entries: Vec<(usize, f64)> = Vec::with_capacity(16);
    for (a, &i) in free.iter().enumerate() {
        // (LᵀL)_iq = Σ_k L_ki L_kq over k ∈ {i} ∪ N(i) (small integers: exact in any order).
        entries.clear();
        for k in with(i) {
            let k = k as usize;
            let lki = if k == i { deg[i] } else { -1.0 };
            for q in with(k) {
                let q = q as usize;
                let v = lki * if q == k { deg[k] } else { -1.0 };
                match entries.iter_mut().find(|e| e.0 == q) {
                    Some(e) => e.1 += v,
                    None => entries.push((q, v)),
                }
            }
        }
        entries.sort_by_key(|e| e.0);
        for &(q, v) in &entries {
            if v == 0.0 {
                continue;
            }
            match fixed[q] {
                None => m[a * nf + fidx[q]] = v,
                Some(k) => {
                    for c in 0..d {
                        rhs[a * d + c] -= v * values[k * d + c];
                    }
                }
            }
        }
        dmax = dmax.max(m[a * nf + a]);
    }
    // The system is positive definite; the tiny shift keeps the factor of earlier versions.
    (Cholesky::new(m, nf, 1e-13 * dmax, 1e-14 * dmax), rhs)
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

    /// The energy's minimiser by dense Gaussian elimination on `LᵀL` with the constraints as
    /// equations, from the definition (no code shared with the solver).
    fn reference(region: &[bool], n: usize, pts: &[[i64; 2]], vals: &[f64]) -> Vec<f64> {
        let cells: Vec<usize> = (0..n * n).filter(|&p| region[p]).collect();
        let m = cells.len();
        let idx = |p: usize| cells.iter().position(|&q| q == p);
        let mut l = vec![vec![0f64; m]; m];
        for (i, &p) in cells.iter().enumerate() {
            let (y, x) = (p / n, p % n);
            let mut nb = Vec::new();
            if y > 0 {
                nb.push(p - n);
            }
            if x > 0 {
                nb.push(p - 1);
            }
            if x + 1 < n {
                nb.push(p + 1);
            }
            if y + 1 < n {
                nb.push(p + n);
            }
            for q in nb {
                if let Some(j) = idx(q) {
                    l[i][j] = -1.0;
                    l[i][i] += 1.0;
                }
            }
        }
        let mut a = vec![vec![0f64; m + 1]; m];
        for i in 0..m {
            for j in 0..m {
                a[i][j] = (0..m).map(|k| l[k][i] * l[k][j]).sum();
            }
        }
        for (k, &[r, c]) in pts.iter().enumerate() {
            let i = idx(r as usize * n + c as usize).unwrap();
            a[i].iter_mut().for_each(|v| *v = 0.0);
            a[i][i] = 1.0;
            a[i][m] = vals[k];
        }
        for col in 0..m {
            let piv = (col..m)
                .max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs()))
                .unwrap();
            a.swap(col, piv);
            for row in 0..m {
                if row != col && a[row][col] != 0.0 {
                    let f = a[row][col] / a[col][col];
                    for k in col..=m {
                        a[row][k] -= f * a[col][k];
                    }
                }
            }
        }
        let mut out = vec![f64::NAN; n * n];
        for (i, &p) in cells.iter().enumerate() {
            out[p] = a[i][m] / a[i][i];
        }
        out
    }

    #[test]
    fn direct_and_iterative_paths_match_a_dense_solve() {
        // 16² disk: the exact factor (one CG step); 26² disk: the multigrid PCG path.
        for n in [16usize, 26] {
            let region = disk(n);
            let free = region.iter().filter(|&&r| r).count() - 3;
            assert_eq!(free <= DIRECT, n == 16);
            let c = n as i64 / 2;
            let pts = [[c, 2], [c, n as i64 - 3], [2, c]];
            let vals = [1.0, -0.5, 2.0];
            let f =
                interpolate_field(&region, n, n, &pts, &vals, 1, &FieldParams::default()).unwrap();
            let r = reference(&region, n, &pts, &vals);
            for p in 0..n * n {
                if region[p] {
                    assert!(
                        (f64::from(f.values[p]) - r[p]).abs() < 1e-5,
                        "{n}: {} vs {}",
                        f.values[p],
                        r[p]
                    );
                }
            }
            assert!(f.residual <= 1e-10, "{n}: {}", f.residual);
            assert_eq!(
                f.iterations <= 1,
                n == 16,
                "{n}: {} iterations",
                f.iterations
            );
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
