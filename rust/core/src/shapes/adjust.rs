//! Shape adjustment (Rosenberger et al. 2009; thesis §3.6.3): every matched exemplar patch is
//! laid over its synthesised boundary pixel and votes, with weight
//! `1 / (1 + D(x_S, x_E))` times a Gaussian falloff, for the label it shows at each pixel it
//! covers (Eq. 3.10; for two labels the signed indicator is the difference of the two
//! votes). Then each voted pixel takes a label so that every label keeps its target area:
//! the dynamic threshold of the thesis, generalised to `k` labels. Pairs (pixel, label) are
//! taken in order of the label's share of the pixel's votes, while the label has area left.
//!
//! Votes are gathered row by row (each output row sums the patches that cover it, in a fixed
//! order), so they are bit-identical for any thread count.

use rayon::prelude::*;

use super::patches::{coord, Geometry, Patch, MAX_PATCH};
use crate::rng::mix64;

/// The Gaussian falloff over a `p × p` patch, `σ = p / 4`.
#[must_use]
pub fn falloff(p: usize) -> Vec<f32> {
    let r = (p / 2) as f32;
    let s2 = 2.0 * (p as f32 / 4.0).max(0.5).powi(2);
    (0..p * p)
        .map(|i| {
            let (dy, dx) = ((i / p) as f32 - r, (i % p) as f32 - r);
            (-(dy * dy + dx * dx) / s2).exp()
        })
        .collect()
}

/// Matched patches laid over a map: `centres` (raster order) with their exemplar patch and
/// its distance.
pub struct Overlay<'a> {
    /// Boundary pixels of the synthesised map, ascending.
    pub centres: &'a [u32],
    /// The exemplar patch matched to each centre (as rotated when matched).
    pub patches: &'a [Patch],
    /// The distance of each match.
    pub dists: &'a [u32],
}

/// Votes of one row: `(pixel, label, share, vote)` for every voted pixel and label with a
/// positive vote, and which pixels got any vote.
pub struct RowVotes {
    /// `(pixel, label, share of the pixel's votes, vote)`.
    pub entries: Vec<(u32, u8, f32, f32)>,
    /// Whether each pixel of the row got a vote.
    pub voted: Vec<bool>,
}

/// Gathers the votes of `ov` on an `h × w` map with `k` labels.
#[must_use]
pub fn votes(
    g: &Geometry,
    ov: &Overlay<'_>,
    h: usize,
    w: usize,
    k: usize,
    wrap: bool,
    fall: &[f32],
) -> Vec<RowVotes> {
    let p = g.p;
    let r = (p / 2) as isize;
    let row_start: Vec<usize> = (0..=h)
        .map(|y| ov.centres.partition_point(|&c| (c as usize) < y * w))
        .collect();
    (0..h)
        .into_par_iter()
        .map(|y| {
            let mut acc = vec![0f32; w * k];
            let mut voted = vec![false; w];
            for dy in -r..=r {
                let sy = y as isize - dy;
                if !wrap && (sy < 0 || sy >= h as isize) {
                    continue;
                }
                let sy = coord(sy, h, true);
                for c in row_start[sy]..row_start[sy + 1] {
                    let sx = ov.centres[c] as usize % w;
                    let weight = 1.0 / (1.0 + ov.dists[c] as f32);
                    let patch = &ov.patches[c];
                    let row_bit = ((dy + r) as usize) * p;
                    // This patch row's labels, all planes at once.
                    let mut labels = [0u8; MAX_PATCH];
                    for j in 0..g.planes {
                        let bits = (patch.0[j] >> row_bit) as u32;
                        for (dx, l) in labels[..p].iter_mut().enumerate() {
                            *l |= (((bits >> dx) & 1) as u8) << j;
                        }
                    }
                    let wrow = &fall[row_bit..row_bit + p];
                    if sx >= r as usize && sx + (r as usize) < w {
                        // Interior: no wrapping or clipping.
                        let x0 = sx - r as usize;
                        for (i, (&l, &f)) in labels[..p].iter().zip(wrow).enumerate() {
                            let l = l as usize;
                            if l < k {
                                acc[(x0 + i) * k + l] += weight * f;
                                voted[x0 + i] = true;
                            }
                        }
                        continue;
                    }
                    for dx in -r..=r {
                        let x = sx as isize + dx;
                        if !wrap && (x < 0 || x >= w as isize) {
                            continue;
                        }
                        let x = coord(x, w, true);
                        let i = (dx + r) as usize;
                        let l = labels[i] as usize;
                        if l < k {
                            acc[x * k + l] += weight * wrow[i];
                            voted[x] = true;
                        }
                    }
                }
            }
            let mut entries = Vec::new();
            for x in 0..w {
                if !voted[x] {
                    continue;
                }
                let v = &acc[x * k..(x + 1) * k];
                let total: f32 = v.iter().sum();
                for (l, &vl) in v.iter().enumerate() {
                    if vl > 0.0 {
                        entries.push(((y * w + x) as u32, l as u8, vl / total, vl));
                    }
                }
            }
            RowVotes { entries, voted }
        })
        .collect()
}

/// The adjusted map: voted, allowed pixels take labels so that label `l` covers
/// `targets[l]` allowed pixels where possible; the rest keep theirs. Returns the new map and
/// how many pixels changed. `key` keys the random tie-breaks.
#[must_use]
pub fn decide(
    map: &[u8],
    rows: Vec<RowVotes>,
    allowed: Option<&[bool]>,
    k: usize,
    targets: &[usize],
    key: u64,
) -> (Vec<u8>, usize) {
    let ok = |i: usize| allowed.is_none_or(|a| a[i]);
    let voted: Vec<bool> = rows.iter().flat_map(|r| r.voted.iter().copied()).collect();
    let mut cap: Vec<i64> = targets.iter().map(|&t| t as i64).collect();
    for (i, &l) in map.iter().enumerate() {
        if ok(i) && !voted[i] {
            cap[l as usize] -= 1;
        }
    }
    // Highest share first, then strongest vote, then a random order (not raster order, which
    // would grow shapes towards the top-left). Keys are built once, not per comparison.
    let mut order: Vec<(u32, u32, u64, u32, u8)> = rows
        .into_iter()
        .flat_map(|r| r.entries)
        .filter(|e| ok(e.0 as usize))
        .map(|e| {
            (
                u32::MAX - e.2.to_bits(),
                u32::MAX - e.3.to_bits(),
                mix64(key ^ (u64::from(e.0) * 64 + u64::from(e.1))),
                e.0,
                e.1,
            )
        })
        .collect();
    order.par_sort_unstable();
    let entries = order.into_iter().map(|(_, _, _, i, l)| (i, l));
    let mut out = map.to_vec();
    let mut done = vec![false; map.len()];
    for (i, l) in entries {
        let i = i as usize;
        if !done[i] && cap[l as usize] > 0 {
            out[i] = l;
            cap[l as usize] -= 1;
            done[i] = true;
        }
    }
    // Pixels whose voted labels were all full: keep their label if it has room, else take the
    // label with the most room left.
    for i in 0..map.len() {
        if !voted[i] || done[i] || !ok(i) {
            continue;
        }
        let cur = map[i] as usize;
        let l = if cap[cur] > 0 {
            cur
        } else {
            (0..k)
                .max_by_key(|&l| (cap[l], std::cmp::Reverse(l)))
                .unwrap_or(cur)
        };
        if cap[l] > 0 {
            cap[l] -= 1;
        }
        out[i] = l as u8;
    }
    let changed = out.iter().zip(map).filter(|(a, b)| a != b).count();
    (out, changed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn votes_follow_the_patches_and_areas_match_targets() {
        // A vertical edge voted by patches that put it two pixels further right: the shape
        // moves right and keeps the target area.
        let (h, w, p) = (12usize, 12usize, 5usize);
        let g = Geometry::new(p, 2);
        let map: Vec<u8> = (0..h * w).map(|i| u8::from(i % w >= 6)).collect();
        let shifted: Vec<u8> = (0..h * w).map(|i| u8::from(i % w >= 8)).collect();
        let centres = super::super::patches::boundary(&map, h, w, false);
        let patches: Vec<Patch> = centres
            .iter()
            .map(|&c| g.extract(&shifted, h, w, c as usize / w, c as usize % w, false))
            .collect();
        let dists = vec![0u32; centres.len()];
        let ov = Overlay {
            centres: &centres,
            patches: &patches,
            dists: &dists,
        };
        let fall = falloff(p);
        let rows = votes(&g, &ov, h, w, 2, false, &fall);
        let target = (h * w / 2) - 2 * h;
        let (out, changed) = decide(&map, rows, None, 2, &[h * w - target, target], 1);
        assert_eq!(
            out.iter().map(|&l| usize::from(l == 1)).sum::<usize>(),
            target
        );
        assert_eq!(changed, 2 * h);
        assert_eq!(out, shifted);
    }
}
