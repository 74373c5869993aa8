//! Exact earth mover's distance between small histograms, and the sliding-window map of it
//! that layer induction needs (Assa & Cohen-Or, Eq. 1: the colour distance S(x, c) between
//! the histogram of each pixel's 8×8 neighbourhood and the histogram of the user's layer).
//!
//! The EMD between two histograms of equal (unit) mass is a transportation problem with
//! `n × n` cells. [`Transport`] solves it exactly by the transportation simplex on a spanning
//! tree basis: a least-cost starting basis, then primal (MODI) pivots, with Bland's rule once
//! a run of degenerate pivots suggests cycling. Zero bins and ties are ordinary degenerate
//! bases here: the tree always has `2n − 1` edges, some carrying no flow.
//!
//! The map reuses work twice. Window histograms slide along a row (one column in, one out),
//! and a window whose histogram equals the previous one reuses its value. And since only the
//! supplies change from one window to the next while the costs stay, the previous optimal
//! basis stays *dual* feasible: the next window starts from it, recomputes the tree flows
//! (O(n)) and, where some flow turned negative, restores feasibility by dual simplex pivots
//! (usually none or one). Every row starts from the same basis, so the result does not depend
//! on the number of threads.

use rayon::prelude::*;

use crate::{cancel, error::invalid, Result};

/// The largest number of bins [`Transport`] accepts.
pub const MAX_BINS: usize = 32;

/// Flows and reduced costs this far below zero count as zero: the masses are sums of a few
/// dozen terms of order 1, so their rounding is far below this.
const EPS: f64 = 1e-12;

/// An exact transportation-simplex solver for `n`-bin histograms under a fixed ground
/// distance; it keeps its last optimal basis so the next solve can start from it.
#[derive(Clone, Debug)]
pub struct Transport {
    n: usize,
    cost: Vec<f64>,
    /// Cells in order of increasing cost (ties by index), for the least-cost start.
    order: Vec<usize>,
    /// Basis cells `i * n + j`, always `2n − 1` of them, and their flows.
    basis: Vec<usize>,
    flow: Vec<f64>,
    /// Whether `basis` is an optimal basis of some earlier solve (hence dual feasible).
    warm: bool,
    // Scratch, kept to avoid allocating per solve.
    u: Vec<f64>,
    v: Vec<f64>,
    adj: Vec<Vec<(usize, usize)>>,
}

impl Transport {
    /// A solver for `n` bins; `ground` is `n × n` row-major, finite and non-negative.
    pub fn new(n: usize, ground: &[f64]) -> Result<Self> {
        if n == 0 || n > MAX_BINS {
            return Err(invalid(
                "n_bins",
                format!("expected 1 to {MAX_BINS} bins, got {n}"),
            ));
        }
        if ground.len() != n * n {
            return Err(invalid(
                "ground",
                format!("expected {n}×{n} = {} values, got {}", n * n, ground.len()),
            ));
        }
        if ground.iter().any(|d| !d.is_finite() || *d < 0.0) {
            return Err(invalid("ground", "expected finite, non-negative distances"));
        }
        let mut order: Vec<usize> = (0..n * n).collect();
        order.sort_by(|&a, &b| ground[a].total_cmp(&ground[b]).then(a.cmp(&b)));
        Ok(Self {
            n,
            cost: ground.to_vec(),
            order,
            basis: Vec::with_capacity(2 * n),
            flow: Vec::with_capacity(2 * n),
            warm: false,
            u: vec![0.0; n],
            v: vec![0.0; n],
            adj: vec![Vec::with_capacity(n); 2 * n],
        })
    }

    /// The number of bins.
    #[must_use]
    pub fn bins(&self) -> usize {
        self.n
    }

    /// The minimal cost of moving `a` onto `b`; both have `n` non-negative entries of equal
    /// sum (the caller normalises). Starts from the last optimal basis when there is one.
    pub fn solve(&mut self, a: &[f64], b: &[f64]) -> Result<f64> {
        if self.warm {
            self.flows(a, b);
            if self.dual(a, b) {
                return Ok(self.value());
            }
        }
        self.least_cost(a, b);
        self.primal()?;
        self.warm = true;
        Ok(self.value())
    }

    /// The optimal flow of the last solve as `(cell, flow)` pairs (`cell = i * n + j`).
    #[must_use]
    pub fn plan(&self) -> Vec<(usize, f64)> {
        self.basis
            .iter()
            .copied()
            .zip(self.flow.iter().copied())
            .collect()
    }

    fn value(&self) -> f64 {
        self.basis
            .iter()
            .zip(&self.flow)
            .map(|(&c, &x)| self.cost[c] * x.max(0.0))
            .sum()
    }

    /// The least-cost starting basis: the cheapest cell whose row and column are both open
    /// gets as much as it can, and exactly one of the two closes (both only at the end), so
    /// the `2n − 1` cells chosen form a spanning tree.
    fn least_cost(&mut self, a: &[f64], b: &[f64]) {
        let n = self.n;
        let mut ra = a.to_vec();
        let mut rb = b.to_vec();
        let mut row_open = [true; MAX_BINS];
        let mut col_open = [true; MAX_BINS];
        let (mut rows, mut cols) = (n, n);
        self.basis.clear();
        self.flow.clear();
        for &c in &self.order {
            let (i, j) = (c / n, c % n);
            if !row_open[i] || !col_open[j] {
                continue;
            }
            let x = ra[i].min(rb[j]);
            self.basis.push(c);
            self.flow.push(x);
            ra[i] -= x;
            rb[j] -= x;
            if rows == 1 && cols == 1 {
                break;
            }
            // Close the line that ran out; on a tie close the row unless it is the last.
            if (ra[i] <= rb[j] && rows > 1) || cols == 1 {
                row_open[i] = false;
                rows -= 1;
                rb[j] += ra[i].max(0.0);
                ra[i] = 0.0;
            } else {
                col_open[j] = false;
                cols -= 1;
                ra[i] += rb[j].max(0.0);
                rb[j] = 0.0;
            }
        }
        debug_assert_eq!(self.basis.len(), 2 * n - 1);
    }

    /// Rebuilds the tree's adjacency: rows are nodes `0..n`, columns `n..2n`.
    fn adjacency(&mut self) {
        let n = self.n;
        for l in &mut self.adj {
            l.clear();
        }
        for (k, &c) in self.basis.iter().enumerate() {
            let (i, j) = (c / n, c % n);
            self.adj[i].push((n + j, k));
            self.adj[n + j].push((i, k));
        }
    }

    /// Dual potentials `u_i + v_j = cost_ij` on the tree, `u_0 = 0` (needs [`Self::adjacency`]).
    fn potentials(&mut self) {
        let n = self.n;
        let mut seen = [false; 2 * MAX_BINS];
        let mut stack = [0usize; 2 * MAX_BINS];
        let mut top = 1;
        stack[0] = 0;
        seen[0] = true;
        self.u[0] = 0.0;
        while top > 0 {
            top -= 1;
            let p = stack[top];
            for &(q, k) in &self.adj[p] {
                if seen[q] {
                    continue;
                }
                seen[q] = true;
                let c = self.cost[self.basis[k]];
                if q >= n {
                    self.v[q - n] = c - self.u[p];
                } else {
                    self.u[q] = c - self.v[p - n];
                }
                stack[top] = q;
                top += 1;
            }
        }
    }

    /// The flows the current tree carries for supplies `a` and demands `b`, by peeling leaves.
    fn flows(&mut self, a: &[f64], b: &[f64]) {
        let n = self.n;
        self.adjacency();
        let mut rest = [0.0f64; 2 * MAX_BINS];
        rest[..n].copy_from_slice(a);
        rest[n..2 * n].copy_from_slice(b);
        let mut degree = [0usize; 2 * MAX_BINS];
        for (p, l) in self.adj.iter().enumerate().take(2 * n) {
            degree[p] = l.len();
        }
        let mut done = [false; 2 * MAX_BINS];
        let mut queue = [0usize; 2 * MAX_BINS];
        let (mut head, mut tail) = (0, 0);
        for (p, &d) in degree.iter().enumerate().take(2 * n) {
            if d == 1 {
                queue[tail] = p;
                tail += 1;
            }
        }
        while head < tail {
            let p = queue[head];
            head += 1;
            if degree[p] != 1 {
                continue;
            }
            let Some(&(q, k)) = self.adj[p].iter().find(|&&(_, k)| !done[k]) else {
                continue;
            };
            done[k] = true;
            let x = rest[p];
            self.flow[k] = x;
            rest[q] -= x;
            degree[p] = 0;
            degree[q] -= 1;
            if degree[q] == 1 {
                queue[tail] = q;
                tail += 1;
            }
        }
    }

    /// Dual simplex from the current (dual feasible) tree: while some flow is negative, take
    /// the most negative out and bring in the cheapest cell that crosses the cut in the
    /// direction that can carry it. `false` if it gave up (then the caller starts afresh).
    fn dual(&mut self, a: &[f64], b: &[f64]) -> bool {
        let n = self.n;
        for _ in 0..(8 * n) {
            let Some(k) = (0..self.basis.len())
                .filter(|&k| self.flow[k] < -EPS)
                .min_by(|&x, &y| self.flow[x].total_cmp(&self.flow[y]).then(x.cmp(&y)))
            else {
                return true;
            };
            self.potentials();
            // The side of the cut that holds the leaving cell's row.
            let mut side = [false; 2 * MAX_BINS];
            let (p, _) = (self.basis[k] / n, self.basis[k] % n);
            let mut stack = [0usize; 2 * MAX_BINS];
            let mut top = 1;
            stack[0] = p;
            side[p] = true;
            while top > 0 {
                top -= 1;
                let x = stack[top];
                for &(y, e) in &self.adj[x] {
                    if e != k && !side[y] {
                        side[y] = true;
                        stack[top] = y;
                        top += 1;
                    }
                }
            }
            // The row's side lacks mass: it must receive along a row outside → column inside.
            let mut best: Option<(f64, usize)> = None;
            for i in (0..n).filter(|&i| !side[i]) {
                for j in (0..n).filter(|&j| side[n + j]) {
                    let c = i * n + j;
                    let r = self.cost[c] - self.u[i] - self.v[j];
                    if best.is_none_or(|(br, _)| r < br) {
                        best = Some((r, c));
                    }
                }
            }
            let Some((_, c)) = best else {
                return false;
            };
            self.basis[k] = c;
            self.flows(a, b);
        }
        false
    }

    /// Primal (MODI) pivots to optimality from a feasible tree.
    fn primal(&mut self) -> Result<()> {
        let n = self.n;
        let mut degenerate = 0usize;
        let limit = 64 * n * n;
        for _ in 0..limit {
            self.adjacency();
            self.potentials();
            let bland = degenerate > 2 * n;
            let mut basic = [false; MAX_BINS * MAX_BINS];
            for &c in &self.basis {
                basic[c] = true;
            }
            let mut enter: Option<(f64, usize)> = None;
            for c in (0..n * n).filter(|&c| !basic[c]) {
                let r = self.cost[c] - self.u[c / n] - self.v[c % n];
                if r < -EPS && enter.is_none_or(|(br, _)| r < br) {
                    enter = Some((r, c));
                    if bland {
                        break;
                    }
                }
            }
            let Some((_, c)) = enter else {
                return Ok(());
            };
            // The tree path from the entering cell's column back to its row; its cells
            // alternate −, +, −, … around the cycle the entering cell closes.
            let (ei, ej) = (c / n, c % n);
            let mut parent = [(usize::MAX, usize::MAX); 2 * MAX_BINS];
            let mut stack = [0usize; 2 * MAX_BINS];
            let mut top = 1;
            stack[0] = ei;
            parent[ei] = (ei, usize::MAX);
            while top > 0 {
                top -= 1;
                let x = stack[top];
                for &(y, e) in &self.adj[x] {
                    if parent[y].0 == usize::MAX {
                        parent[y] = (x, e);
                        stack[top] = y;
                        top += 1;
                    }
                }
            }
            let mut path = Vec::with_capacity(2 * n);
            let mut x = n + ej;
            while x != ei {
                let (px, e) = parent[x];
                path.push(e);
                x = px;
            }
            let mut leave: Option<(f64, usize, usize)> = None;
            for (pos, &e) in path.iter().enumerate().step_by(2) {
                let f = self.flow[e].max(0.0);
                let better = match leave {
                    None => true,
                    // Exact ties go to the smaller cell (Bland's rule).
                    Some((bf, _, be)) => f
                        .total_cmp(&bf)
                        .then(self.basis[e].cmp(&self.basis[be]))
                        .is_lt(),
                };
                if better {
                    leave = Some((f, pos, e));
                }
            }
            let Some((theta, _, out)) = leave else {
                return Err(crate::Error::Internal(
                    "emd: a cycle without a − cell".into(),
                ));
            };
            degenerate = if theta <= EPS { degenerate + 1 } else { 0 };
            for (pos, &e) in path.iter().enumerate() {
                if pos % 2 == 0 {
                    self.flow[e] -= theta;
                } else {
                    self.flow[e] += theta;
                }
            }
            self.basis[out] = c;
            self.flow[out] = theta;
        }
        Err(crate::Error::Internal(
            "emd: the transportation simplex did not converge".into(),
        ))
    }
}

/// Checks a histogram and returns it scaled to unit mass.
fn unit(name: &'static str, h: &[f64], n: usize) -> Result<Vec<f64>> {
    if h.len() != n {
        return Err(invalid(name, format!("expected {n} bins, got {}", h.len())));
    }
    if h.iter().any(|x| !x.is_finite() || *x < 0.0) {
        return Err(invalid(name, "expected finite, non-negative counts"));
    }
    let s: f64 = h.iter().sum();
    if s <= 0.0 {
        return Err(invalid(name, "the histogram is empty (all bins zero)"));
    }
    Ok(h.iter().map(|x| x / s).collect())
}

/// The exact EMD between histograms `a` and `b` (each scaled to unit mass first) under the
/// `n × n` ground distance `ground`.
pub fn emd(a: &[f64], b: &[f64], ground: &[f64]) -> Result<f64> {
    let mut t = Transport::new(a.len(), ground)?;
    let a = unit("hist_a", a, t.bins())?;
    let b = unit("hist_b", b, t.bins())?;
    t.solve(&a, &b)
}

/// Inputs of [`emd_map`].
#[derive(Clone, Copy, Debug)]
pub struct MapInput<'a> {
    /// `H × W` palette indices, row-major; `−1` marks pixels outside the leaf, which count in
    /// no window and get no value.
    pub labels: &'a [i32],
    /// Height and width.
    pub size: (usize, usize),
    /// The number of palette colours (at most [`MAX_BINS`]).
    pub n_bins: usize,
    /// `n_bins × n_bins` ground distances between the palette colours.
    pub ground: &'a [f64],
    /// The histogram the windows are compared with (any positive mass).
    pub target: &'a [f64],
    /// The window side: a pixel's window spans rows `y − window/2 .. y − window/2 + window`
    /// (and the same for columns), clipped to the image.
    pub window: usize,
}

/// The normalised EMD between `target` and the histogram of every pixel's window: the EMD
/// divided by the largest ground distance, so 0 is a match and 1 the farthest two histograms
/// can be. Pixels outside the leaf (label −1) get NaN; a window always holds its own centre,
/// so every other pixel gets a value. With all ground distances zero every value is 0.
pub fn emd_map(input: &MapInput<'_>) -> Result<Vec<f32>> {
    let (h, w) = input.size;
    let n = input.n_bins;
    if input.labels.len() != h * w {
        return Err(invalid(
            "labels",
            format!(
                "expected {h}×{w} = {} values, got {}",
                h * w,
                input.labels.len()
            ),
        ));
    }
    if input.window == 0 {
        return Err(invalid("window", "expected a window of at least 1 pixel"));
    }
    let base = Transport::new(n, input.ground)?;
    let target = unit("target", input.target, n)?;
    if let Some(bad) = input.labels.iter().find(|&&l| l < -1 || l >= n as i32) {
        return Err(invalid(
            "labels",
            format!("expected palette indices 0..{n} or -1, got {bad}"),
        ));
    }
    let scale = input.ground.iter().copied().fold(0.0f64, f64::max);
    // One optimal basis (any supplies) is dual feasible for all: every row starts from it.
    let mut base = base;
    base.solve(&target, &target)?;
    let win = input.window;
    let before = win / 2;
    let after = win - before; // exclusive
    let mut out = vec![f32::NAN; h * w];
    out.par_chunks_mut(w.max(1))
        .enumerate()
        .try_for_each(|(y, row)| -> Result<()> {
            if cancel::cancelled() {
                return Ok(());
            }
            let y0 = y.saturating_sub(before);
            let y1 = (y + after).min(h);
            let mut solver = base.clone();
            let mut counts = [0u32; MAX_BINS];
            let mut total = 0u32;
            let mut last: Option<([u32; MAX_BINS], f32)> = None;
            let mut supply = vec![0.0f64; n];
            let column = |x: usize, counts: &mut [u32; MAX_BINS], total: &mut u32, add: bool| {
                for yy in y0..y1 {
                    let l = input.labels[yy * w + x];
                    if l >= 0 {
                        if add {
                            counts[l as usize] += 1;
                            *total += 1;
                        } else {
                            counts[l as usize] -= 1;
                            *total -= 1;
                        }
                    }
                }
            };
            // Columns [x − before, x + after) are in the window of pixel x.
            for x in 0..after.saturating_sub(1).min(w) {
                column(x, &mut counts, &mut total, true);
            }
            // `x` also indexes the labels and the columns entering and leaving.
            #[allow(clippy::needless_range_loop)]
            for x in 0..w {
                if x + after - 1 < w {
                    column(x + after - 1, &mut counts, &mut total, true);
                }
                if x > before {
                    column(x - before - 1, &mut counts, &mut total, false);
                }
                if input.labels[y * w + x] < 0 || total == 0 {
                    continue;
                }
                if let Some((c, s)) = last {
                    if c[..n] == counts[..n] {
                        row[x] = s;
                        continue;
                    }
                }
                let t = f64::from(total);
                for (s, &c) in supply.iter_mut().zip(&counts[..n]) {
                    *s = f64::from(c) / t;
                }
                let d = solver.solve(&supply, &target)?;
                let s = if scale > 0.0 { (d / scale) as f32 } else { 0.0 };
                row[x] = s;
                last = Some((counts, s));
            }
            Ok(())
        })?;
    cancel::check()?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Rng(crate::rng::Rng);

    impl Rng {
        fn new(seed: u64) -> Self {
            Self(crate::rng::Rng::keyed(seed, 0, 0))
        }

        fn f64(&mut self) -> f64 {
            (self.0.next_u64() >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    fn line_ground(n: usize) -> Vec<f64> {
        (0..n * n).map(|c| (c / n).abs_diff(c % n) as f64).collect()
    }

    fn random_hist(rng: &mut Rng, n: usize, zeros: bool) -> Vec<f64> {
        (0..n)
            .map(|_| {
                let x = rng.f64();
                if zeros && x < 0.4 {
                    0.0
                } else {
                    x
                }
            })
            .collect()
    }

    /// Optimality by the LP's own conditions: the plan moves `a` onto `b`, the potentials are
    /// dual feasible, and every cell that carries flow is tight (complementary slackness);
    /// and the value equals the dual objective.
    fn check_optimal(t: &mut Transport, a: &[f64], b: &[f64]) -> f64 {
        let n = t.bins();
        let d = t.solve(a, b).unwrap();
        let plan = t.plan();
        let (mut rs, mut cs) = (vec![0.0; n], vec![0.0; n]);
        for &(c, x) in &plan {
            assert!(x >= -1e-9, "negative flow {x}");
            rs[c / n] += x;
            cs[c % n] += x;
        }
        for i in 0..n {
            assert!((rs[i] - a[i]).abs() < 1e-9 && (cs[i] - b[i]).abs() < 1e-9);
        }
        t.adjacency();
        t.potentials();
        for c in 0..n * n {
            let r = t.cost[c] - t.u[c / n] - t.v[c % n];
            assert!(r >= -1e-9, "dual infeasible at {c}: {r}");
        }
        for &(c, x) in &plan {
            let r = t.cost[c] - t.u[c / n] - t.v[c % n];
            assert!(x.abs() < 1e-12 || r.abs() < 1e-9);
        }
        let dual: f64 = (0..n).map(|i| t.u[i] * a[i] + t.v[i] * b[i]).sum();
        assert!((dual - d).abs() < 1e-9, "primal {d} vs dual {dual}");
        d
    }

    /// Brute force for tiny problems: every vertex of the transportation polytope is a
    /// spanning-tree basis; try every set of 2n − 1 cells.
    fn brute(a: &[f64], b: &[f64], ground: &[f64]) -> f64 {
        let n = a.len();
        let cells = n * n;
        let k = 2 * n - 1;
        let mut best = f64::INFINITY;
        for mask in 0u32..(1 << cells) {
            if mask.count_ones() as usize != k {
                continue;
            }
            let mut t = Transport::new(n, ground).unwrap();
            t.basis = (0..cells).filter(|c| mask & (1 << c) != 0).collect();
            t.flow = vec![0.0; k];
            t.adjacency();
            // A spanning tree: connected with 2n − 1 edges.
            let mut seen = vec![false; 2 * n];
            let mut stack = vec![0];
            seen[0] = true;
            while let Some(p) = stack.pop() {
                for &(q, _) in &t.adj[p] {
                    if !seen[q] {
                        seen[q] = true;
                        stack.push(q);
                    }
                }
            }
            if seen.iter().any(|s| !s) {
                continue;
            }
            t.flows(a, b);
            if t.flow.iter().all(|&x| x >= -1e-12) {
                best = best.min(t.value());
            }
        }
        best
    }

    #[test]
    fn identical_histograms_cost_nothing() {
        let mut rng = Rng::new(1);
        for n in [1, 2, 5, 16, 32] {
            let g: Vec<f64> = (0..n * n)
                .map(|c| if c / n == c % n { 0.0 } else { 1.0 + rng.f64() })
                .collect();
            let a = random_hist(&mut rng, n, true);
            let a = if a.iter().sum::<f64>() == 0.0 {
                vec![1.0; n]
            } else {
                a
            };
            assert!(emd(&a, &a, &g).unwrap().abs() < 1e-12, "n = {n}");
        }
    }

    #[test]
    fn one_dimensional_histograms_match_the_cdf_formula() {
        let mut rng = Rng::new(2);
        for n in [2, 3, 8, 16, 32] {
            for zeros in [false, true] {
                let g = line_ground(n);
                let mut a = random_hist(&mut rng, n, zeros);
                let mut b = random_hist(&mut rng, n, zeros);
                a[0] += 0.1;
                b[n - 1] += 0.1;
                let (sa, sb): (f64, f64) = (a.iter().sum(), b.iter().sum());
                let (mut ca, mut cb, mut want) = (0.0, 0.0, 0.0);
                for i in 0..n - 1 {
                    ca += a[i] / sa;
                    cb += b[i] / sb;
                    want += (ca - cb).abs();
                }
                let got = emd(&a, &b, &g).unwrap();
                assert!((got - want).abs() < 1e-9, "n {n}: {got} vs {want}");
            }
        }
    }

    #[test]
    fn random_problems_satisfy_the_optimality_conditions() {
        let mut rng = Rng::new(3);
        for trial in 0..300 {
            let n = 1 + (trial % 20);
            let g: Vec<f64> = (0..n * n).map(|_| (rng.f64() * 4.0).floor()).collect(); // ties
            let mut t = Transport::new(n, &g).unwrap();
            for _ in 0..5 {
                let a = unit(
                    "a",
                    &[random_hist(&mut rng, n, true), vec![0.5]].concat()[..n],
                    n,
                )
                .unwrap_or_else(|_| vec![1.0 / n as f64; n]);
                let b = unit("b", &random_hist(&mut rng, n, true), n)
                    .unwrap_or_else(|_| vec![1.0 / n as f64; n]);
                check_optimal(&mut t, &a, &b); // warm starts after the first
            }
        }
    }

    #[test]
    fn tiny_problems_match_the_brute_force() {
        let mut rng = Rng::new(4);
        for trial in 0..60 {
            let n = 2 + trial % 2;
            let g: Vec<f64> = (0..n * n).map(|_| (rng.f64() * 3.0).floor()).collect();
            let a = unit("a", &random_hist(&mut rng, n, trial % 3 == 0), n)
                .unwrap_or_else(|_| vec![1.0 / n as f64; n]);
            let b = unit("b", &random_hist(&mut rng, n, false), n).unwrap();
            let got = emd(&a, &b, &g).unwrap();
            let want = brute(&a, &b, &g);
            assert!((got - want).abs() < 1e-9, "{got} vs {want}");
        }
    }

    #[test]
    fn degenerate_histograms_are_exact() {
        // Point masses, disjoint supports and a one-bin histogram.
        let g = line_ground(4);
        assert!(
            (emd(&[1.0, 0.0, 0.0, 0.0], &[0.0, 0.0, 0.0, 3.0], &g).unwrap() - 3.0).abs() < 1e-12
        );
        assert!(
            (emd(&[1.0, 1.0, 0.0, 0.0], &[0.0, 0.0, 1.0, 1.0], &g).unwrap() - 2.0).abs() < 1e-12
        );
        assert!(emd(&[2.0], &[5.0], &[0.0]).unwrap().abs() < 1e-15);
        assert!(emd(&[0.0, 0.0], &[1.0, 1.0], &line_ground(2)).is_err());
        assert!(emd(&[1.0; 33], &[1.0; 33], &vec![0.0; 33 * 33]).is_err());
    }

    fn map_by_windows(input: &MapInput<'_>) -> Vec<f32> {
        let (h, w) = input.size;
        let n = input.n_bins;
        let scale = input.ground.iter().copied().fold(0.0, f64::max);
        let (b, a) = (input.window / 2, input.window - input.window / 2);
        let mut out = vec![f32::NAN; h * w];
        for y in 0..h {
            for x in 0..w {
                if input.labels[y * w + x] < 0 {
                    continue;
                }
                let mut hist = vec![0.0; n];
                for yy in y.saturating_sub(b)..(y + a).min(h) {
                    for xx in x.saturating_sub(b)..(x + a).min(w) {
                        let l = input.labels[yy * w + xx];
                        if l >= 0 {
                            hist[l as usize] += 1.0;
                        }
                    }
                }
                out[y * w + x] = (emd(&hist, input.target, input.ground).unwrap() / scale) as f32;
            }
        }
        out
    }

    #[test]
    fn the_sliding_map_equals_per_window_solves() {
        let mut rng = Rng::new(5);
        let (h, w, n) = (23, 31, 6);
        // Blobs of one label with noise, so identical consecutive windows occur.
        let labels: Vec<i32> = (0..h * w)
            .map(|p| {
                let (y, x) = (p / w, p % w);
                if rng.f64() < 0.1 {
                    -1
                } else if rng.f64() < 0.2 {
                    (rng.f64() * n as f64) as i32
                } else {
                    ((y / 7 + x / 9) % n) as i32
                }
            })
            .collect();
        let pts: Vec<[f64; 2]> = (0..n)
            .map(|_| [rng.f64() * 10.0, rng.f64() * 10.0])
            .collect();
        let ground: Vec<f64> = (0..n * n)
            .map(|c| {
                let (p, q) = (pts[c / n], pts[c % n]);
                (p[0] - q[0]).hypot(p[1] - q[1])
            })
            .collect();
        let target = random_hist(&mut rng, n, true);
        for window in [1, 2, 5, 8, 40] {
            let input = MapInput {
                labels: &labels,
                size: (h, w),
                n_bins: n,
                ground: &ground,
                target: &target,
                window,
            };
            let got = emd_map(&input).unwrap();
            let want = map_by_windows(&input);
            for (g, e) in got.iter().zip(&want) {
                assert!(
                    (g.is_nan() && e.is_nan()) || (g - e).abs() < 1e-6,
                    "window {window}: {g} vs {e}"
                );
                assert!(g.is_nan() || (-1e-6..=1.0 + 1e-6).contains(g));
            }
        }
    }

    #[test]
    fn bad_map_input_is_an_error() {
        let g = line_ground(2);
        let ok = MapInput {
            labels: &[0, 1, -1, 1],
            size: (2, 2),
            n_bins: 2,
            ground: &g,
            target: &[1.0, 1.0],
            window: 8,
        };
        assert!(emd_map(&ok).is_ok());
        assert!(emd_map(&MapInput { window: 0, ..ok }).is_err());
        assert!(emd_map(&MapInput {
            labels: &[0, 2, 0, 0],
            ..ok
        })
        .is_err());
        assert!(emd_map(&MapInput { labels: &[0], ..ok }).is_err());
        assert!(emd_map(&MapInput {
            target: &[0.0, 0.0],
            ..ok
        })
        .is_err());
    }
}
