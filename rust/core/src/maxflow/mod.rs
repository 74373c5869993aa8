//! Exact s-t max-flow / min-cut on 4- and 8-connected grid graphs.
//!
//! Planar problems (4-connectivity, terminal edges only on the border, in a source arc and a
//! sink arc) are solved as a shortest path in the dual graph ([`Method::Planar`], in the
//! private `planar` module). Every other problem goes to Boykov–Kolmogorov
//! ([`Method::BoykovKolmogorov`]):
//!
//! The algorithm is Boykov & Kolmogorov's (*An experimental comparison of min-cut/max-flow
//! algorithms for energy minimization in vision*, PAMI 2004), as in their `maxflow` v3
//! library: two search trees grown from the terminals, augmentation along the paths where
//! they meet, and adoption of orphans with the timestamp/distance heuristics. It is
//! specialised to grids: the graph is padded by one ring of nodes with zero capacity, so a
//! neighbour is an implicit offset and the hot loops have no adjacency lists and no bounds
//! tests.
//!
//! Capacities are `f32`, as in the `GraphFloat` variant of the C++ library; the flow value is
//! accumulated in `f64`. A terminal capacity of `+∞` is a hard constraint. Both methods are
//! deterministic (Boykov–Kolmogorov's split start depends only on the grid's shape); the seam
//! code builds its capacities in parallel.

use std::collections::VecDeque;

use crate::error::{invalid, Result};

mod planar;

/// Row and column steps of the directions, in the order E, S, W, N, SE, SW, NW, NE; the
/// opposite of direction `d` is `d ^ 2`.
pub const DIRS: [(isize, isize); 8] = [
    (0, 1),
    (1, 0),
    (0, -1),
    (-1, 0),
    (1, 1),
    (1, -1),
    (-1, -1),
    (-1, 1),
];

/// The directions of the symmetric edge layout: E and S for 4-connectivity, then SE and SW.
pub const SYMMETRIC_DIRS: [usize; 4] = [0, 1, 4, 5];

/// Grids of at least this many pixels are split in two for [`GridGraph::maxflow`] ...
const SPLIT_MIN_PIXELS: usize = 1 << 13;
/// ... as long as each half keeps at least this many rows (or columns).
const SPLIT_MIN_SIDE: usize = 32;
/// ... at most this many times over (four parts: enough for the few cores phloem targets).
const SPLIT_DEPTH: usize = 2;

/// Most nodes of a [`GridGraph`] (about 16k × 16k; some 10 GB of graph).
pub const MAX_NODES: usize = 1 << 28;

const FREE: u8 = 255;
const TERMINAL: u8 = 254;
const ORPHAN: u8 = 253;

#[inline]
const fn opp(d: usize) -> usize {
    d ^ 2
}

/// How edge capacities are given to [`GridGraph::set_edges`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EdgeLayout {
    /// `k/2` values per pixel (E, S[, SE, SW]): one capacity for both directions of an edge.
    Symmetric,
    /// `k` values per pixel (E, S, W, N[, SE, SW, NW, NE]): the capacity from the pixel to
    /// that neighbour.
    Directed,
}

/// The algorithm behind a [`GridGraph`]'s minimum cut.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// A shortest path in the planar dual graph (Schmidt, Töppe & Cremers 2009). Applies to
    /// 4-connected grids whose terminal edges all attach to border pixels, the source-tied
    /// ones in one arc of the border and the sink-tied ones in another.
    Planar,
    /// Boykov–Kolmogorov augmenting paths: any grid.
    BoykovKolmogorov,
}

/// A grid graph with residual capacities, ready for [`GridGraph::maxflow`].
#[derive(Clone, Debug)]
pub struct GridGraph {
    h: usize,
    w: usize,
    pw: usize,
    k: usize,
    /// Residual capacity from node `i` in direction `d` at `i * k + d` (padded indexing).
    cap: Vec<f32>,
    /// Residual terminal capacity: `> 0` from the source, `< 0` to the sink.
    tr: Vec<f32>,
    /// Flow already pushed straight from source to sink through single nodes.
    base_flow: f64,
    sink_side: Vec<bool>,
    solved: bool,
    method: Option<Method>,
}

impl GridGraph {
    /// An `h × w` grid with `connectivity` 4 or 8 and all capacities zero.
    pub fn new(h: usize, w: usize, connectivity: usize) -> Result<Self> {
        if connectivity != 4 && connectivity != 8 {
            return Err(invalid(
                "connectivity",
                format!("expected 4 or 8, got {connectivity}"),
            ));
        }
        if h == 0 || w == 0 {
            return Err(invalid(
                "shape",
                format!("expected a non-empty grid, got {h}×{w}"),
            ));
        }
        let (ph, pw) = (h + 2, w + 2);
        let n = ph
            .checked_mul(pw)
            .filter(|&n| n <= MAX_NODES)
            .ok_or_else(|| {
                invalid(
                    "shape",
                    format!("{h}×{w} is too large for a grid graph (at most {MAX_NODES} nodes)"),
                )
            })?;
        Ok(Self {
            h,
            w,
            pw,
            k: connectivity,
            cap: vec![0.0; n * connectivity],
            tr: vec![0.0; n],
            base_flow: 0.0,
            sink_side: Vec::new(),
            solved: false,
            method: None,
        })
    }

    #[inline]
    fn node(&self, y: usize, x: usize) -> usize {
        (y + 1) * self.pw + x + 1
    }

    fn offset(&self, d: usize) -> isize {
        DIRS[d].0 * self.pw as isize + DIRS[d].1
    }

    fn inside(&self, y: usize, x: usize, d: usize) -> bool {
        let (ny, nx) = (y as isize + DIRS[d].0, x as isize + DIRS[d].1);
        ny >= 0 && nx >= 0 && (ny as usize) < self.h && (nx as usize) < self.w
    }

    /// Sets every edge capacity from an `h × w × m` row-major array (`m = k/2` for
    /// [`EdgeLayout::Symmetric`], `k` for [`EdgeLayout::Directed`]). Capacities of edges that
    /// leave the grid are ignored. `name` is the argument named in errors.
    pub fn set_edges(
        &mut self,
        name: &'static str,
        edges: &[f32],
        layout: EdgeLayout,
    ) -> Result<()> {
        let m = match layout {
            EdgeLayout::Symmetric => self.k / 2,
            EdgeLayout::Directed => self.k,
        };
        if edges.len() != self.h * self.w * m {
            return Err(invalid(
                name,
                format!(
                    "expected {}×{}×{m} capacities, got {} values",
                    self.h,
                    self.w,
                    edges.len()
                ),
            ));
        }
        if let Some(i) = edges.iter().position(|v| !v.is_finite() || *v < 0.0) {
            return Err(invalid(
                name,
                format!(
                    "capacities must be finite and non-negative; entry {} (pixel ({}, {}), direction {}) is {}",
                    i,
                    i / m / self.w,
                    i / m % self.w,
                    i % m,
                    edges[i]
                ),
            ));
        }
        self.cap.fill(0.0);
        let k = self.k;
        for y in 0..self.h {
            for x in 0..self.w {
                let p = self.node(y, x);
                for (s, &v) in edges[(y * self.w + x) * m..][..m].iter().enumerate() {
                    let d = match layout {
                        EdgeLayout::Symmetric => SYMMETRIC_DIRS[s],
                        EdgeLayout::Directed => s,
                    };
                    if !self.inside(y, x, d) {
                        continue;
                    }
                    self.cap[p * k + d] = v;
                    if layout == EdgeLayout::Symmetric {
                        let q = p.wrapping_add_signed(self.offset(d));
                        self.cap[q * k + opp(d)] = v;
                    }
                }
            }
        }
        self.solved = false;
        Ok(())
    }

    /// Sets the terminal capacities from two `h × w` arrays: `source[i]` from the source to
    /// pixel `i`, `sink[i]` from pixel `i` to the sink. `+∞` is a hard constraint; a pixel
    /// may not be hard-tied to both terminals.
    pub fn set_terminals(&mut self, source: &[f32], sink: &[f32]) -> Result<()> {
        for (name, a) in [("source", source), ("sink", sink)] {
            if a.len() != self.h * self.w {
                return Err(invalid(
                    name,
                    format!(
                        "expected {}×{} capacities, got {} values",
                        self.h,
                        self.w,
                        a.len()
                    ),
                ));
            }
            if let Some(i) = a.iter().position(|v| v.is_nan() || *v < 0.0) {
                return Err(invalid(
                    name,
                    format!(
                        "capacities must be non-negative (+inf for a hard constraint); pixel ({}, {}) is {}",
                        i / self.w,
                        i % self.w,
                        a[i]
                    ),
                ));
            }
        }
        self.tr.fill(0.0);
        self.base_flow = 0.0;
        for y in 0..self.h {
            for x in 0..self.w {
                let i = y * self.w + x;
                let (s, t) = (source[i], sink[i]);
                if s.is_infinite() && t.is_infinite() {
                    return Err(invalid(
                        "sink",
                        format!("pixel ({y}, {x}) has infinite capacity to both terminals"),
                    ));
                }
                self.set_terminal(y, x, s, t);
            }
        }
        Ok(())
    }

    /// Adds `s` to the source capacity and `t` to the sink capacity of pixel `(y, x)`.
    #[inline]
    pub fn set_terminal(&mut self, y: usize, x: usize, s: f32, t: f32) {
        let p = self.node(y, x);
        let (s, t) = (s + self.tr[p].max(0.0), t + (-self.tr[p]).max(0.0));
        // Push min(s, t) straight through the node; keep the difference as residual.
        let m = s.min(t);
        self.base_flow += f64::from(m);
        self.tr[p] = if s.is_infinite() {
            f32::INFINITY
        } else if t.is_infinite() {
            f32::NEG_INFINITY
        } else {
            s - t
        };
        self.solved = false;
    }

    /// Computes the maximum flow, leaving the minimum cut for [`GridGraph::sink_side`].
    ///
    /// When the graph is planar with its terminals on the border (see [`Method::Planar`]:
    /// the case of a seam across a strip tied to one image on one side and to the other on
    /// the opposite side), the cut is a shortest path in the dual graph; otherwise it is
    /// [`Method::BoykovKolmogorov`]'s. Both are exact; [`GridGraph::method`] tells which ran.
    ///
    /// Once the thread's work is cancelled ([`crate::cancel`]) the search stops within a few
    /// thousand steps and leaves no cut ([`GridGraph::sink_side`] is `None`); callers check
    /// [`crate::cancel::check`] after it. Plain Rust callers are never cancelled.
    pub fn maxflow(&mut self) -> f64 {
        if let Some(arcs) = self.planar_arcs() {
            if let Some(flow) = self.planar_solve(&arcs) {
                self.method = Some(Method::Planar);
                return flow;
            }
        }
        self.method = Some(Method::BoykovKolmogorov);
        self.maxflow_split(SPLIT_DEPTH)
    }

    /// [`GridGraph::maxflow`] with a chosen method; [`Method::Planar`] is an error (naming
    /// `method`) where it does not apply.
    pub fn maxflow_with(&mut self, method: Method) -> Result<f64> {
        match method {
            Method::Planar => {
                let arcs = self.planar_arcs().ok_or_else(|| {
                    invalid(
                        "method",
                        "the planar method needs 4-connectivity and terminal edges only on the \
                         border, the source-tied pixels in one arc and the sink-tied ones in another",
                    )
                })?;
                let flow = self.planar_solve(&arcs);
                crate::cancel::check()?;
                let flow =
                    flow.ok_or_else(|| crate::Error::Internal("planar cut check failed".into()))?;
                self.method = Some(Method::Planar);
                Ok(flow)
            }
            Method::BoykovKolmogorov => {
                self.method = Some(Method::BoykovKolmogorov);
                let flow = self.maxflow_split(SPLIT_DEPTH);
                crate::cancel::check()?;
                Ok(flow)
            }
        }
    }

    /// After [`GridGraph::maxflow`]: the method that found the cut.
    #[must_use]
    pub fn method(&self) -> Option<Method> {
        self.method.filter(|_| self.solved)
    }

    /// Boykov–Kolmogorov. Large grids are cut in two along their longer side, the halves
    /// solved independently (in parallel) without the edges between them, their flows kept, and the search run
    /// once more on the whole residual graph (Liu & Sun 2010, *Parallel graph-cuts by
    /// adaptive bottom-up merging*). A flow of the halves is a flow of the whole, so the
    /// result is the exact maximum flow; the split depends only on the grid's shape, so the
    /// result does not depend on the number of threads.
    fn maxflow_split(&mut self, depth: usize) -> f64 {
        let long = self.h.max(self.w);
        if depth > 0 && self.h * self.w >= SPLIT_MIN_PIXELS && long >= 2 * SPLIT_MIN_SIDE {
            let mid = long / 2;
            let (ra, rb) = if self.h >= self.w {
                ((0, mid, 0, self.w), (mid, self.h, 0, self.w))
            } else {
                ((0, self.h, 0, mid), (0, self.h, mid, self.w))
            };
            let (mut a, mut b) = (self.extract(ra), self.extract(rb));
            rayon::join(|| a.maxflow_split(depth - 1), || b.maxflow_split(depth - 1));
            self.insert(&a, ra);
            self.insert(&b, rb);
            self.base_flow += a.base_flow + b.base_flow;
        }
        self.solve()
    }

    /// The sub-grid `rows y0..y1 × cols x0..x1` with its own edges and terminal residuals,
    /// without the edges that leave it.
    fn extract(&self, (y0, y1, x0, x1): (usize, usize, usize, usize)) -> Self {
        let (h, w, k) = (y1 - y0, x1 - x0, self.k);
        let pw = w + 2;
        let mut g = Self {
            h,
            w,
            pw,
            k,
            cap: vec![0.0; (h + 2) * pw * k],
            tr: vec![0.0; (h + 2) * pw],
            base_flow: 0.0,
            sink_side: Vec::new(),
            solved: false,
            method: None,
        };
        for y in 0..h {
            for x in 0..w {
                let (p, q) = (self.node(y0 + y, x0 + x), g.node(y, x));
                g.tr[q] = self.tr[p];
                for d in 0..k {
                    if g.inside(y, x, d) {
                        g.cap[q * k + d] = self.cap[p * k + d];
                    }
                }
            }
        }
        g
    }

    /// Writes the residuals of a solved [`GridGraph::extract`] back.
    fn insert(&mut self, g: &Self, (y0, _, x0, _): (usize, usize, usize, usize)) {
        let k = self.k;
        for y in 0..g.h {
            for x in 0..g.w {
                let (p, q) = (self.node(y0 + y, x0 + x), g.node(y, x));
                self.tr[p] = g.tr[q];
                for d in 0..k {
                    if g.inside(y, x, d) {
                        self.cap[p * k + d] = g.cap[q * k + d];
                    }
                }
            }
        }
    }

    fn solve(&mut self) -> f64 {
        let n = self.tr.len();
        let mut offs = [0isize; 8];
        for (d, o) in offs.iter_mut().enumerate().take(self.k) {
            *o = self.offset(d);
        }
        let mut s = Solver {
            k: self.k,
            offs,
            cap: &mut self.cap,
            tr: &mut self.tr,
            parent: vec![FREE; n],
            is_sink: vec![false; n],
            ts: vec![0; n],
            dist: vec![0; n],
            queued: vec![false; n],
            active: VecDeque::new(),
            orphans: VecDeque::new(),
            time: 0,
            flow: self.base_flow,
        };
        if s.run() {
            // Cancelled: no cut; the residual capacities hold a partial flow.
            self.solved = false;
            return f64::NAN;
        }
        let flow = s.flow;
        let (parent, is_sink) = (s.parent, s.is_sink);
        self.sink_side = (0..self.h)
            .flat_map(|y| (0..self.w).map(move |x| (y, x)))
            .map(|(y, x)| {
                let p = (y + 1) * self.pw + x + 1;
                parent[p] != FREE && is_sink[p]
            })
            .collect();
        self.base_flow = flow;
        self.solved = true;
        flow
    }

    /// After [`GridGraph::maxflow`]: `true` for the pixels on the sink side of a minimum cut
    /// (nodes reachable from neither tree go to the source side, as in the C++ library).
    #[must_use]
    pub fn sink_side(&self) -> Option<&[bool]> {
        self.solved.then_some(self.sink_side.as_slice())
    }
}

struct Solver<'g> {
    k: usize,
    offs: [isize; 8],
    cap: &'g mut [f32],
    tr: &'g mut [f32],
    parent: Vec<u8>,
    is_sink: Vec<bool>,
    ts: Vec<u32>,
    dist: Vec<u32>,
    queued: Vec<bool>,
    active: VecDeque<u32>,
    orphans: VecDeque<u32>,
    time: u32,
    flow: f64,
}

impl Solver<'_> {
    #[inline]
    fn nb(&self, i: usize, d: usize) -> usize {
        i.wrapping_add_signed(self.offs[d])
    }

    #[inline]
    fn activate(&mut self, i: usize) {
        if !self.queued[i] {
            self.queued[i] = true;
            self.active.push_back(i as u32);
        }
    }

    fn next_active(&mut self) -> Option<usize> {
        while let Some(i) = self.active.pop_front() {
            let i = i as usize;
            self.queued[i] = false;
            if self.parent[i] != FREE {
                return Some(i);
            }
        }
        None
    }

    /// Returns `true` if it stopped because the thread's work was cancelled (checked every
    /// 1024 steps of the growth/augmentation loop).
    fn run(&mut self) -> bool {
        for i in 0..self.tr.len() {
            let t = self.tr[i];
            if t != 0.0 {
                self.parent[i] = TERMINAL;
                self.is_sink[i] = t < 0.0;
                self.dist[i] = 1;
                self.activate(i);
            }
        }
        let mut current: Option<usize> = None;
        let mut steps = 0u32;
        loop {
            if steps % 1024 == 0 && crate::cancel::cancelled() {
                return true;
            }
            steps = steps.wrapping_add(1);
            let i = match current.take() {
                Some(i) if self.parent[i] != FREE => i,
                _ => match self.next_active() {
                    Some(i) => i,
                    None => break,
                },
            };
            if let Some((p, q, d)) = self.grow(i) {
                self.time += 1;
                self.augment(p, q, d);
                self.adopt();
                current = Some(i);
            }
        }
        false
    }

    /// Grows the tree of `i` by one layer; returns a source-tree node, a sink-tree node and
    /// the direction of the residual edge between them when the trees touch.
    #[inline]
    fn grow(&mut self, i: usize) -> Option<(usize, usize, usize)> {
        let k = self.k;
        let sink = self.is_sink[i];
        for d in 0..k {
            let j = self.nb(i, d);
            let r = if sink {
                self.cap[j * k + opp(d)]
            } else {
                self.cap[i * k + d]
            };
            if r <= 0.0 {
                continue;
            }
            if self.parent[j] == FREE {
                self.is_sink[j] = sink;
                self.parent[j] = opp(d) as u8;
                self.ts[j] = self.ts[i];
                self.dist[j] = self.dist[i] + 1;
                self.activate(j);
            } else if self.is_sink[j] != sink {
                return Some(if sink { (j, i, opp(d)) } else { (i, j, d) });
            } else if self.ts[j] <= self.ts[i] && self.dist[j] > self.dist[i] {
                self.parent[j] = opp(d) as u8;
                self.ts[j] = self.ts[i];
                self.dist[j] = self.dist[i] + 1;
            }
        }
        None
    }

    #[inline]
    fn orphan_front(&mut self, i: usize) {
        self.parent[i] = ORPHAN;
        self.orphans.push_front(i as u32);
    }

    fn augment(&mut self, p: usize, q: usize, d: usize) {
        let k = self.k;
        let mut f = self.cap[p * k + d];
        let mut i = p;
        loop {
            let a = self.parent[i];
            if a == TERMINAL {
                f = f.min(self.tr[i]);
                break;
            }
            let j = self.nb(i, a as usize);
            f = f.min(self.cap[j * k + opp(a as usize)]);
            i = j;
        }
        i = q;
        loop {
            let a = self.parent[i];
            if a == TERMINAL {
                f = f.min(-self.tr[i]);
                break;
            }
            f = f.min(self.cap[i * k + a as usize]);
            i = self.nb(i, a as usize);
        }

        self.cap[p * k + d] -= f;
        self.cap[q * k + opp(d)] += f;
        i = p;
        loop {
            let a = self.parent[i];
            if a == TERMINAL {
                self.tr[i] -= f;
                if self.tr[i] <= 0.0 {
                    self.orphan_front(i);
                }
                break;
            }
            let a = a as usize;
            let j = self.nb(i, a);
            self.cap[j * k + opp(a)] -= f;
            self.cap[i * k + a] += f;
            if self.cap[j * k + opp(a)] <= 0.0 {
                self.orphan_front(i);
            }
            i = j;
        }
        i = q;
        loop {
            let a = self.parent[i];
            if a == TERMINAL {
                self.tr[i] += f;
                if self.tr[i] >= 0.0 {
                    self.orphan_front(i);
                }
                break;
            }
            let a = a as usize;
            let j = self.nb(i, a);
            self.cap[i * k + a] -= f;
            self.cap[j * k + opp(a)] += f;
            if self.cap[i * k + a] <= 0.0 {
                self.orphan_front(i);
            }
            i = j;
        }
        self.flow += f64::from(f);
    }

    fn adopt(&mut self) {
        while let Some(i) = self.orphans.pop_front() {
            self.process_orphan(i as usize);
        }
    }

    /// Residual capacity of the edge that would make `j` (neighbour of `i` in direction `d`)
    /// the parent of `i` in a tree of side `sink`.
    #[inline]
    fn residual_to(&self, i: usize, j: usize, d: usize, sink: bool) -> f32 {
        if sink {
            self.cap[i * self.k + d]
        } else {
            self.cap[j * self.k + opp(d)]
        }
    }

    fn process_orphan(&mut self, i: usize) {
        let k = self.k;
        let sink = self.is_sink[i];
        let mut best: Option<(usize, u32)> = None;
        for d in 0..k {
            let j = self.nb(i, d);
            if self.parent[j] == FREE
                || self.is_sink[j] != sink
                || self.residual_to(i, j, d, sink) <= 0.0
            {
                continue;
            }
            // Does j still reach its terminal? Count the distance on the way.
            let mut m = j;
            let mut dd = 0u32;
            let valid = loop {
                if self.ts[m] == self.time {
                    dd += self.dist[m];
                    break true;
                }
                let a = self.parent[m];
                dd += 1;
                if a == TERMINAL {
                    self.ts[m] = self.time;
                    self.dist[m] = 1;
                    break true;
                }
                if a == ORPHAN {
                    break false;
                }
                m = self.nb(m, a as usize);
            };
            if valid {
                if best.is_none_or(|(_, bd)| dd < bd) {
                    best = Some((d, dd));
                }
                let mut m = j;
                while self.ts[m] != self.time {
                    self.ts[m] = self.time;
                    self.dist[m] = dd;
                    dd -= 1;
                    m = self.nb(m, self.parent[m] as usize);
                }
            }
        }
        if let Some((d, dd)) = best {
            self.parent[i] = d as u8;
            self.ts[i] = self.time;
            self.dist[i] = dd + 1;
            return;
        }
        self.ts[i] = 0;
        for d in 0..k {
            let j = self.nb(i, d);
            let a = self.parent[j];
            if a == FREE || self.is_sink[j] != sink {
                continue;
            }
            if self.residual_to(i, j, d, sink) > 0.0 {
                self.activate(j);
            }
            if a != TERMINAL && a != ORPHAN && self.nb(j, a as usize) == i {
                self.parent[j] = ORPHAN;
                self.orphans.push_back(j as u32);
            }
        }
        self.parent[i] = FREE;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// Dinic-free reference: Edmonds–Karp on a dense residual matrix (tiny graphs only).
    pub(super) fn reference(
        h: usize,
        w: usize,
        k: usize,
        edges: &[f32],
        source: &[f32],
        sink: &[f32],
    ) -> f64 {
        let n = h * w + 2;
        let (s, t) = (h * w, h * w + 1);
        let mut c = vec![vec![0f64; n]; n];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                c[s][i] += f64::from(source[i]);
                c[i][t] += f64::from(sink[i]);
                for d in 0..k {
                    let (ny, nx) = (y as isize + DIRS[d].0, x as isize + DIRS[d].1);
                    if ny < 0 || nx < 0 || ny >= h as isize || nx >= w as isize {
                        continue;
                    }
                    c[i][ny as usize * w + nx as usize] += f64::from(edges[i * k + d]);
                }
            }
        }
        let mut flow = 0.0;
        loop {
            let mut prev = vec![usize::MAX; n];
            prev[s] = s;
            let mut q = VecDeque::from([s]);
            while let Some(u) = q.pop_front() {
                for v in 0..n {
                    if prev[v] == usize::MAX && c[u][v] > 1e-12 {
                        prev[v] = u;
                        q.push_back(v);
                    }
                }
            }
            if prev[t] == usize::MAX {
                return flow;
            }
            let mut f = f64::INFINITY;
            let mut v = t;
            while v != s {
                f = f.min(c[prev[v]][v]);
                v = prev[v];
            }
            v = t;
            while v != s {
                c[prev[v]][v] -= f;
                c[v][prev[v]] += f;
                v = prev[v];
            }
            flow += f;
        }
    }

    pub(super) fn cut_value(
        h: usize,
        w: usize,
        k: usize,
        edges: &[f32],
        source: &[f32],
        sink: &[f32],
        side: &[bool],
    ) -> f64 {
        let mut v = 0.0;
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                v += f64::from(if side[i] { source[i] } else { sink[i] });
                for d in 0..k {
                    let (ny, nx) = (y as isize + DIRS[d].0, x as isize + DIRS[d].1);
                    if ny < 0 || nx < 0 || ny >= h as isize || nx >= w as isize {
                        continue;
                    }
                    if !side[i] && side[ny as usize * w + nx as usize] {
                        v += f64::from(edges[i * k + d]);
                    }
                }
            }
        }
        v
    }

    fn random_case(seed: u64, h: usize, w: usize, k: usize) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
        let mut rng = Rng::keyed(seed, 1, 2);
        let mut u = || (rng.below(1000) as f32) / 100.0;
        let edges: Vec<f32> = (0..h * w * k).map(|_| u()).collect();
        let mut source: Vec<f32> = (0..h * w).map(|_| u() * 0.5).collect();
        let mut sink: Vec<f32> = (0..h * w).map(|_| u() * 0.5).collect();
        // Sparse terminals, like a seam problem.
        for i in 0..h * w {
            if i % 3 != 0 {
                source[i] = 0.0;
            }
            if i % 5 != 1 {
                sink[i] = 0.0;
            }
        }
        (edges, source, sink)
    }

    #[test]
    fn flow_equals_reference_and_labels_are_a_minimum_cut() {
        for (seed, (h, w, k)) in [(5, 7, 4), (6, 6, 8), (1, 13, 4), (9, 4, 8), (8, 8, 4)]
            .into_iter()
            .enumerate()
        {
            for rep in 0..4 {
                let (edges, source, sink) = random_case(seed as u64 * 10 + rep, h, w, k);
                let mut g = GridGraph::new(h, w, k).unwrap();
                g.set_edges("edges", &edges, EdgeLayout::Directed).unwrap();
                g.set_terminals(&source, &sink).unwrap();
                let flow = g.maxflow();
                let want = reference(h, w, k, &edges, &source, &sink);
                assert!(
                    (flow - want).abs() <= 1e-4 * want.max(1.0),
                    "{h}×{w}×{k}: {flow} vs {want}"
                );
                let cut = cut_value(h, w, k, &edges, &source, &sink, g.sink_side().unwrap());
                assert!(
                    (cut - want).abs() <= 1e-4 * want.max(1.0),
                    "cut {cut} vs {want}"
                );
            }
        }
    }

    #[test]
    fn many_random_grids_with_hard_constraints_match_the_reference() {
        let mut rng = Rng::keyed(4242, 0, 0);
        for case in 0..60 {
            let (h, w) = (1 + rng.below(12) as usize, 1 + rng.below(12) as usize);
            let k = if case % 2 == 0 { 4 } else { 8 };
            let zero = 1 + rng.below(4);
            let mut val = |scale: u64| {
                if rng.below(zero + 1) == 0 {
                    0.0
                } else {
                    rng.below(scale) as f32 / 7.0
                }
            };
            let edges: Vec<f32> = (0..h * w * k).map(|_| val(50)).collect();
            let mut source: Vec<f32> = (0..h * w).map(|_| val(30)).collect();
            let mut sink: Vec<f32> = (0..h * w).map(|_| val(30)).collect();
            source[0] = f32::INFINITY;
            sink[h * w - 1] = if h * w > 1 { f32::INFINITY } else { 1.0 };
            let mut g = GridGraph::new(h, w, k).unwrap();
            g.set_edges("edges", &edges, EdgeLayout::Directed).unwrap();
            g.set_terminals(&source, &sink).unwrap();
            let flow = g.maxflow();
            // The reference cannot take infinities: a capacity above every finite cut is as hard.
            let big = 1e6f32;
            let fin = |a: &[f32]| a.iter().map(|v| v.min(big)).collect::<Vec<_>>();
            let want = reference(h, w, k, &edges, &fin(&source), &fin(&sink));
            assert!(
                (flow - want).abs() <= 1e-4 * want.max(1.0),
                "case {case} {h}×{w}×{k}: {flow} vs {want}"
            );
            let side = g.sink_side().unwrap();
            let cut = cut_value(h, w, k, &edges, &fin(&source), &fin(&sink), side);
            assert!(
                (cut - want).abs() <= 1e-4 * want.max(1.0),
                "case {case}: cut {cut} vs {want}"
            );
            assert!(!side[0]);
        }
    }

    #[test]
    fn split_solve_equals_the_direct_solve() {
        // 320×240 is split twice; the parts' flows plus the final pass must be the maximum.
        let (h, w, k) = (320, 240, 4);
        let (edges, mut source, mut sink) = random_case(99, h, w, k);
        for y in 0..h {
            source[y * w] = f32::INFINITY;
            sink[y * w + w - 1] = f32::INFINITY;
        }
        let mut split = GridGraph::new(h, w, k).unwrap();
        split
            .set_edges("edges", &edges, EdgeLayout::Directed)
            .unwrap();
        split.set_terminals(&source, &sink).unwrap();
        let mut direct = split.clone();
        let f_split = split.maxflow();
        let f_direct = direct.solve();
        assert!(
            (f_split - f_direct).abs() <= 1e-5 * f_direct,
            "{f_split} vs {f_direct}"
        );
        let big = 1e6f32;
        let fin = |a: &[f32]| a.iter().map(|v| v.min(big)).collect::<Vec<_>>();
        let cut = cut_value(
            h,
            w,
            k,
            &edges,
            &fin(&source),
            &fin(&sink),
            split.sink_side().unwrap(),
        );
        assert!(
            (cut - f_direct).abs() <= 1e-5 * f_direct,
            "cut {cut} vs {f_direct}"
        );
    }

    #[test]
    fn symmetric_layout_is_the_directed_one_with_equal_capacities() {
        let (h, w) = (6, 9);
        for k in [4, 8] {
            let (edges, source, sink) = random_case(77, h, w, k / 2);
            let sym = &edges[..h * w * k / 2];
            let mut dir = vec![0f32; h * w * k];
            for y in 0..h {
                for x in 0..w {
                    for (s, &d) in SYMMETRIC_DIRS[..k / 2].iter().enumerate() {
                        let v = sym[(y * w + x) * k / 2 + s];
                        dir[(y * w + x) * k + d] = v;
                        let (ny, nx) = (y as isize + DIRS[d].0, x as isize + DIRS[d].1);
                        if ny >= 0 && nx >= 0 && (ny as usize) < h && (nx as usize) < w {
                            dir[(ny as usize * w + nx as usize) * k + opp(d)] = v;
                        }
                    }
                }
            }
            let mut a = GridGraph::new(h, w, k).unwrap();
            a.set_edges("edges", sym, EdgeLayout::Symmetric).unwrap();
            a.set_terminals(&source, &sink).unwrap();
            let want = reference(h, w, k, &dir, &source, &sink);
            assert!((a.maxflow() - want).abs() < 1e-4 * want.max(1.0));
        }
    }

    #[test]
    fn hard_constraints_hold_and_a_straight_cut_is_found() {
        // Columns 0 tied to the source, the last to the sink, unit edges: the cut is one column
        // of horizontal edges, so the flow is h, and every hard constraint is on its side.
        let (h, w) = (10, 12);
        let mut g = GridGraph::new(h, w, 4).unwrap();
        g.set_edges("edges", &vec![1.0; h * w * 2], EdgeLayout::Symmetric)
            .unwrap();
        let mut source = vec![0f32; h * w];
        let mut sink = vec![0f32; h * w];
        for y in 0..h {
            source[y * w] = f32::INFINITY;
            sink[y * w + w - 1] = f32::INFINITY;
        }
        g.set_terminals(&source, &sink).unwrap();
        assert!((g.maxflow() - h as f64).abs() < 1e-9);
        let side = g.sink_side().unwrap();
        for y in 0..h {
            assert!(!side[y * w] && side[y * w + w - 1]);
        }
    }

    #[test]
    fn bad_capacities_are_rejected_by_name() {
        let mut g = GridGraph::new(2, 2, 4).unwrap();
        let e = g.set_edges(
            "edges",
            &[1.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            EdgeLayout::Symmetric,
        );
        assert!(matches!(
            e,
            Err(crate::Error::InvalidArgument { name: "edges", .. })
        ));
        let e = g.set_edges("edges", &[f32::NAN; 8], EdgeLayout::Symmetric);
        assert!(matches!(
            e,
            Err(crate::Error::InvalidArgument { name: "edges", .. })
        ));
        let e = g.set_terminals(
            &[f32::INFINITY, 0.0, 0.0, 0.0],
            &[f32::INFINITY, 0.0, 0.0, 0.0],
        );
        assert!(matches!(
            e,
            Err(crate::Error::InvalidArgument { name: "sink", .. })
        ));
        let e = g.set_terminals(&[0.0, f32::NAN, 0.0, 0.0], &[0.0; 4]);
        assert!(matches!(
            e,
            Err(crate::Error::InvalidArgument { name: "source", .. })
        ));
        assert!(GridGraph::new(2, 2, 6).is_err());
    }
}
