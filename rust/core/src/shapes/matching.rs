//! Quota-balanced greedy boundary patch matching (Rosenberger et al. 2009; thesis §3.6.2).
//!
//! Every synthesised boundary patch gets one exemplar boundary patch. With
//! `|B_S| = Q·|B_E| + R`, the thesis uses each exemplar patch exactly `Q` times, or `Q + 1`
//! times if it is among `R` chosen at random, so the output uses the exemplar's boundaries
//! evenly. phloem allows [`QUOTA_SLACK`] more uses per patch, so the quota caps how often a
//! patch is used without forcing rare ones in ([`quotas`] with slack 0 is the thesis' rule).
//! The greedy assignment takes the closest (synthesised, exemplar) pairs first: each round
//! every unmatched synthesised patch proposes its `k` nearest exemplar patches that still
//! have quota, the proposals are accepted in order of distance while quota lasts, and the
//! rest try again among the patches with quota left.
//!
//! Nearest patches come from an [`Index`]: exemplar patches under their four rotations,
//! sorted by how many pixels carry one key label in the left columns and in the rest. Those
//! counts differ by at most the distance between two patches, so a search that walks
//! outwards from the query's counts stops as soon as the count gap reaches the `k`-th best
//! distance ([`Index::knn`], exact). Above [`EXACT_WORK`] the first round's candidates come
//! from a PatchMatch-style search instead ([`propagate`]). Identical queries are searched
//! once and exact results cached for the level. Searches run in parallel; each is sequential,
//! draws from its own random stream and breaks ties on fixed indices, so the result does not
//! depend on the thread count.

use std::collections::HashMap;

use rayon::prelude::*;

use super::patches::{coord, Geometry, Patch};
use super::Rotations;
use crate::rng::Rng;

/// Marks an unmatched patch.
pub const NONE: u32 = u32::MAX;

/// Extra uses per exemplar patch on top of the thesis' quota (see [`quotas`]). The exact
/// quota forces every exemplar patch into the output, rare and noisy ones too, which then
/// stamp specks and holes all over it; as a cap it still keeps any patch from dominating.
pub const QUOTA_SLACK: u32 = 3;

/// Candidates kept per query in one round.
pub const K: usize = 4;

/// Exact search while queries × entries stays below this; above it, propagation and
/// random samples.
pub const EXACT_WORK: usize = 2_000_000;

/// Random entries tried per query by the approximate searches.
const SAMPLES: usize = 48;

/// Inserts `cand` into the ascending top-`k` list `best` unless its entry is there already.
#[inline]
fn insert(best: &mut Vec<(u32, u32)>, cand: (u32, u32), k: usize) {
    if best.iter().any(|b| b.1 == cand.1) || (best.len() == k && cand >= best[k - 1]) {
        return;
    }
    let at = best.partition_point(|b| *b < cand);
    best.insert(at, cand);
    best.truncate(k);
}

/// Where an exemplar pixel's patch sits in an [`Index`].
#[derive(Clone, Debug)]
pub struct Lookup {
    /// Unique patch id of each exemplar pixel (`NONE` if not in the index).
    pub pix_id: Vec<u32>,
    /// Entry of each `(id, rotation)`, at `id * 4 + rotation` (`NONE` if absent).
    pub id_rot: Vec<u32>,
    /// Exemplar height.
    pub h: usize,
    /// Exemplar width.
    pub w: usize,
}

impl Lookup {
    /// The lookup of `index`, whose unique patch `pixel_ids[j].1` shows at exemplar pixel
    /// `pixel_ids[j].0`.
    #[must_use]
    pub fn new(index: &Index, pixel_ids: &[(u32, u32)], h: usize, w: usize) -> Self {
        let mut pix_id = vec![NONE; h * w];
        for &(px, id) in pixel_ids {
            pix_id[px as usize] = id;
        }
        let n_ids = index.ids.iter().map(|&i| i as usize + 1).max().unwrap_or(0);
        let mut id_rot = vec![NONE; n_ids * 4];
        for e in 0..index.len() {
            id_rot[index.ids[e] as usize * 4 + index.rots[e] as usize] = e as u32;
        }
        Self {
            pix_id,
            id_rot,
            h,
            w,
        }
    }
}

/// Approximate first-round candidates by PatchMatch-style search over boundary patches
/// (Barnes et al. 2009): each query tries the exemplar pixel its own pixel matched last
/// time, the pixels its 4 neighbours matched shifted back by their (rotated) offset, pixels at halving radii around its best, and random entries.
/// `field` holds, per output pixel (`h × w`), the exemplar pixel and rotation of its last
/// match (`NONE` if none); it is updated in place. Passes are Jacobi-style (each reads the
/// previous pass), and every query draws from its own random stream, so the result does not
/// depend on the thread count.
#[allow(clippy::too_many_arguments)]
pub fn propagate(
    index: &Index,
    lookup: &Lookup,
    rep: &[u32],
    queries: &[Patch],
    centres: &[u32],
    (h, w, wrap): (usize, usize, bool),
    field: &mut [(u32, u8)],
    passes: usize,
    k: usize,
    seed: u64,
) -> Vec<Vec<(u32, u32)>> {
    let n = queries.len();
    let mut best: Vec<Vec<(u32, u32)>> = vec![Vec::new(); n];
    let (eh, ew) = (lookup.h as isize, lookup.w as isize);
    for pass in 0..passes {
        if crate::cancel::cancelled() {
            break;
        }
        let f: &[(u32, u8)] = field;
        best = std::mem::take(&mut best)
            .into_par_iter()
            .enumerate()
            .map(|(i, mut b)| {
                let q = &queries[i];
                let c = centres[i] as usize;
                let (y, x) = ((c / w) as isize, (c % w) as isize);
                let mut rng = Rng::keyed(seed, pass as u64, c as u64);
                let try_px = |b: &mut Vec<(u32, u32)>, py: isize, px: isize, rot: u8| {
                    if py < 0 || px < 0 || py >= eh || px >= ew {
                        return;
                    }
                    let id = lookup.pix_id[(py * ew + px) as usize];
                    if id == NONE {
                        return;
                    }
                    let e = lookup.id_rot[id as usize * 4 + rot as usize];
                    if e != NONE && !b.iter().any(|c| c.1 == e) {
                        insert(b, (index.dist(q, e as usize), e), k);
                    }
                };
                if f[c].0 != NONE {
                    let (p, r) = f[c];
                    try_px(
                        &mut b,
                        (p as usize / lookup.w) as isize,
                        (p as usize % lookup.w) as isize,
                        r,
                    );
                }
                for (dy, dx) in [(-1isize, 0isize), (0, -1), (0, 1), (1, 0)] {
                    let (ny, nx) = (y + dy, x + dx);
                    if !wrap && (ny < 0 || nx < 0 || ny >= h as isize || nx >= w as isize) {
                        continue;
                    }
                    let nb = coord(ny, h, true) * w + coord(nx, w, true);
                    let (p, r) = f[nb];
                    if p == NONE {
                        continue;
                    }
                    let (py, px) = (
                        (p as usize / lookup.w) as isize,
                        (p as usize % lookup.w) as isize,
                    );
                    // The entry shows the exemplar turned `r` times by 90°, so the step from
                    // the neighbour back to this pixel turns with it.
                    let (oy, ox) = match r {
                        0 => (dy, dx),
                        1 => (-dx, dy),
                        2 => (-dy, -dx),
                        _ => (dx, -dy),
                    };
                    try_px(&mut b, py - oy, px - ox, r);
                }
                if let Some(&(_, e)) = b.first() {
                    let p = rep[index.ids[e as usize] as usize] as usize;
                    let (py, px) = ((p / lookup.w) as isize, (p % lookup.w) as isize);
                    let r = index.rots[e as usize];
                    let mut radius = eh.max(ew);
                    while radius >= 1 {
                        let oy = rng.range_inclusive(-(radius as i64), radius as i64) as isize;
                        let ox = rng.range_inclusive(-(radius as i64), radius as i64) as isize;
                        try_px(&mut b, py + oy, px + ox, r);
                        radius /= 2;
                    }
                }
                // Random entries cost a cache miss each: many only on a cold start (more than two
                // passes), a couple otherwise, where the neighbours' matches carry the search.
                let samples = if pass == 0 && passes > 2 {
                    SAMPLES / 3
                } else {
                    2
                };
                for _ in 0..samples {
                    let e = rng.below(index.len() as u64) as u32;
                    insert(&mut b, (index.dist(q, e as usize), e), k);
                }
                b
            })
            .collect();
        for (i, b) in best.iter().enumerate() {
            if let Some(&(_, e)) = b.first() {
                field[centres[i] as usize] =
                    (rep[index.ids[e as usize] as usize], index.rots[e as usize]);
            }
        }
    }
    best
}

/// Rounds of the greedy assignment before the last few patches take any free quota.
const MAX_ROUNDS: usize = 64;

/// Exemplar patches under their rotations, sorted for pruned nearest-neighbour search.
#[derive(Clone, Debug)]
pub struct Index {
    /// The (rotated) patch of each entry.
    pub patches: Vec<Patch>,
    /// The exemplar patch (unique id) each entry comes from.
    pub ids: Vec<u32>,
    /// How many 90° turns each entry is rotated by.
    pub rots: Vec<u8>,
    /// Each entry's index in the full index (itself, unless this is a [`Index::subset`]).
    pub entry: Vec<u32>,
    /// The entries' bit planes back to back (`planes` words each): a third to a sixth of the
    /// memory of `patches`, so the searches' random reads miss the cache less.
    flat: Vec<u128>,
    planes: usize,
    /// `(left count << 16) | right count` of each entry, ascending.
    keys: Vec<u32>,
    key_label: u8,
    left: u128,
}

impl Index {
    /// The index of `unique` exemplar patches, each under the turns `rotations` allows.
    #[must_use]
    pub fn new(g: &Geometry, unique: &[Patch], rotations: Rotations, key_label: u8) -> Self {
        let turns = rotations.turns();
        let left = (0..g.p * g.p)
            .filter(|i| i % g.p < g.p / 2)
            .fold(0u128, |m, i| m | (1u128 << i));
        let mut e: Vec<(u32, u32, u8, Patch)> = Vec::with_capacity(unique.len() * turns.len());
        for (id, p) in unique.iter().enumerate() {
            let mut q = *p;
            let mut at = 0u8;
            for &r in turns {
                while at < r {
                    q = g.rotate(&q);
                    at += 1;
                }
                let m = g.label_mask(&q, key_label);
                let key = ((m & left).count_ones() << 16) | (m & !left).count_ones();
                e.push((key, id as u32, r, q));
            }
        }
        e.sort_unstable_by_key(|a| (a.0, a.1, a.2));
        Self {
            keys: e.iter().map(|a| a.0).collect(),
            ids: e.iter().map(|a| a.1).collect(),
            rots: e.iter().map(|a| a.2).collect(),
            flat: e
                .iter()
                .flat_map(|a| a.3 .0[..g.planes].iter().copied())
                .collect(),
            planes: g.planes,
            patches: e.iter().map(|a| a.3).collect(),
            entry: (0..e.len() as u32).collect(),
            key_label,
            left,
        }
    }

    /// Number of differing pixels between `q` and entry `i`.
    #[inline]
    #[must_use]
    pub fn dist(&self, q: &Patch, i: usize) -> u32 {
        let e = &self.flat[i * self.planes..(i + 1) * self.planes];
        let mut m = 0u128;
        for (a, b) in q.0.iter().zip(e) {
            m |= a ^ b;
        }
        m.count_ones()
    }

    /// Number of entries.
    #[must_use]
    pub fn len(&self) -> usize {
        self.keys.len()
    }

    /// Whether the index has no entries.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// The entries whose exemplar patch still has quota (`quota[id] > 0`).
    #[must_use]
    pub fn subset(&self, quota: &[u32]) -> Self {
        let keep: Vec<usize> = (0..self.len())
            .filter(|&i| quota[self.ids[i] as usize] > 0)
            .collect();
        Self {
            flat: keep
                .iter()
                .flat_map(|&i| {
                    self.flat[i * self.planes..(i + 1) * self.planes]
                        .iter()
                        .copied()
                })
                .collect(),
            planes: self.planes,
            patches: keep.iter().map(|&i| self.patches[i]).collect(),
            ids: keep.iter().map(|&i| self.ids[i]).collect(),
            rots: keep.iter().map(|&i| self.rots[i]).collect(),
            entry: keep.iter().map(|&i| self.entry[i]).collect(),
            keys: keep.iter().map(|&i| self.keys[i]).collect(),
            key_label: self.key_label,
            left: self.left,
        }
    }

    /// The two-part key of a patch: pixels of the key label in the left columns, and in the
    /// others.
    #[inline]
    fn key(&self, g: &Geometry, q: &Patch) -> (u32, u32) {
        let m = g.label_mask(q, self.key_label);
        ((m & self.left).count_ones(), (m & !self.left).count_ones())
    }

    /// The `k` nearest entries to `q` as `(distance, full-index entry)`, ascending by
    /// `(distance, position)`.
    #[must_use]
    pub fn knn(&self, g: &Geometry, q: &Patch, k: usize) -> Vec<(u32, u32)> {
        let (qa, qb) = self.key(g, q);
        let max_a = self.keys.last().map_or(0, |&x| x >> 16);
        let mut best: Vec<(u32, u32)> = Vec::with_capacity(k + 1);
        let worst = |best: &Vec<(u32, u32)>| {
            if best.len() == k {
                best[k - 1].0
            } else {
                u32::MAX
            }
        };
        // Visit the blocks of equal left count in order of their gap to the query's, and
        // inside a block walk outwards from the query's right count; the sum of the two gaps
        // is a lower bound of the distance.
        for delta in 0..=qa.max(max_a) {
            if delta >= worst(&best) {
                break;
            }
            for a in [qa.checked_sub(delta), (delta > 0).then_some(qa + delta)]
                .into_iter()
                .flatten()
            {
                if a > max_a {
                    continue;
                }
                let lo_block = self.keys.partition_point(|&x| x < a << 16);
                let hi_block = self.keys.partition_point(|&x| x < (a + 1) << 16);
                let start = lo_block
                    + self.keys[lo_block..hi_block].partition_point(|&x| (x & 0xffff) < qb);
                let (mut lo, mut hi) = (start, start);
                loop {
                    let w = worst(&best);
                    let dlo = if lo > lo_block {
                        qb - (self.keys[lo - 1] & 0xffff)
                    } else {
                        u32::MAX
                    };
                    let dhi = if hi < hi_block {
                        (self.keys[hi] & 0xffff) - qb
                    } else {
                        u32::MAX
                    };
                    let i = if dlo <= dhi {
                        if dlo == u32::MAX || delta + dlo >= w {
                            break;
                        }
                        lo -= 1;
                        lo
                    } else {
                        if delta + dhi >= w {
                            break;
                        }
                        hi += 1;
                        hi - 1
                    };
                    let d = self.dist(q, i);
                    let cand = (d, i as u32);
                    if best.len() < k || cand < best[k - 1] {
                        let at = best.partition_point(|b| *b < cand);
                        best.insert(at, cand);
                        best.truncate(k);
                    }
                }
            }
        }
        best.into_iter()
            .map(|(d, i)| (d, self.entry[i as usize]))
            .collect()
    }
}

/// Quota of each exemplar patch: `mult[u]` copies of patch `u` in the exemplar, `n_s`
/// synthesised patches to serve. With `n_s = Q·Σmult + R`, every copy serves `Q` and `R`
/// copies drawn at random (from `seed`) one more, so the quotas sum to `n_s` (the thesis'
/// exact quota); `slack` more uses per copy turn it into a cap.
#[must_use]
pub fn quotas(n_s: usize, mult: &[u32], slack: u32, seed: u64) -> Vec<u32> {
    let n_e: usize = mult.iter().map(|&m| m as usize).sum();
    if n_e == 0 {
        return vec![0; mult.len()];
    }
    let (q, r) = ((n_s / n_e) as u32, n_s % n_e);
    let mut out: Vec<u32> = mult.iter().map(|&m| m * (q + slack)).collect();
    let mut inst: Vec<u32> = mult
        .iter()
        .enumerate()
        .flat_map(|(u, &m)| std::iter::repeat_n(u as u32, m as usize))
        .collect();
    let mut rng = Rng::keyed(seed, 0x9007a, n_s as u64);
    for i in 0..r {
        let j = i + rng.below((n_e - i) as u64) as usize;
        inst.swap(i, j);
        out[inst[i] as usize] += 1;
    }
    out
}

/// One greedy round: `edges` are `(distance, query, entry)`; in ascending order, a query
/// without a match takes the entry if its exemplar patch has quota left.
pub fn assign(
    edges: &mut [(u32, u32, u32)],
    ids: &[u32],
    quota: &mut [u32],
    out: &mut [(u32, u32)],
) {
    edges.par_sort_unstable();
    for &(d, s, e) in edges.iter() {
        let id = ids[e as usize] as usize;
        if out[s as usize].0 == NONE && quota[id] > 0 {
            out[s as usize] = (e, d);
            quota[id] -= 1;
        }
    }
}

/// The first-round candidates of [`match_all`] by exact search: the `k` nearest entries of
/// each query. `cache` holds results per query patch, valid while `index` is.
#[allow(clippy::implicit_hasher)]
pub fn exact_candidates(
    g: &Geometry,
    index: &Index,
    queries: &[Patch],
    k: usize,
    cache: &mut HashMap<Patch, Vec<(u32, u32)>>,
) -> Vec<Vec<(u32, u32)>> {
    let mut uniq: Vec<Patch> = queries.to_vec();
    uniq.par_sort_unstable();
    uniq.dedup();
    let missing: Vec<Patch> = uniq
        .into_iter()
        .filter(|p| !cache.contains_key(p))
        .collect();
    let found: Vec<Vec<(u32, u32)>> = missing.par_iter().map(|q| index.knn(g, q, k)).collect();
    cache.extend(missing.into_iter().zip(found));
    queries.iter().map(|q| cache[q].clone()).collect()
}

/// Matches every query to an index entry under the quotas: `(entry, distance)` per query.
/// `first` holds each query's candidates `(distance, entry)` for the first round; later
/// rounds search the entries with quota left, exactly while that is cheap, else among
/// random samples (keyed by `seed`).
#[must_use]
pub fn match_all(
    g: &Geometry,
    index: &Index,
    queries: &[Patch],
    mut quota: Vec<u32>,
    k: usize,
    first: &[Vec<(u32, u32)>],
    seed: u64,
) -> Vec<(u32, u32)> {
    let n = queries.len();
    let mut out = vec![(NONE, 0u32); n];
    if index.is_empty() || n == 0 {
        return out;
    }
    let mut edges: Vec<(u32, u32, u32)> = first
        .iter()
        .enumerate()
        .flat_map(|(s, c)| c.iter().map(move |&(d, e)| (d, s as u32, e)))
        .collect();
    assign(&mut edges, &index.ids, &mut quota, &mut out);
    for round in 0.. {
        if crate::cancel::cancelled() {
            break;
        }
        let left: Vec<u32> = (0..n as u32)
            .filter(|&s| out[s as usize].0 == NONE)
            .collect();
        if left.is_empty() {
            break;
        }
        let sub = index.subset(&quota);
        if sub.is_empty() {
            break;
        }
        if round >= MAX_ROUNDS {
            // A long tail of contested patches: each takes its nearest patch with quota left.
            for &s in &left {
                let cands = sub.knn(g, &queries[s as usize], sub.len());
                if let Some(&(d, e)) = cands
                    .iter()
                    .find(|c| quota[index.ids[c.1 as usize] as usize] > 0)
                {
                    out[s as usize] = (e, d);
                    quota[index.ids[e as usize] as usize] -= 1;
                }
            }
            break;
        }
        let mut lq: Vec<Patch> = left.iter().map(|&s| queries[s as usize]).collect();
        lq.par_sort_unstable();
        lq.dedup();
        let exact = lq.len() * sub.len() <= EXACT_WORK;
        let res: HashMap<Patch, Vec<(u32, u32)>> = lq
            .par_iter()
            .enumerate()
            .map(|(j, q)| {
                if exact {
                    return (*q, sub.knn(g, q, k));
                }
                let mut rng = Rng::keyed(seed, 0x5ab + round as u64, j as u64);
                let mut best: Vec<(u32, u32)> = Vec::with_capacity(k + 1);
                for _ in 0..SAMPLES {
                    let i = rng.below(sub.len() as u64) as usize;
                    insert(&mut best, (sub.dist(q, i), sub.entry[i]), k);
                }
                (*q, best)
            })
            .collect();
        let mut edges: Vec<(u32, u32, u32)> = left
            .iter()
            .flat_map(|&s| {
                res[&queries[s as usize]]
                    .iter()
                    .map(move |&(d, e)| (d, s, e))
            })
            .collect();
        assign(&mut edges, &index.ids, &mut quota, &mut out);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn random_patches(g: &Geometry, n: usize, seed: u64, k: u64) -> Vec<Patch> {
        let mut r = Rng::keyed(seed, 1, 2);
        (0..n)
            .map(|_| {
                let map: Vec<u8> = (0..g.p * g.p).map(|_| r.below(k) as u8).collect();
                g.extract(&map, g.p, g.p, g.p / 2, g.p / 2, false)
            })
            .collect()
    }

    #[test]
    fn knn_equals_brute_force() {
        for (k_lab, rot) in [
            (2u64, Rotations::All),
            (3, Rotations::None),
            (5, Rotations::Half),
        ] {
            let g = Geometry::new(5, k_lab as usize);
            let ex = random_patches(&g, 60, 1, k_lab);
            let idx = Index::new(&g, &ex, rot, 1);
            for q in random_patches(&g, 30, 2, k_lab) {
                let mut all: Vec<(u32, u32)> = (0..idx.len())
                    .map(|i| (g.dist(&q, &idx.patches[i]), i as u32))
                    .collect();
                all.sort_unstable();
                let got = idx.knn(&g, &q, 3);
                let dists: Vec<u32> = got.iter().map(|a| a.0).collect();
                let want: Vec<u32> = all[..3].iter().map(|a| a.0).collect();
                assert_eq!(dists, want);
                for &(d, e) in &got {
                    assert_eq!(g.dist(&q, &idx.patches[e as usize]), d);
                }
            }
        }
    }

    #[test]
    fn quotas_sum_and_balance() {
        let mult = [1, 3, 2, 1];
        for n_s in [0, 3, 7, 8, 23] {
            let q = quotas(n_s, &mult, 0, 5);
            assert_eq!(q.iter().sum::<u32>() as usize, n_s);
            let base = (n_s / 7) as u32;
            for (qu, m) in q.iter().zip(mult) {
                assert!(*qu >= base * m && *qu <= (base + 1) * m, "{q:?}");
            }
            let capped = quotas(n_s, &mult, 2, 5);
            for ((c, qu), m) in capped.iter().zip(&q).zip(mult) {
                assert_eq!(*c, qu + 2 * m);
            }
        }
    }

    /// The thesis' greedy, by brute force: repeatedly take the globally closest pair of an
    /// unmatched query and an entry whose patch has quota.
    fn brute_force(
        g: &Geometry,
        idx: &Index,
        qs: &[Patch],
        mut quota: Vec<u32>,
    ) -> Vec<(u32, u32)> {
        let mut out = vec![(NONE, 0); qs.len()];
        loop {
            let mut best: Option<(u32, u32, u32)> = None;
            for (s, q) in qs.iter().enumerate() {
                if out[s].0 != NONE {
                    continue;
                }
                for e in 0..idx.len() {
                    if quota[idx.ids[e] as usize] == 0 {
                        continue;
                    }
                    let c = (g.dist(q, &idx.patches[e]), s as u32, e as u32);
                    if best.is_none_or(|b| c < b) {
                        best = Some(c);
                    }
                }
            }
            let Some((d, s, e)) = best else { break };
            out[s as usize] = (e, d);
            quota[idx.ids[e as usize] as usize] -= 1;
        }
        out
    }

    #[test]
    fn greedy_respects_quota_and_matches_brute_force() {
        let g = Geometry::new(3, 2);
        let ex = random_patches(&g, 7, 3, 2);
        let idx = Index::new(&g, &ex, Rotations::All, 1);
        let qs = random_patches(&g, 23, 4, 2);
        let mult = vec![1u32; ex.len()];
        let quota = quotas(qs.len(), &mult, 0, 9);
        // With every entry as a candidate the first round is the brute-force greedy.
        let mut cache = HashMap::new();
        let first = exact_candidates(&g, &idx, &qs, idx.len(), &mut cache);
        let got = match_all(&g, &idx, &qs, quota.clone(), idx.len(), &first, 0);
        assert_eq!(got, brute_force(&g, &idx, &qs, quota.clone()));
        // With few candidates it takes more rounds, but every query is matched and every
        // exemplar patch is used exactly its quota.
        for k in [1, 2, 4] {
            let mut cache = HashMap::new();
            let first = exact_candidates(&g, &idx, &qs, k, &mut cache);
            let got = match_all(&g, &idx, &qs, quota.clone(), k, &first, 0);
            let mut used = vec![0u32; ex.len()];
            for (s, &(e, d)) in got.iter().enumerate() {
                assert_ne!(e, NONE);
                assert_eq!(g.dist(&qs[s], &idx.patches[e as usize]), d);
                used[idx.ids[e as usize] as usize] += 1;
            }
            assert_eq!(used, quota);
        }
    }
}
