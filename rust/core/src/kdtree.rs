//! Approximate nearest neighbours of patches in a reduced space: a PCA basis of the source
//! patches and a kd-tree over their projections, searched best-bin-first with a budget.
//!
//! This is the search half of propagation-assisted kd-trees (He & Sun 2012, "Computing
//! nearest-neighbor fields via propagation-assisted kd-trees"): every target patch gets a few
//! candidates that are close in the reduced space, wherever they lie in the source, and
//! PatchMatch's propagation then spreads the good ones ([`crate::patch`] ranks them by the
//! true patch distance). He & Sun project on Walsh–Hadamard bases; a PCA basis of the source
//! patches keeps more of the variance in as many dimensions.
//!
//! Everything here is deterministic: the PCA is computed serially in `f64` from a fixed
//! sample, the tree is built serially, and each query is independent of the others.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// Points per leaf at most.
const LEAF: usize = 8;
/// Subspace-iteration steps of the PCA.
const PCA_STEPS: usize = 20;

/// A linear map to `d` dimensions: `project(v) = basis · (v − mean)`.
pub(crate) struct Pca {
    pub mean: Vec<f32>,
    /// `d` rows of `dim` values each.
    basis: Vec<f32>,
    pub d: usize,
    dim: usize,
}

impl Pca {
    /// The top-`d` principal directions of `n` sample vectors of length `dim`, written by
    /// `sample(i, out)` (at most `d = dim` directions).
    pub fn fit(n: usize, dim: usize, d: usize, sample: impl Fn(usize, &mut [f32])) -> Pca {
        let d = d.min(dim).max(1);
        let mut x = vec![0f32; dim];
        let mut rows = vec![0f64; n * dim];
        let mut mean = vec![0f64; dim];
        for i in 0..n {
            sample(i, &mut x);
            for (j, v) in x.iter().enumerate() {
                rows[i * dim + j] = f64::from(*v);
                mean[j] += f64::from(*v);
            }
        }
        for m in &mut mean {
            *m /= n.max(1) as f64;
        }
        for row in rows.chunks_exact_mut(dim) {
            for (v, m) in row.iter_mut().zip(&mean) {
                *v -= m;
            }
        }
        // Covariance (unnormalised; the scale does not change the directions).
        let mut cov = vec![0f64; dim * dim];
        for row in rows.chunks_exact(dim) {
            for a in 0..dim {
                let ra = row[a];
                if ra == 0.0 {
                    continue;
                }
                let out = &mut cov[a * dim..(a + 1) * dim];
                for (o, rb) in out[a..].iter_mut().zip(&row[a..]) {
                    *o += ra * rb;
                }
            }
        }
        for a in 0..dim {
            for b in 0..a {
                cov[a * dim + b] = cov[b * dim + a];
            }
        }
        // Subspace iteration from a fixed, well-spread start.
        let mut q: Vec<f64> = (0..d * dim)
            .map(|i| {
                let h = crate::rng::mix64(0x5EED_0F9C ^ i as u64);
                (h >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect();
        orthonormalise(&mut q, dim);
        let mut z = vec![0f64; d * dim];
        for _ in 0..PCA_STEPS {
            for (zr, qr) in z.chunks_exact_mut(dim).zip(q.chunks_exact(dim)) {
                for (a, o) in zr.iter_mut().enumerate() {
                    *o = cov[a * dim..(a + 1) * dim]
                        .iter()
                        .zip(qr)
                        .map(|(c, v)| c * v)
                        .sum();
                }
            }
            std::mem::swap(&mut q, &mut z);
            orthonormalise(&mut q, dim);
        }
        Pca {
            mean: mean.iter().map(|v| *v as f32).collect(),
            basis: q.iter().map(|v| *v as f32).collect(),
            d,
            dim,
        }
    }

    /// Writes the projection of `v` (length `dim`) into `out` (length `d`).
    #[inline]
    pub fn project(&self, v: &[f32], out: &mut [f32]) {
        for (o, b) in out.iter_mut().zip(self.basis.chunks_exact(self.dim)) {
            // Eight independent lanes, so the loop vectorises; the order is fixed.
            let mut acc = [0f32; 8];
            let (vc, mc, bc) = (
                v.chunks_exact(8),
                self.mean.chunks_exact(8),
                b.chunks_exact(8),
            );
            let (vr, mr, br) = (vc.remainder(), mc.remainder(), bc.remainder());
            for ((vv, mm), bb) in vc.zip(mc).zip(bc) {
                for l in 0..8 {
                    acc[l] += (vv[l] - mm[l]) * bb[l];
                }
            }
            let mut s: f32 = acc.iter().sum();
            for ((vv, mm), bb) in vr.iter().zip(mr).zip(br) {
                s += (vv - mm) * bb;
            }
            *o = s;
        }
    }
}

/// Modified Gram–Schmidt on the rows of `q` (each `dim` long). A row that collapses is
/// replaced by a unit vector, so the result is always orthonormal.
fn orthonormalise(q: &mut [f64], dim: usize) {
    let d = q.len() / dim;
    for i in 0..d {
        for j in 0..i {
            let (head, tail) = q.split_at_mut(i * dim);
            let qj = &head[j * dim..(j + 1) * dim];
            let qi = &mut tail[..dim];
            let dot: f64 = qi.iter().zip(qj).map(|(a, b)| a * b).sum();
            for (a, b) in qi.iter_mut().zip(qj) {
                *a -= dot * b;
            }
        }
        let qi = &mut q[i * dim..(i + 1) * dim];
        let norm = qi.iter().map(|a| a * a).sum::<f64>().sqrt();
        if norm > 1e-12 {
            for a in qi.iter_mut() {
                *a /= norm;
            }
        } else {
            qi.fill(0.0);
            qi[i % dim] = 1.0;
        }
    }
}

#[derive(Clone, Copy)]
struct Node {
    /// Split dimension, or `u32::MAX` for a leaf.
    dim: u32,
    split: f32,
    /// Children (internal node) or the range of `order` (leaf).
    a: u32,
    b: u32,
}

/// A kd-tree over `n` points of `d` dimensions, split at the median of the widest dimension.
pub(crate) struct KdTree {
    /// The points in leaf order, so that a leaf is one contiguous run of memory (a query
    /// reads a few leaves; scattered points cost a cache miss each on large sources).
    points: Vec<f32>,
    d: usize,
    /// Point ids in leaf order.
    order: Vec<u32>,
    nodes: Vec<Node>,
}

/// Points sampled per node to choose its split dimension.
const SPREAD_SAMPLES: usize = 256;

/// A heap entry: lower bound of the squared distance to anything under `node`.
#[derive(Clone, Copy, PartialEq)]
pub(crate) struct Bin(f32, u32);
impl Eq for Bin {}
impl Ord for Bin {
    fn cmp(&self, o: &Self) -> Ordering {
        // Reversed: BinaryHeap is a max-heap and we want the smallest bound first.
        o.0.total_cmp(&self.0).then(o.1.cmp(&self.1))
    }
}
impl PartialOrd for Bin {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

impl KdTree {
    /// Builds the tree over `points` (`n × d`, row-major).
    pub fn build(points: &[f32], d: usize) -> KdTree {
        let n = points.len() / d;
        let mut order: Vec<u32> = (0..n as u32).collect();
        let mut nodes = vec![Node {
            dim: u32::MAX,
            split: 0.0,
            a: 0,
            b: n as u32,
        }];
        let mut stack = vec![0usize];
        while let Some(id) = stack.pop() {
            let (lo, hi) = (nodes[id].a as usize, nodes[id].b as usize);
            if hi - lo <= LEAF {
                continue;
            }
            let ids = &mut order[lo..hi];
            // Widest dimension of (an even sample of) this node's points.
            let stride = ids.len().div_ceil(SPREAD_SAMPLES);
            let mut best = (0usize, -1f32);
            for k in 0..d {
                let (mut mn, mut mx) = (f32::INFINITY, f32::NEG_INFINITY);
                for &i in ids.iter().step_by(stride) {
                    let v = points[i as usize * d + k];
                    mn = mn.min(v);
                    mx = mx.max(v);
                }
                if mx - mn > best.1 {
                    best = (k, mx - mn);
                }
            }
            let k = best.0;
            let m = ids.len() / 2;
            ids.select_nth_unstable_by(m, |&a, &b| {
                points[a as usize * d + k]
                    .total_cmp(&points[b as usize * d + k])
                    .then(a.cmp(&b))
            });
            let split = points[ids[m] as usize * d + k];
            let left = nodes.len();
            nodes.push(Node {
                dim: u32::MAX,
                split: 0.0,
                a: lo as u32,
                b: (lo + m) as u32,
            });
            nodes.push(Node {
                dim: u32::MAX,
                split: 0.0,
                a: (lo + m) as u32,
                b: hi as u32,
            });
            nodes[id] = Node {
                dim: k as u32,
                split,
                a: left as u32,
                b: left as u32 + 1,
            };
            stack.push(left + 1);
            stack.push(left);
        }
        let mut sorted = Vec::with_capacity(points.len());
        for &i in &order {
            sorted.extend_from_slice(&points[i as usize * d..(i as usize + 1) * d]);
        }
        KdTree {
            points: sorted,
            d,
            order,
            nodes,
        }
    }

    /// The (up to) `k` points nearest to `q` among those in the leaves visited best-bin-first
    /// until `budget` points have been compared, as `(squared distance, id)` in increasing
    /// order, written into `best` (cleared first). `heap` is scratch space.
    pub fn search(
        &self,
        q: &[f32],
        k: usize,
        budget: usize,
        best: &mut Vec<(f32, u32)>,
        heap: &mut BinaryHeap<Bin>,
    ) {
        best.clear();
        heap.clear();
        heap.push(Bin(0.0, 0));
        let mut seen = 0usize;
        while let Some(Bin(bound, mut id)) = heap.pop() {
            if seen >= budget || (best.len() == k && bound >= best[k - 1].0) {
                break;
            }
            // Descend to a leaf, queueing the far side of every split.
            loop {
                let node = self.nodes[id as usize];
                if node.dim == u32::MAX {
                    break;
                }
                let diff = q[node.dim as usize] - node.split;
                let (near, far) = if diff < 0.0 {
                    (node.a, node.b)
                } else {
                    (node.b, node.a)
                };
                heap.push(Bin(bound.max(diff * diff), far));
                id = near;
            }
            let node = self.nodes[id as usize];
            for at in node.a as usize..node.b as usize {
                let p = self.order[at];
                let row = &self.points[at * self.d..(at + 1) * self.d];
                let dist: f32 = row.iter().zip(q).map(|(a, b)| (a - b) * (a - b)).sum();
                seen += 1;
                if best.len() < k || dist < best[best.len() - 1].0 {
                    let at = best.partition_point(|e| e.0 <= dist);
                    best.insert(at, (dist, p));
                    best.truncate(k);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pca_finds_the_dominant_direction() {
        // Points along (1, 2, 0) with a little spread along z.
        let pca = Pca::fit(200, 3, 1, |i, out| {
            let t = i as f32 / 10.0 - 10.0;
            out.copy_from_slice(&[t, 2.0 * t, ((i * 7) % 5) as f32 * 0.01]);
        });
        let mut p = [0f32; 1];
        pca.project(&[1.0 + pca.mean[0], 2.0 + pca.mean[1], pca.mean[2]], &mut p);
        assert!((p[0].abs() - 5f32.sqrt()).abs() < 1e-3, "{p:?}");
    }

    #[test]
    fn search_with_full_budget_is_exact() {
        let d = 4;
        let n = 500;
        let pts: Vec<f32> = (0..n * d)
            .map(|i| (crate::rng::mix64(i as u64) % 1000) as f32 / 1000.0)
            .collect();
        let tree = KdTree::build(&pts, d);
        let (mut best, mut heap) = (Vec::new(), BinaryHeap::new());
        for qi in 0..20 {
            let q: Vec<f32> = (0..d)
                .map(|k| (crate::rng::mix64(9999 + (qi * d + k) as u64) % 1000) as f32 / 1000.0)
                .collect();
            tree.search(&q, 3, usize::MAX, &mut best, &mut heap);
            let mut all: Vec<(f32, u32)> = (0..n)
                .map(|p| {
                    let row = &pts[p * d..(p + 1) * d];
                    (
                        row.iter().zip(&q).map(|(a, b)| (a - b) * (a - b)).sum(),
                        p as u32,
                    )
                })
                .collect();
            all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            assert_eq!(
                best.iter().map(|e| e.0).collect::<Vec<_>>(),
                all[..3].iter().map(|e| e.0).collect::<Vec<_>>()
            );
        }
    }
}
