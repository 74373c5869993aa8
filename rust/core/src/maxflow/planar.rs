//! Exact minimum cuts of planar grid problems as shortest paths in the dual graph.
//!
//! A 4-connected grid is a plane graph. When every terminal edge attaches to a pixel on the
//! grid's border, and the pixels tied to the source form one arc of the border cycle and
//! those tied to the sink another arc that does not interleave with it, the source and the
//! sink can be drawn in the outer face and the whole s-t graph stays planar. Its minimum cut
//! is then the shortest path, in the directed dual graph, between the two pieces of the outer
//! face that lie between the arcs (Schmidt, Töppe & Cremers, *Efficient planar graph cuts
//! with applications in computer vision*, CVPR 2009; Hassin 1981 for the undirected case).
//! Dijkstra finds it in `O(n log n)` and, unlike an augmenting-path method, does not slow
//! down when augmenting paths are long (as they are across a seam problem's overlap).
//!
//! The dual: face `(fi, fj)` (`0 ≤ fi ≤ h`, `0 ≤ fj ≤ w`) lies between pixels
//! `(fi-1, fj-1)`, `(fi-1, fj)`, `(fi, fj-1)` and `(fi, fj)`; faces with `fi ∈ {0, h}` or
//! `fj ∈ {0, w}` form a ring outside the grid. Crossing a primal edge costs the capacity
//! from the pixel on the right of the direction of travel to the one on its left (screen
//! orientation, rows going down), so a path from the first to the second outer piece has the
//! source side on its right. Between consecutive ring faces lies the terminal edge of one
//! border pixel (a *ray*): crossing it clockwise costs the pixel's capacity to the sink, anti
//! clockwise its capacity from the source. The ray costs are written into the padding ring of
//! [`GridGraph`]'s capacity array for the search and cleared afterwards, so the search reads
//! every cost straight from the graph.
//!
//! The labels are the pixels reachable from the source without crossing the path. Their cut
//! value is checked against the path length; on a mismatch (which would be a bug) the caller
//! falls back to Boykov–Kolmogorov.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use super::{opp, GridGraph};
use crate::cancel;

const E: usize = 0;
const S: usize = 1;
const W: usize = 2;
const N: usize = 3;

/// Face states of the search.
const OPEN: u8 = 0;
const DONE: u8 = 1;
const TARGET: u8 = 2;
/// `pred` of a face the search started from.
const SEED: u8 = u8::MAX;

/// Which border pixels are tied to which terminal, when the planar method applies.
pub(super) struct Arcs {
    /// Border cycle indices (clockwise from the top-left pixel) of the first and last pixel of
    /// the source arc, and of the first and last pixel of the sink arc.
    src: (usize, usize),
    snk: (usize, usize),
}

impl GridGraph {
    /// Length of the clockwise border cycle.
    fn cycle_len(&self) -> usize {
        2 * (self.h + self.w) - 4
    }

    /// Border pixel `c` of the clockwise cycle (top row left to right, right column down,
    /// bottom row right to left, left column up): its padded index and the outward direction
    /// of its ray. Each corner belongs to the side it starts.
    fn border(&self, c: usize) -> (usize, usize) {
        let (h, w) = (self.h, self.w);
        if c < w {
            (self.node(0, c), N)
        } else if c < w + h - 1 {
            (self.node(c + 1 - w, w - 1), E)
        } else if c < 2 * w + h - 2 {
            (self.node(h - 1, 2 * w + h - 3 - c), S)
        } else {
            (self.node(2 * w + 2 * h - 4 - c, 0), W)
        }
    }

    /// The arcs, when the planar method applies: 4-connectivity, at least 2×2 pixels, every
    /// residual terminal capacity on the border, and the source-tied and sink-tied border
    /// pixels in two non-interleaving arcs (both non-empty).
    pub(super) fn planar_arcs(&self) -> Option<Arcs> {
        let (h, w) = (self.h, self.w);
        if self.k != 4 || h < 2 || w < 2 {
            return None;
        }
        for y in 1..h - 1 {
            let row = &self.tr[self.node(y, 1)..self.node(y, w - 1)];
            if row.iter().any(|&t| t != 0.0) {
                return None;
            }
        }
        // The signs of the nonzero border terminals, in cycle order; exactly two changes.
        let l = self.cycle_len();
        let sign = |c: usize| {
            let t = self.tr[self.border(c).0];
            if t > 0.0 {
                1i8
            } else if t < 0.0 {
                -1
            } else {
                0
            }
        };
        let mut first: Option<(usize, i8)> = None;
        let mut prev: Option<(usize, i8)> = None;
        let (mut src, mut snk) = ((usize::MAX, usize::MAX), (usize::MAX, usize::MAX));
        let mut changes = 0;
        let mut step = |a: (usize, i8), b: (usize, i8)| {
            if a.1 != b.1 {
                changes += 1;
                if a.1 > 0 {
                    (src.1, snk.0) = (a.0, b.0);
                } else {
                    (snk.1, src.0) = (a.0, b.0);
                }
            }
        };
        for c in 0..l {
            let s = sign(c);
            if s == 0 {
                continue;
            }
            match prev {
                None => first = Some((c, s)),
                Some(p) => step(p, (c, s)),
            }
            prev = Some((c, s));
        }
        step(prev?, first?);
        (changes == 2).then_some(Arcs { src, snk })
    }

    /// Solves the cut by a shortest dual path; `None` if the labels it yields are not a cut of
    /// the path's length (never expected; the caller then runs Boykov–Kolmogorov) or once the
    /// thread's work is cancelled (the search checks every few thousand faces).
    pub(super) fn planar_solve(&mut self, arcs: &Arcs) -> Option<f64> {
        let (h, w, pw) = (self.h, self.w, self.pw);
        let l = self.cycle_len();
        let off = |d: usize| super::DIRS[d].0 * pw as isize + super::DIRS[d].1;
        // Ray costs into the padding: clockwise = pixel to sink, anticlockwise = source to pixel.
        for c in 0..l {
            let (p, d) = self.border(c);
            let q = p.wrapping_add_signed(off(d));
            let t = self.tr[p];
            self.cap[p * 4 + d] = (-t).max(0.0);
            self.cap[q * 4 + opp(d)] = t.max(0.0);
        }
        let found = self.dual_path(arcs);
        for c in 0..l {
            let (p, d) = self.border(c);
            let q = p.wrapping_add_signed(off(d));
            self.cap[p * 4 + d] = 0.0;
            self.cap[q * 4 + opp(d)] = 0.0;
        }
        let (length, cut) = found?;

        // Flood the source side: from the source arc's pixels whose ray is not cut, through
        // the edges the path does not cross.
        let n = self.tr.len();
        let mut seen = vec![true; n];
        for y in 0..h {
            seen[self.node(y, 0)..=self.node(y, w - 1)].fill(false);
        }
        let mut stack: Vec<u32> = Vec::new();
        let mut c = arcs.src.0;
        loop {
            let (p, d) = self.border(c);
            if cut[p] & (1 << d) == 0 && !seen[p] {
                seen[p] = true;
                stack.push(p as u32);
            }
            if c == arcs.src.1 {
                break;
            }
            c = (c + 1) % l;
        }
        let offs = [off(E), off(S), off(W), off(N)];
        while let Some(p) = stack.pop() {
            let p = p as usize;
            for (d, &o) in offs.iter().enumerate() {
                let q = p.wrapping_add_signed(o);
                if cut[p] & (1 << d) == 0 && !seen[q] {
                    seen[q] = true;
                    stack.push(q as u32);
                }
            }
        }

        // The labels' cut value must be the path length.
        let mut value = 0f64;
        for y in 0..h {
            for x in 0..w {
                let p = self.node(y, x);
                let t = self.tr[p];
                if seen[p] {
                    value += f64::from((-t).max(0.0));
                    for (d, &o) in offs.iter().enumerate() {
                        let q = p.wrapping_add_signed(o);
                        if !seen[q] {
                            value += f64::from(self.cap[p * 4 + d]);
                        }
                    }
                } else {
                    value += f64::from(t.max(0.0));
                }
            }
        }
        if !(value - length).abs().le(&(1e-9 * length.max(1.0))) {
            return None;
        }
        self.sink_side = (0..h)
            .flat_map(|y| (0..w).map(move |x| (y, x)))
            .map(|(y, x)| !seen[self.node(y, x)])
            .collect();
        // No flow is pushed, so the capacities stay the original (or residual) ones and
        // `base_flow` keeps meaning the flow already in them: solving again, or after more
        // terminal capacity is added, stays exact.
        self.solved = true;
        Some(self.base_flow + length)
    }

    /// Dijkstra from the outer piece after the source arc to the one after the sink arc.
    /// Returns the path length and, per padded pixel, a bit mask of the directions whose
    /// edge (or, outward, whose terminal edge) the path crosses.
    ///
    /// Faces are indexed `g = (fi + 1) * pw + fj`, the padded index of the face's lower-left
    /// pixel, so the search reads capacities without conversions; rows `0` and `h + 2` and
    /// column `w + 1` are not faces. Ties go to the smaller face index, so the result is
    /// deterministic.
    fn dual_path(&self, arcs: &Arcs) -> Option<(f64, Vec<u8>)> {
        let (h, w, pw) = (self.h, self.w, self.pw);
        let nf = (h + 3) * pw;
        let mut state = vec![OPEN; nf];
        state[..pw].fill(DONE);
        state[(h + 2) * pw..].fill(DONE);
        for r in 1..h + 2 {
            state[r * pw + w + 1] = DONE;
        }
        // The ring of outer faces, clockwise from the top-left corner, each with the border
        // cycle index of the ray that follows it (None: no pixel's terminal edge there).
        let mut ring: Vec<(usize, Option<usize>)> = Vec::with_capacity(2 * (h + w));
        ring.extend((0..=w).map(|fj| (pw + fj, (fj < w).then_some(fj))));
        ring.extend((1..=h).map(|fi| ((fi + 1) * pw + w, (fi < h).then(|| w - 1 + fi))));
        ring.extend(
            (0..w)
                .rev()
                .map(|fj| ((h + 1) * pw + fj, (fj >= 1).then(|| 2 * w + h - 2 - fj))),
        );
        ring.extend(
            (1..h)
                .rev()
                .map(|fi| ((fi + 1) * pw, (fi >= 2).then(|| 2 * w + 2 * h - 3 - fi))),
        );
        // The faces after ray `from` up to the one before ray `to`, clockwise.
        let piece = |from: usize, to: usize| {
            let start = ring.iter().position(|r| r.1 == Some(from)).expect("ray");
            let mut out = Vec::new();
            for i in 1..=ring.len() {
                let (g, ray) = ring[(start + i) % ring.len()];
                out.push(g);
                if ray == Some(to) {
                    break;
                }
            }
            out
        };
        let mut dist = vec![f64::INFINITY; nf];
        let mut pred = vec![SEED; nf];
        let mut heap = BinaryHeap::new();
        for g in piece(arcs.snk.1, arcs.src.0) {
            state[g] = TARGET;
        }
        for g in piece(arcs.src.1, arcs.snk.0) {
            dist[g] = 0.0;
            heap.push(Reverse((0u64, g as u32)));
        }
        let cap = &self.cap;
        let steps = [1isize, pw as isize, -1, -(pw as isize)];
        let mut target = usize::MAX;
        let mut pops = 0u32;
        while let Some(Reverse((key, g))) = heap.pop() {
            pops = pops.wrapping_add(1);
            if pops % 4096 == 0 && cancel::cancelled() {
                return None;
            }
            let g = g as usize;
            let d = f64::from_bits(key);
            if state[g] == DONE || d > dist[g] {
                continue;
            }
            if state[g] == TARGET {
                target = g;
                break;
            }
            state[g] = DONE;
            let costs = [
                cap[(g + 1) * 4 + N],
                cap[g * 4 + E],
                cap[(g - pw) * 4 + S],
                cap[(g - pw + 1) * 4 + W],
            ];
            for dir in 0..4 {
                let ng = g.wrapping_add_signed(steps[dir]);
                if state[ng] == DONE {
                    continue;
                }
                let nd = d + f64::from(costs[dir]);
                if nd < dist[ng] {
                    dist[ng] = nd;
                    pred[ng] = dir as u8;
                    heap.push(Reverse((nd.to_bits(), ng as u32)));
                }
            }
        }
        assert!(
            target != usize::MAX,
            "the dual search always reaches the sink piece"
        );
        let mut cut = vec![0u8; self.tr.len()];
        let mut g = target;
        while pred[g] != SEED {
            let dir = pred[g] as usize;
            let f = g.wrapping_add_signed(-steps[dir]);
            // The edge crossed by the move from face f in direction dir.
            let (a, da, b, db) = match dir {
                E => (f - pw + 1, S, f + 1, N),
                S => (f, E, f + 1, W),
                W => (f - pw, S, f, N),
                _ => (f - pw, E, f - pw + 1, W),
            };
            cut[a] |= 1 << da;
            cut[b] |= 1 << db;
            g = f;
        }
        Some((dist[target], cut))
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::{cut_value, reference};
    use super::super::{EdgeLayout, GridGraph, Method};
    use crate::rng::Rng;

    /// The border pixels `(y, x)` clockwise from the top-left one, listed independently of
    /// [`GridGraph::border`].
    fn cycle(h: usize, w: usize) -> Vec<(usize, usize)> {
        let mut v: Vec<(usize, usize)> = (0..w).map(|x| (0, x)).collect();
        v.extend((1..h).map(|y| (y, w - 1)));
        v.extend((0..w - 1).rev().map(|x| (h - 1, x)));
        v.extend((1..h - 1).rev().map(|y| (y, 0)));
        v
    }

    struct Case {
        h: usize,
        w: usize,
        edges: Vec<f32>,
        source: Vec<f32>,
        sink: Vec<f32>,
    }

    /// A random planar case: directed capacities with many zeros and ties, a source arc and
    /// a sink arc of random lengths and positions on the border (finite, zero or infinite
    /// capacities, some pixels tied to both terminals), and gap pixels tied equally to both.
    fn planar_case(rng: &mut Rng, h: usize, w: usize) -> Case {
        let val = |rng: &mut Rng, scale: u64| {
            if rng.below(3) == 0 {
                0.0
            } else {
                rng.below(scale) as f32 / 4.0
            }
        };
        let edges: Vec<f32> = (0..h * w * 4).map(|_| val(rng, 20)).collect();
        let mut source = vec![0f32; h * w];
        let mut sink = vec![0f32; h * w];
        let cyc = cycle(h, w);
        let l = cyc.len();
        let src_len = 1 + rng.below(l as u64 - 1) as usize;
        let snk_len = 1 + rng.below((l - src_len) as u64) as usize;
        let gap = rng.below((l - src_len - snk_len + 1) as u64) as usize;
        let start = rng.below(l as u64) as usize;
        for i in 0..l {
            let (y, x) = cyc[(start + i) % l];
            let p = y * w + x;
            let pick = |rng: &mut Rng, first: bool| match rng.below(6) {
                _ if first => 1.0 + rng.below(40) as f32 / 4.0,
                0 => f32::INFINITY,
                1 => 0.0,
                _ => rng.below(40) as f32 / 4.0,
            };
            if i < src_len {
                source[p] = pick(rng, i == 0);
                if source[p].is_finite() && rng.below(4) == 0 {
                    sink[p] = source[p] * 0.5; // both terminals, the source's larger
                }
            } else if (src_len + gap..src_len + gap + snk_len).contains(&i) {
                sink[p] = pick(rng, i == src_len + gap);
                if sink[p].is_finite() && rng.below(4) == 0 {
                    source[p] = sink[p] * 0.25;
                }
            } else if rng.below(2) == 0 {
                // A tie: both terminals equal, nothing left after the straight push.
                let v = rng.below(10) as f32;
                (source[p], sink[p]) = (v, v);
            }
        }
        Case {
            h,
            w,
            edges,
            source,
            sink,
        }
    }

    fn graph(c: &Case, k: usize) -> GridGraph {
        let mut g = GridGraph::new(c.h, c.w, k).unwrap();
        g.set_edges("edges", &c.edges, EdgeLayout::Directed)
            .unwrap();
        g.set_terminals(&c.source, &c.sink).unwrap();
        g
    }

    /// Checks flow and labels against the reference; returns the method used.
    fn check(c: &Case, k: usize, what: &str) -> Method {
        let fin = |a: &[f32]| a.iter().map(|v| v.min(1e6)).collect::<Vec<_>>();
        let (src, snk) = (fin(&c.source), fin(&c.sink));
        let want = reference(c.h, c.w, k, &c.edges, &src, &snk);
        let mut g = graph(c, k);
        let flow = g.maxflow();
        let tol = 1e-6 * want.max(1.0);
        assert!((flow - want).abs() <= tol, "{what}: {flow} vs {want}");
        let side = g.sink_side().unwrap();
        let cut = cut_value(c.h, c.w, k, &c.edges, &src, &snk, side);
        assert!((cut - want).abs() <= tol, "{what}: cut {cut} vs {want}");
        for (i, &b) in side.iter().enumerate() {
            assert!(!(c.source[i].is_infinite() && b), "{what}: hard source {i}");
            assert!(!c.sink[i].is_infinite() || b, "{what}: hard sink {i}");
        }
        let mut bk = graph(c, k);
        let f_bk = bk.maxflow_with(Method::BoykovKolmogorov).unwrap();
        assert!((f_bk - flow).abs() <= tol, "{what}: BK {f_bk} vs {flow}");
        g.method().unwrap()
    }

    #[test]
    fn planar_cuts_equal_the_reference_and_boykov_kolmogorov() {
        let mut rng = Rng::keyed(2009, 3, 0);
        for case in 0..300 {
            let (h, w) = (2 + rng.below(11) as usize, 2 + rng.below(11) as usize);
            let c = planar_case(&mut rng, h, w);
            let m = check(&c, 4, &format!("case {case} {h}×{w}"));
            assert_eq!(m, Method::Planar, "case {case}: planar method not taken");
        }
    }

    #[test]
    fn planar_cut_of_a_seam_strip_equals_boykov_kolmogorov() {
        // Left column to the source, right column to the sink, like the seam benchmark.
        let mut rng = Rng::keyed(7, 7, 7);
        for (h, w) in [(200, 24), (40, 90), (64, 64)] {
            let edges: Vec<f32> = (0..h * w * 4)
                .map(|_| rng.below(1000) as f32 / 9.0)
                .collect();
            let mut source = vec![0f32; h * w];
            let mut sink = vec![0f32; h * w];
            for y in 0..h {
                source[y * w] = f32::INFINITY;
                sink[y * w + w - 1] = f32::INFINITY;
            }
            let c = Case {
                h,
                w,
                edges,
                source,
                sink,
            };
            let mut g = graph(&c, 4);
            let flow = g.maxflow();
            assert_eq!(g.method(), Some(Method::Planar));
            let mut bk = graph(&c, 4);
            let want = bk.maxflow_with(Method::BoykovKolmogorov).unwrap();
            assert!(
                (flow - want).abs() <= 1e-6 * want,
                "{h}×{w}: {flow} vs {want}"
            );
            let fin = |a: &[f32]| a.iter().map(|v| v.min(1e9)).collect::<Vec<_>>();
            let side = g.sink_side().unwrap();
            let cut = cut_value(h, w, 4, &c.edges, &fin(&c.source), &fin(&c.sink), side);
            assert!((cut - want).abs() <= 1e-6 * want, "cut {cut} vs {want}");
        }
    }

    #[test]
    fn solving_again_or_after_adding_terminal_capacity_stays_exact() {
        let mut rng = Rng::keyed(77, 1, 1);
        for case in 0..30 {
            let (h, w) = (3 + rng.below(8) as usize, 3 + rng.below(8) as usize);
            let mut c = planar_case(&mut rng, h, w);
            let mut g = graph(&c, 4);
            let first = g.maxflow();
            assert_eq!(g.method(), Some(Method::Planar));
            let again = g.maxflow();
            assert!(
                again.to_bits() == first.to_bits(),
                "case {case}: a second solve changed the flow ({first} -> {again})"
            );
            // More capacity on a border pixel (planar again) or an interior one (BK now).
            for (y, x) in [(0, w / 2), (h / 2, w / 2)] {
                let (s, t) = (rng.below(9) as f32, rng.below(9) as f32);
                g.set_terminal(y, x, s, t);
                c.source[y * w + x] += s;
                c.sink[y * w + x] += t;
                let flow = g.maxflow();
                let want = graph(&c, 4).maxflow_with(Method::BoykovKolmogorov).unwrap();
                assert!(
                    (flow - want).abs() <= 1e-6 * want.max(1.0),
                    "case {case} after ({y}, {x}): {flow} vs {want} ({:?})",
                    g.method()
                );
            }
        }
    }

    #[test]
    fn boykov_kolmogorov_is_the_fallback_where_the_graph_is_not_planar() {
        let mut rng = Rng::keyed(31, 4, 1);
        for case in 0..40 {
            let (h, w) = (3 + rng.below(8) as usize, 3 + rng.below(8) as usize);
            let mut c = planar_case(&mut rng, h, w);
            // The same case with 8-connectivity is not planar.
            let mut c8 = planar_case(&mut rng, h, w);
            c8.edges = (0..h * w * 8).map(|_| rng.below(20) as f32 / 4.0).collect();
            assert_eq!(check(&c8, 8, "8-connected"), Method::BoykovKolmogorov);
            assert!(graph(&c8, 8).maxflow_with(Method::Planar).is_err());
            // An interior terminal edge.
            let (y, x) = (
                1 + rng.below(h as u64 - 2) as usize,
                1 + rng.below(w as u64 - 2) as usize,
            );
            c.source[y * w + x] = 2.5;
            assert_eq!(check(&c, 4, "interior"), Method::BoykovKolmogorov, "{case}");
            assert!(graph(&c, 4).maxflow_with(Method::Planar).is_err());
        }
        // Interleaving arcs: source, sink, source, sink at the four corners.
        let (h, w) = (6, 7);
        let mut c = planar_case(&mut rng, h, w);
        c.source.fill(0.0);
        c.sink.fill(0.0);
        c.source[0] = 3.0;
        c.sink[w - 1] = 4.0;
        c.source[h * w - 1] = 5.0;
        c.sink[(h - 1) * w] = f32::INFINITY;
        assert_eq!(check(&c, 4, "interleaved"), Method::BoykovKolmogorov);
        // Only one terminal present.
        c.sink.fill(0.0);
        assert_eq!(check(&c, 4, "source only"), Method::BoykovKolmogorov);
        // One row: no border cycle.
        let c = planar_case(&mut rng, 3, 5);
        let c1 = Case {
            h: 1,
            w: 15,
            edges: c.edges.clone(),
            source: c.source.clone(),
            sink: c.sink.clone(),
        };
        assert_eq!(check(&c1, 4, "one row"), Method::BoykovKolmogorov);
    }
}
