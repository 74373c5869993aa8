//! Exact earth mover's distance between small histograms, and the sliding-window map of it
//! that layer induction needs (Assa & Cohen-Or, Eq. 1: the colour distance S(x, c) between
//! the histogram of each pixel's 8×8 neighbourhood and the histogram of the user's layer).
//!
//! The EMD between two histograms of equal (unit) mass is a transportation problem with
//! `n × n` cells. [`Transport`] solves it exactly by the transportation simplex on a spanning
//! tree basis: a least-cost starting basis, then primal (MODI) pivots, with Bland's rule once
//! a run of degenerate pivots suggests cycling. Zero bins and ties are ordinary degenerate
//! bases here: the tree always has `2n − 1` edges, some carrying no flow. The tree lives in
//! flat, fixed-size arrays (parent, parent edge, breadth-first order), so a solve allocates
//! nothing.
//!
//! The map reuses work three ways. Window histograms slide along a row (one column in, one
//! out). A window's histogram is an integer vector, so its value depends on nothing else: a
//! small exact cache (histogram → value) per block of rows answers repeats, which flat regions
//! of a leaf are full of. And since only the supplies change from one window to the next while
//! the costs stay, the previous optimal basis stays *dual* feasible: the next window starts
//! from it, recomputes the tree flows (O(n)) and, where some flow turned negative, restores
//! feasibility by dual simplex pivots (usually none or one). Blocks of rows are fixed (not
//! per thread) and each starts from the same basis, so the result does not depend on the
//! number of threads.

use rayon::prelude::*;

use crate::{cancel, error::invalid, Result};

/// The largest number of bins [`Transport`] accepts.
pub const MAX_BINS: usize = 32;

/// Nodes of the basis tree: rows `0..n`, columns `n..2n`.
const NODES: usize = 2 * MAX_BINS;

/// Flows and reduced costs this far below zero count as zero: the masses are sums of a few
/// dozen terms of order 1, so their rounding is far below this.
const EPS: f64 = 1e-12;

/// An exact transportation-simplex solver for `n`-bin histograms under a fixed ground
/// distance; it keeps its last optimal basis so the next solve can start from it.
#[derive(Clone, Debug)]
pub struct Transport {
    /// Rows (supplies) and columns (demands); the square solver of [`Transport::new`] has
    /// `n = m`, the map's has only the target's non-empty bins as columns.
    n: usize,
    m: usize,
    cost: Vec<f64>,
    /// Cells in order of increasing cost (ties by index), for the least-cost start.
    order: Vec<usize>,
    /// Basis cells `i * m + j`, always `n + m − 1` of them, and their flows.
    basis: Vec<usize>,
    flow: Vec<f64>,
    /// Whether `basis` is an optimal basis of some earlier solve (hence dual feasible).
    warm: bool,
    /// The basis tree rooted at row 0 (filled by [`Self::rebuild`]): each other node's
    /// parent and the basis edge to it, the breadth-first order, the depth, and the dual
    /// potentials (`u_i` at node `i`, `v_j` at node `n + j`, `u_0 = 0`).
    parent: [u8; NODES],
    up: [u8; NODES],
    bfs: [u8; NODES],
    depth: [u8; NODES],
    pot: [f64; NODES],
    /// The node below each basis edge (the one whose parent edge it is).
    below: [u8; NODES],
    /// Scratch of [`Self::flows`] (kept here so a call need not zero 512 bytes).
    rest: [f64; NODES],
}

impl Transport {
    /// A solver for `n` bins; `ground` is `n × n` row-major, finite and non-negative.
    pub fn new(n: usize, ground: &[f64]) -> Result<Self> {
        Self::rect(n, n, ground)
    }

    /// A solver for `n` supplies and `m` demands; `ground` is `n × m` row-major.
    fn rect(n: usize, m: usize, ground: &[f64]) -> Result<Self> {
        if n == 0 || n > MAX_BINS || m == 0 || m > MAX_BINS {
            return Err(invalid(
                "n_bins",
                format!("expected 1 to {MAX_BINS} bins, got {n}"),
            ));
        }
        if ground.len() != n * m {
            return Err(invalid(
                "ground",
                format!("expected {n}×{m} = {} values, got {}", n * m, ground.len()),
            ));
        }
        if ground.iter().any(|d| !d.is_finite() || *d < 0.0) {
            return Err(invalid("ground", "expected finite, non-negative distances"));
        }
        let mut order: Vec<usize> = (0..n * m).collect();
        order.sort_by(|&a, &b| ground[a].total_cmp(&ground[b]).then(a.cmp(&b)));
        Ok(Self {
            n,
            m,
            cost: ground.to_vec(),
            order,
            basis: Vec::with_capacity(n + m),
            flow: Vec::with_capacity(n + m),
            warm: false,
            parent: [0; NODES],
            up: [0; NODES],
            bfs: [0; NODES],
            depth: [0; NODES],
            pot: [0.0; NODES],
            below: [0; NODES],
            rest: [0.0; NODES],
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

    /// The optimal flow of the last solve as `(cell, flow)` pairs (`cell = i * m + j`).
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
        let (n, m) = (self.n, self.m);
        let mut ra = [0.0f64; MAX_BINS];
        let mut rb = [0.0f64; MAX_BINS];
        ra[..n].copy_from_slice(a);
        rb[..m].copy_from_slice(b);
        let mut row_open = [true; MAX_BINS];
        let mut col_open = [true; MAX_BINS];
        let (mut rows, mut cols) = (n, m);
        self.basis.clear();
        self.flow.clear();
        for &c in &self.order {
            let (i, j) = (c / m, c % m);
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
        debug_assert_eq!(self.basis.len(), n + m - 1);
    }

    /// Roots the basis tree at row 0: parents, parent edges, breadth-first order, depths
    /// and the dual potentials `u_i + v_j = cost_ij` on its edges. `false` if the basis
    /// does not span all `2n` nodes (only hand-made bases in tests can fail this).
    fn rebuild(&mut self) -> bool {
        let (n, m) = (self.n, self.m);
        // Compressed adjacency: node `p`'s neighbours are `adj[start[p]..start[p + 1]]`.
        let mut start = [0u8; NODES + 1];
        for &c in &self.basis {
            start[c / m + 1] += 1;
            start[n + c % m + 1] += 1;
        }
        for p in 0..n + m {
            start[p + 1] += start[p];
        }
        let mut fill = start;
        let mut adj = [(0u8, 0u8); 2 * NODES];
        for (k, &c) in self.basis.iter().enumerate() {
            let (i, j) = (c / m, n + c % m);
            adj[fill[i] as usize] = (j as u8, k as u8);
            fill[i] += 1;
            adj[fill[j] as usize] = (i as u8, k as u8);
            fill[j] += 1;
        }
        let mut seen = [false; NODES];
        seen[0] = true;
        self.bfs[0] = 0;
        self.depth[0] = 0;
        self.pot[0] = 0.0;
        let (mut head, mut tail) = (0usize, 1usize);
        while head < tail {
            let p = self.bfs[head] as usize;
            head += 1;
            for &(q, k) in &adj[start[p] as usize..start[p + 1] as usize] {
                let q = q as usize;
                if seen[q] {
                    continue;
                }
                seen[q] = true;
                self.parent[q] = p as u8;
                self.up[q] = k;
                self.below[k as usize] = q as u8;
                self.depth[q] = self.depth[p] + 1;
                self.pot[q] = self.cost[self.basis[k as usize]] - self.pot[p];
                self.bfs[tail] = q as u8;
                tail += 1;
            }
        }
        tail == n + m
    }

    /// The flows the current tree carries for supplies `a` and demands `b`: leaves first,
    /// each node's edge to its parent carries the net supply of the node's subtree.
    fn flows(&mut self, a: &[f64], b: &[f64]) {
        let (n, m) = (self.n, self.m);
        let rest = &mut self.rest;
        rest[..n].copy_from_slice(a);
        for (r, &d) in rest[n..n + m].iter_mut().zip(b) {
            *r = -d;
        }
        for t in (1..n + m).rev() {
            let q = self.bfs[t] as usize;
            let net = rest[q];
            // A row's subtree sends its surplus to the parent column; a column's subtree
            // receives its deficit from the parent row.
            self.flow[self.up[q] as usize] = if q < n { net } else { -net };
            rest[self.parent[q] as usize] += net;
        }
    }

    /// Dual simplex from the current (dual feasible, rebuilt) tree: while some flow is
    /// negative, take the most negative out and bring in the cheapest cell that crosses the
    /// cut in the direction that can carry it. `false` if it gave up (then the caller starts
    /// afresh).
    fn dual(&mut self, a: &[f64], b: &[f64]) -> bool {
        let (n, m) = (self.n, self.m);
        for _ in 0..(4 * (n + m)) {
            let mut k = usize::MAX;
            let mut worst = -EPS;
            for (e, &x) in self.flow.iter().enumerate() {
                if x < worst {
                    worst = x;
                    k = e;
                }
            }
            if k == usize::MAX {
                return true;
            }
            // The subtree below the leaving edge is one side of the cut.
            let mut below = [false; NODES];
            below[self.below[k] as usize] = true;
            for t in 1..n + m {
                let q = self.bfs[t] as usize;
                below[q] = below[q] || below[self.parent[q] as usize];
            }
            // The side holding the leaving cell's row lacks mass: it must receive along a
            // row outside → column inside.
            let row_side = below[self.basis[k] / m];
            let mut cols = [0u8; MAX_BINS];
            let mut inside = 0;
            for j in 0..m {
                if below[n + j] == row_side {
                    cols[inside] = j as u8;
                    inside += 1;
                }
            }
            let mut best = f64::INFINITY;
            let mut enter = usize::MAX;
            for i in (0..n).filter(|&i| below[i] != row_side) {
                let row = &self.cost[i * m..(i + 1) * m];
                let ui = self.pot[i];
                for &j in &cols[..inside] {
                    let j = j as usize;
                    let r = row[j] - ui - self.pot[n + j];
                    if r < best {
                        best = r;
                        enter = i * m + j;
                    }
                }
            }
            if enter == usize::MAX {
                return false;
            }
            self.pivot(k, enter, best, &below);
            self.flows(a, b);
        }
        false
    }

    /// Replaces basis edge `k` by cell `enter` (reduced cost `r`) without rebuilding the
    /// tree: the subtree `below` edge `k` is re-hung from the entering cell's endpoint inside
    /// it (the parent links along the path up to the subtree's old top reverse), its
    /// potentials shift by `±r`, and its nodes move to the end of the breadth-first order
    /// (so parents still come before children).
    fn pivot(&mut self, k: usize, enter: usize, r: f64, below: &[bool; NODES]) {
        let (n, m) = (self.n, self.m);
        let (i, j) = (enter / m, n + enter % m);
        let (inner, outer) = if below[i] { (i, j) } else { (j, i) };
        let top = self.below[k] as usize;
        self.basis[k] = enter;
        // Re-hang: walk from `inner` up to `top`, reversing parent links.
        let mut on_path = [false; NODES];
        let mut path = [0u8; NODES];
        let mut len = 0;
        let (mut x, mut to, mut edge) = (inner, outer, k as u8);
        let mut d = self.depth[outer] + 1;
        loop {
            let (old_parent, old_edge) = (self.parent[x] as usize, self.up[x]);
            self.parent[x] = to as u8;
            self.up[x] = edge;
            self.below[edge as usize] = x as u8;
            self.depth[x] = d;
            on_path[x] = true;
            path[len] = x as u8;
            len += 1;
            if x == top {
                break;
            }
            (to, edge, x, d) = (x, old_edge, old_parent, d + 1);
        }
        // The inner row's potential rises by r (its column's, if the column is inside).
        let shift_rows = if inner < n { r } else { -r };
        // The new order: the rest as it was, then the path from `inner` to `top` (each node's
        // new parent is the one before it), then the subtree's other nodes in their old order
        // (their parents did not change and come earlier).
        let mut others = [0u8; NODES];
        let (mut kept, mut count) = (0, 0);
        for t in 0..n + m {
            let q = self.bfs[t] as usize;
            if below[q] {
                self.pot[q] += if q < n { shift_rows } else { -shift_rows };
                if !on_path[q] {
                    self.depth[q] = self.depth[self.parent[q] as usize] + 1;
                    others[count] = q as u8;
                    count += 1;
                }
            } else {
                self.bfs[kept] = q as u8;
                kept += 1;
            }
        }
        self.bfs[kept..kept + len].copy_from_slice(&path[..len]);
        self.bfs[kept + len..kept + len + count].copy_from_slice(&others[..count]);
    }

    /// Primal (MODI) pivots to optimality from a feasible tree.
    fn primal(&mut self) -> Result<()> {
        let (n, m) = (self.n, self.m);
        let mut degenerate = 0usize;
        let limit = 64 * n * m;
        for _ in 0..limit {
            self.rebuild();
            let bland = degenerate > n + m;
            let mut basic = [false; MAX_BINS * MAX_BINS];
            for &c in &self.basis {
                basic[c] = true;
            }
            let mut enter: Option<(f64, usize)> = None;
            for c in (0..n * m).filter(|&c| !basic[c]) {
                let r = self.cost[c] - self.pot[c / m] - self.pot[n + c % m];
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
            // The tree path from the entering cell's column to its row (up to their common
            // ancestor from both ends); its cells alternate −, +, −, … around the cycle the
            // entering cell closes.
            let (mut x, mut y) = (n + c % m, c / m);
            let mut from_col = [0u8; NODES];
            let mut from_row = [0u8; NODES];
            let (mut nc, mut nr) = (0, 0);
            while x != y {
                if self.depth[x] >= self.depth[y] {
                    from_col[nc] = self.up[x];
                    nc += 1;
                    x = self.parent[x] as usize;
                } else {
                    from_row[nr] = self.up[y];
                    nr += 1;
                    y = self.parent[y] as usize;
                }
            }
            let path = from_col[..nc]
                .iter()
                .chain(from_row[..nr].iter().rev())
                .map(|&e| e as usize);
            let mut leave: Option<(f64, usize)> = None;
            for e in path.clone().step_by(2) {
                let f = self.flow[e].max(0.0);
                let better = match leave {
                    None => true,
                    // Exact ties go to the smaller cell (Bland's rule).
                    Some((bf, be)) => f
                        .total_cmp(&bf)
                        .then(self.basis[e].cmp(&self.basis[be]))
                        .is_lt(),
                };
                if better {
                    leave = Some((f, e));
                }
            }
            let Some((theta, out)) = leave else {
                return Err(crate::Error::Internal(
                    "emd: a cycle without a − cell".into(),
                ));
            };
            degenerate = if theta <= EPS { degenerate + 1 } else { 0 };
            for (pos, e) in path.enumerate() {
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

/// Colours per parallel task of [`nearest`].
const NEAREST_CHUNK: usize = 1 << 14;

/// The index of each colour's nearest palette colour, the first on a tie: for `points` (`N × 3`,
/// row-major) and `centres` (`k × 3`) with `norms[c] = |centres[c]|²`, the smallest of
/// `norms[c] − 2 ⟨p, centres[c]⟩` (|p|² is the same for every centre, so it is left out). In
/// float32 with the operations in the order NumPy evaluates
/// `cc[k] - 2.0 * (x * c[k, 0] + y * c[k, 1] + z * c[k, 2])`, so the labels equal that
/// expression's bit for bit.
pub fn nearest(points: &[f32], centres: &[f32], norms: &[f32]) -> Result<Vec<i32>> {
    if points.len() % 3 != 0 {
        return Err(invalid("points", "expected N × 3 values"));
    }
    let k = centres.len() / 3;
    if centres.len() % 3 != 0 || k == 0 || k > MAX_BINS {
        return Err(invalid(
            "centres",
            format!("expected 1 to {MAX_BINS} colours of 3 values"),
        ));
    }
    if norms.len() != k {
        return Err(invalid(
            "norms",
            format!("expected {k} values, got {}", norms.len()),
        ));
    }
    let mut out = vec![0i32; points.len() / 3];
    out.par_chunks_mut(NEAREST_CHUNK)
        .zip(points.par_chunks(3 * NEAREST_CHUNK))
        .for_each(|(labels, pts)| {
            for (l, p) in labels.iter_mut().zip(pts.chunks_exact(3)) {
                let mut best = f32::INFINITY;
                for (c, (q, &cc)) in centres.chunks_exact(3).zip(norms).enumerate() {
                    let d = cc - 2.0 * (p[0] * q[0] + p[1] * q[1] + p[2] * q[2]);
                    if d < best {
                        best = d;
                        *l = c as i32;
                    }
                }
            }
        });
    cancel::check()?;
    Ok(out)
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

/// Rows per block of the map: each block runs sequentially (warm starts and the cache carry
/// along it), blocks in parallel. Fixed, so the result does not depend on the thread count.
const BLOCK_ROWS: usize = 16;

/// Slots of the per-block histogram cache (a power of two).
const CACHE_BITS: u32 = 15;

/// An exact cache from window histograms (integer counts) to their value: open addressing
/// on a linear hash `Σ count_b · R_b` that the sliding window updates in O(1) per pixel.
/// It is filled to at most half, then only looked up.
///
/// Where windows hardly repeat (a textured or noisy leaf: ~all distinct) a lookup is a cache
/// miss in a 2 MB table for nothing, so a row whose hit rate is low makes the next row only
/// sample (every [`SAMPLE`]-th window); a sampled row with hits turns it back on. The choice
/// depends only on the block's own rows, and the values are exact either way.
struct Cache {
    n: usize,
    keys: Vec<u32>,
    hashes: Vec<u64>,
    values: Vec<f32>,
    used: Vec<bool>,
    filled: usize,
    lookups: u32,
    hits: u32,
    sampling: bool,
}

/// While sampling, the cache sees every `SAMPLE`-th window of a row.
const SAMPLE: usize = 8;

impl Cache {
    fn new(n: usize) -> Self {
        let slots = 1usize << CACHE_BITS;
        Self {
            n,
            keys: vec![0; slots * n],
            hashes: vec![0; slots],
            values: vec![0.0; slots],
            used: vec![false; slots],
            filled: 0,
            lookups: 0,
            hits: 0,
            sampling: false,
        }
    }

    fn clear(&mut self) {
        self.used.fill(false);
        self.filled = 0;
        self.lookups = 0;
        self.hits = 0;
        self.sampling = false;
    }

    /// Whether the window at column `x` goes through the cache.
    fn sees(&self, x: usize) -> bool {
        !self.sampling || x % SAMPLE == 0
    }

    /// Ends a row: the next one samples unless at least one lookup in eight hit.
    fn end_row(&mut self) {
        self.sampling = 8 * self.hits < self.lookups;
        self.lookups = 0;
        self.hits = 0;
    }

    /// The slot holding `counts`, or the empty slot where it would go.
    fn slot(&self, hash: u64, counts: &[u32]) -> usize {
        let mask = (1usize << CACHE_BITS) - 1;
        let mut s = (hash >> (64 - CACHE_BITS)) as usize;
        while self.used[s]
            && (self.hashes[s] != hash || self.keys[s * self.n..(s + 1) * self.n] != *counts)
        {
            s = (s + 1) & mask;
        }
        s
    }

    fn get(&mut self, hash: u64, counts: &[u32]) -> Option<f32> {
        let s = self.slot(hash, counts);
        self.lookups += 1;
        self.hits += u32::from(self.used[s]);
        self.used[s].then(|| self.values[s])
    }

    fn put(&mut self, hash: u64, counts: &[u32], value: f32) {
        if 2 * self.filled >= self.used.len() {
            return;
        }
        let s = self.slot(hash, counts);
        if !self.used[s] {
            self.used[s] = true;
            self.hashes[s] = hash;
            self.keys[s * self.n..(s + 1) * self.n].copy_from_slice(counts);
            self.values[s] = value;
            self.filled += 1;
        }
    }
}

/// The hash multiplier of bin `b` (splitmix64 of `b`), odd so no bin is lost.
fn multiplier(b: usize) -> u64 {
    let mut z = (b as u64)
        .wrapping_add(1)
        .wrapping_mul(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    (z ^ (z >> 31)) | 1
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
    // Bins the target lacks receive nothing in any plan, so their columns are dropped: an
    // `n × k` problem with the same optimum, smaller the more concentrated the layer is.
    drop(base);
    let cols: Vec<usize> = (0..n).filter(|&j| target[j] > 0.0).collect();
    let demand: Vec<f64> = cols.iter().map(|&j| target[j]).collect();
    let ground: Vec<f64> = (0..n)
        .flat_map(|i| cols.iter().map(move |&j| input.ground[i * n + j]))
        .collect();
    // One optimal basis (any supplies) is dual feasible for all: every block starts from it.
    let mut base = Transport::rect(n, cols.len(), &ground)?;
    base.solve(&target, &demand)?;
    let mut mult = [0u64; MAX_BINS];
    for (b, m) in mult.iter_mut().enumerate() {
        *m = multiplier(b);
    }
    let mut out = vec![f32::NAN; h * w];
    if w == 0 {
        return Ok(out);
    }
    out.par_chunks_mut(BLOCK_ROWS * w)
        .enumerate()
        .try_for_each_init(
            || Cache::new(n),
            |cache, (block, rows)| -> Result<()> {
                if cancel::cancelled() {
                    return Ok(());
                }
                cache.clear();
                let mut start = base.clone();
                for (r, row) in rows.chunks_mut(w).enumerate() {
                    let y = block * BLOCK_ROWS + r;
                    start = map_row(input, &demand, scale, &mult, cache, start, y, row)?;
                }
                Ok(())
            },
        )?;
    cancel::check()?;
    Ok(out)
}

/// One row of [`emd_map`], warm-started from `start`; returns the solver as it was after the
/// row's first solve, the start of the next row (whose first window is nearly the same).
#[allow(clippy::too_many_arguments)]
fn map_row(
    input: &MapInput<'_>,
    target: &[f64],
    scale: f64,
    mult: &[u64; MAX_BINS],
    cache: &mut Cache,
    start: Transport,
    y: usize,
    row: &mut [f32],
) -> Result<Transport> {
    let (h, w) = input.size;
    let n = input.n_bins;
    let before = input.window / 2;
    let after = input.window - before; // exclusive
    let y0 = y.saturating_sub(before);
    let y1 = (y + after).min(h);
    let mut solver = start.clone();
    let mut next: Option<Transport> = None;
    let mut counts = [0u32; MAX_BINS];
    let mut total = 0u32;
    let mut hash = 0u64;
    let mut supply = [0.0f64; MAX_BINS];
    let mut last: Option<(u64, [u32; MAX_BINS], f32)> = None;
    let column =
        |x: usize, counts: &mut [u32; MAX_BINS], total: &mut u32, hash: &mut u64, add: bool| {
            for yy in y0..y1 {
                let l = input.labels[yy * w + x];
                if l >= 0 {
                    let l = l as usize;
                    if add {
                        counts[l] += 1;
                        *total += 1;
                        *hash = hash.wrapping_add(mult[l]);
                    } else {
                        counts[l] -= 1;
                        *total -= 1;
                        *hash = hash.wrapping_sub(mult[l]);
                    }
                }
            }
        };
    // Columns [x − before, x + after) are in the window of pixel x.
    for x in 0..after.saturating_sub(1).min(w) {
        column(x, &mut counts, &mut total, &mut hash, true);
    }
    // `x` also indexes the labels and the columns entering and leaving.
    #[allow(clippy::needless_range_loop)]
    for x in 0..w {
        if x + after - 1 < w {
            column(x + after - 1, &mut counts, &mut total, &mut hash, true);
        }
        if x > before {
            column(x - before - 1, &mut counts, &mut total, &mut hash, false);
        }
        if input.labels[y * w + x] < 0 {
            continue;
        }
        let key = &counts[..n];
        if let Some((lh, c, s)) = &last {
            if *lh == hash && c[..n] == *key {
                row[x] = *s;
                continue;
            }
        }
        let sees = cache.sees(x);
        let s = if let Some(s) = sees.then(|| cache.get(hash, key)).flatten() {
            s
        } else {
            let t = f64::from(total);
            for (s, &c) in supply.iter_mut().zip(key) {
                // 0 / t is 0: only the window's colours need a division.
                *s = if c == 0 { 0.0 } else { f64::from(c) / t };
            }
            let d = solver.solve(&supply[..n], target)?;
            if next.is_none() {
                next = Some(solver.clone());
            }
            let s = if scale > 0.0 { (d / scale) as f32 } else { 0.0 };
            if sees {
                cache.put(hash, key, s);
            }
            s
        };
        row[x] = s;
        last = Some((hash, counts, s));
    }
    cache.end_row();
    Ok(next.unwrap_or(start))
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
        // Potentials of a freshly rooted tree, not the solver's incrementally kept ones.
        let mut t = t.clone();
        t.rebuild();
        for c in 0..n * n {
            let r = t.cost[c] - t.pot[c / n] - t.pot[n + c % n];
            assert!(r >= -1e-9, "dual infeasible at {c}: {r}");
        }
        for &(c, x) in &plan {
            let r = t.cost[c] - t.pot[c / n] - t.pot[n + c % n];
            assert!(x.abs() < 1e-12 || r.abs() < 1e-9);
        }
        let dual: f64 = (0..n).map(|i| t.pot[i] * a[i] + t.pot[n + i] * b[i]).sum();
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
            // A spanning tree: connected with 2n − 1 edges.
            if !t.rebuild() {
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
                let mut fresh = t.clone();
                fresh.rebuild();
                assert_eq!(t.parent[..2 * n], fresh.parent[..2 * n]);
                assert_eq!(t.up[..2 * n], fresh.up[..2 * n]);
                assert_eq!(t.depth[..2 * n], fresh.depth[..2 * n]);
                for q in 0..2 * n {
                    assert!((t.pot[q] - fresh.pot[q]).abs() < 1e-9);
                }
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
    fn the_cache_tells_histograms_with_one_hash_apart() {
        let mut cache = Cache::new(3);
        cache.put(7, &[1, 2, 3], 0.25);
        cache.put(7, &[3, 2, 1], 0.5); // the same hash: a collision
        assert_eq!(cache.get(7, &[1, 2, 3]), Some(0.25));
        assert_eq!(cache.get(7, &[3, 2, 1]), Some(0.5));
        assert_eq!(cache.get(7, &[2, 2, 2]), None);
        assert_eq!(cache.get(8, &[1, 2, 3]), None);
        // The sliding hash is a function of the histogram alone.
        let h = |c: &[u32]| {
            c.iter().enumerate().fold(0u64, |s, (b, &k)| {
                s.wrapping_add(multiplier(b).wrapping_mul(k.into()))
            })
        };
        assert_ne!(h(&[1, 2, 3]), h(&[3, 2, 1]));
        cache.clear();
        assert_eq!(cache.get(7, &[1, 2, 3]), None);
    }

    #[test]
    fn a_row_of_misses_makes_the_next_row_sample_and_a_hit_turns_it_back() {
        let mut cache = Cache::new(2);
        assert!((0..16).all(|x| cache.sees(x)));
        for x in 0..16 {
            assert_eq!(cache.get(x, &[x as u32, 1]), None);
            cache.put(x, &[x as u32, 1], 0.5);
        }
        cache.end_row(); // 16 misses
        assert!(cache.sees(0) && cache.sees(SAMPLE) && !cache.sees(1) && !cache.sees(SAMPLE - 1));
        assert_eq!(cache.get(3, &[3, 1]), Some(0.5));
        cache.end_row(); // 1 hit in 1 lookup
        assert!((0..16).all(|x| cache.sees(x)));
        for misses in [7, 8] {
            for x in 0..misses {
                cache.get(100 + x, &[0, 0]);
            }
            cache.get(3, &[3, 1]);
            cache.end_row();
            // One hit in eight lookups keeps it on; one in nine is too few.
            assert_eq!(cache.sees(1), misses == 7);
        }
        cache.clear();
        assert!(cache.sees(1));
    }

    #[test]
    fn nearest_takes_the_closest_centre_and_the_first_on_a_tie() {
        let mut rng = Rng::new(6);
        let mut centres: Vec<f32> = (0..30).map(|_| (rng.f64() * 100.0 - 50.0) as f32).collect();
        // Centres 10 and 11 repeat 2 and 7: a tie every time one of those is nearest.
        centres.extend_from_within(6..9);
        centres.extend_from_within(21..24);
        let norms: Vec<f32> = centres
            .chunks_exact(3)
            .map(|c| c[0] * c[0] + c[1] * c[1] + c[2] * c[2])
            .collect();
        let mut points: Vec<f32> = (0..3 * 5000)
            .map(|_| (rng.f64() * 120.0 - 60.0) as f32)
            .collect();
        points.extend_from_slice(&centres[6..9]); // exactly on a repeated centre
        let labels = nearest(&points, &centres, &norms).unwrap();
        let d2 = |p: &[f32], c: usize| -> f64 {
            (0..3)
                .map(|d| (f64::from(p[d]) - f64::from(centres[3 * c + d])).powi(2))
                .sum()
        };
        for (p, &l) in points.chunks_exact(3).zip(&labels) {
            let l = l as usize;
            assert!(l != 10 && l != 11, "a repeated centre took {l}");
            let best = (0..12).map(|c| d2(p, c)).fold(f64::INFINITY, f64::min);
            // Up to float32 rounding of |c|² − 2⟨p, c⟩ (terms of order 10⁴).
            assert!(d2(p, l) <= best + 1e-2, "{} vs {best}", d2(p, l));
        }
        assert_eq!(*labels.last().unwrap(), 2);
        assert!(nearest(&points[..4], &centres, &norms).is_err());
        assert!(nearest(&points, &centres[..2], &norms).is_err());
        assert!(nearest(&points, &centres, &norms[..3]).is_err());
        assert!(nearest(&points, &[], &[]).is_err());
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
