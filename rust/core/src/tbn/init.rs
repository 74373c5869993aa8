//! Initial outputs of texture-by-numbers (Laitoch 2018, §3.4): random copies of same-label
//! exemplar pixels (§3.4.1), and the "smart" initialisation of Fan et al. 2012 after the
//! first pass of Bonneel et al. 2010 (§3.4.2): chamfer 3-4 distance maps of both label maps
//! (Borgefors 1988), the label-and-distance metric of Eq. 3.6, and flood-fill region growth
//! from random seeds that copies coherent exemplar regions.

use std::sync::atomic::{AtomicU32, Ordering};

use rayon::prelude::*;

use crate::patch::NONE;
use crate::rng::Rng;

/// Eq. 3.6 weight of label mismatches against distance-map differences.
pub const SMART_LABEL_WEIGHT: f32 = 90.0;
/// Chamfer distance given to pixels of a map with a single label (no border to measure to).
pub const FAR: u32 = 1 << 20;

/// Chamfer 3-4 distance transform (Borgefors 1988) of a label map: for every pixel, the
/// distance, in thirds of a pixel, to the nearest border pixel (one whose 4-neighbour has a
/// different label; border pixels are 0). Steps cost 3 along an axis and 4 diagonally; two
/// raster passes. A map with a single label is [`FAR`] everywhere.
#[must_use]
pub fn chamfer34(labels: &[u32], h: usize, w: usize) -> Vec<u32> {
    let mut d = vec![FAR; h * w];
    for y in 0..h {
        for x in 0..w {
            let l = labels[y * w + x];
            let border = (y > 0 && labels[(y - 1) * w + x] != l)
                || (y + 1 < h && labels[(y + 1) * w + x] != l)
                || (x > 0 && labels[y * w + x - 1] != l)
                || (x + 1 < w && labels[y * w + x + 1] != l);
            if border {
                d[y * w + x] = 0;
            }
        }
    }
    let at = |d: &[u32], y: i64, x: i64| -> u32 {
        if y < 0 || x < 0 || y >= h as i64 || x >= w as i64 {
            FAR
        } else {
            d[y as usize * w + x as usize]
        }
    };
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            let i = y as usize * w + x as usize;
            let v = d[i]
                .min(at(&d, y, x - 1) + 3)
                .min(at(&d, y - 1, x) + 3)
                .min(at(&d, y - 1, x - 1) + 4)
                .min(at(&d, y - 1, x + 1) + 4);
            d[i] = v.min(FAR);
        }
    }
    for y in (0..h as i64).rev() {
        for x in (0..w as i64).rev() {
            let i = y as usize * w + x as usize;
            let v = d[i]
                .min(at(&d, y, x + 1) + 3)
                .min(at(&d, y + 1, x) + 3)
                .min(at(&d, y + 1, x + 1) + 4)
                .min(at(&d, y + 1, x - 1) + 4);
            d[i] = v.min(FAR);
        }
    }
    d
}

/// Exemplar pixels of each label.
#[must_use]
pub fn pixels_by_label(labels: &[u32], n_labels: usize) -> Vec<Vec<u32>> {
    let mut by = vec![Vec::new(); n_labels];
    for (i, &l) in labels.iter().enumerate() {
        by[l as usize].push(i as u32);
    }
    by
}

/// §3.4.1: every output pixel copies a random exemplar pixel of its own label.
#[must_use]
pub fn random_init(labels_out: &[u32], by_label: &[Vec<u32>], seed: u64, key: u64) -> Vec<u32> {
    labels_out
        .par_iter()
        .enumerate()
        .map(|(i, &l)| pick(by_label, l, seed, key, i))
        .collect()
}

/// A random exemplar pixel of label `l` for output pixel `i`, drawn from the stream
/// `(seed, key, i)`.
#[inline]
pub(crate) fn pick(by_label: &[Vec<u32>], l: u32, seed: u64, key: u64, i: usize) -> u32 {
    let list = &by_label[l as usize];
    list[Rng::keyed(seed, key, i as u64).below(list.len() as u64) as usize]
}

/// A label map with its chamfer distances (in pixels), for Eq. 3.6.
pub struct LabelMap<'a> {
    /// Compact labels.
    pub labels: &'a [u32],
    /// Chamfer distance to the nearest label border, in pixels.
    pub dist: Vec<f32>,
    /// Height.
    pub h: usize,
    /// Width.
    pub w: usize,
}

impl<'a> LabelMap<'a> {
    /// Computes the distance map of `labels`.
    #[must_use]
    pub fn new(labels: &'a [u32], h: usize, w: usize) -> Self {
        let dist = chamfer34(labels, h, w)
            .into_iter()
            .map(|v| v as f32 / 3.0)
            .collect();
        Self { labels, dist, h, w }
    }

    #[inline]
    fn at(&self, y: i64, x: i64) -> usize {
        let y = y.clamp(0, self.h as i64 - 1) as usize;
        let x = x.clamp(0, self.w as i64 - 1) as usize;
        y * self.w + x
    }
}

/// Eq. 3.6: `w ·` (label mismatches over the `p × p` neighbourhood) `+` the L2 norm of the
/// distance-map differences over it; neighbourhoods are clamped at the borders.
#[must_use]
pub fn eq36(a: &LabelMap<'_>, pa: usize, b: &LabelMap<'_>, pb: usize, r: i64) -> f32 {
    eq36_below(a, pa, b, pb, r, f32::INFINITY)
}

/// [`eq36`], or, as soon as a partial sum (checked after every row) exceeds `cutoff`, that
/// partial sum: a value above `cutoff` and at most Eq. 3.6. Values within `cutoff` are
/// bit-identical to [`eq36`]'s.
#[inline]
fn eq36_below(
    a: &LabelMap<'_>,
    pa: usize,
    b: &LabelMap<'_>,
    pb: usize,
    r: i64,
    cutoff: f32,
) -> f32 {
    let (ay, ax) = ((pa / a.w) as i64, (pa % a.w) as i64);
    let (by, bx) = ((pb / b.w) as i64, (pb % b.w) as i64);
    let mut mismatch = 0u32;
    let mut ssd = 0f32;
    for dy in -r..=r {
        for dx in -r..=r {
            let i = a.at(ay + dy, ax + dx);
            let j = b.at(by + dy, bx + dx);
            mismatch += u32::from(a.labels[i] != b.labels[j]);
            let d = a.dist[i] - b.dist[j];
            ssd += d * d;
        }
        let partial = SMART_LABEL_WEIGHT * mismatch as f32 + ssd.sqrt();
        if partial > cutoff {
            return partial;
        }
    }
    SMART_LABEL_WEIGHT * mismatch as f32 + ssd.sqrt()
}

/// §3.4.2: grows regions copied from the exemplar from random seeds until the output is
/// covered. For a seed `pB` (a random uncovered pixel) the exemplar pixel `pA` of the same
/// label nearest under Eq. 3.6 is found by exhaustive search; then a flood fill adds each
/// uncovered 4-neighbour `p'B` whose shifted counterpart `pA + (p'B − pB)` lies in the
/// exemplar, has `p'B`'s label and is closer than `t = (d(pA, pB) + 5) · 1.25`.
/// Every output pixel ends up referencing an exemplar pixel of its own label.
#[must_use]
pub fn smart_init(a: &LabelMap<'_>, b: &LabelMap<'_>, patch_size: usize, seed: u64) -> Vec<u32> {
    let r = (patch_size / 2) as i64;
    let n = b.h * b.w;
    let mut refs = vec![NONE; n];
    let mut uncovered: Vec<u32> = (0..n as u32).collect();
    let mut rng = Rng::keyed(seed, 0x5EED, 0);
    let mut stack = Vec::new();
    let mut remaining = n;
    while remaining > 0 && !crate::cancel::cancelled() {
        // A random uncovered pixel: draw from the list, dropping covered entries lazily.
        let pb = loop {
            let j = rng.below(uncovered.len() as u64) as usize;
            let c = uncovered.swap_remove(j);
            if refs[c as usize] == NONE {
                break c as usize;
            }
        };
        let lb = b.labels[pb];
        // Exhaustive, but a candidate stops once its partial sum exceeds the best distance
        // found so far by any thread. Only candidates strictly worse than the minimum stop,
        // so the result (ties to the lower index) is the same as without pruning.
        let best_bits = AtomicU32::new(f32::INFINITY.to_bits());
        let (best, dbest) = (0..a.labels.len())
            .into_par_iter()
            .filter(|&pa| a.labels[pa] == lb)
            .map(|pa| {
                // Non-negative floats order like their bit patterns.
                let cutoff = f32::from_bits(best_bits.load(Ordering::Relaxed));
                let d = eq36_below(a, pa, b, pb, r, cutoff);
                if d <= cutoff {
                    best_bits.fetch_min(d.to_bits(), Ordering::Relaxed);
                }
                (pa, d)
            })
            .reduce(
                || (usize::MAX, f32::INFINITY),
                |x, y| {
                    // Ties go to the lower index, so the result never depends on the split.
                    if y.1.total_cmp(&x.1).then(y.0.cmp(&x.0)).is_lt() {
                        y
                    } else {
                        x
                    }
                },
            );
        if best == usize::MAX {
            // No exemplar pixel has this label; the caller checks labels first.
            unreachable!("label {lb} is absent from the exemplar");
        }
        let t = (dbest + 5.0) * 1.25;
        let (oy, ox) = (
            (best / a.w) as i64 - (pb / b.w) as i64,
            (best % a.w) as i64 - (pb % b.w) as i64,
        );
        refs[pb] = best as u32;
        remaining -= 1;
        stack.push(pb);
        while let Some(q) = stack.pop() {
            let (qy, qx) = ((q / b.w) as i64, (q % b.w) as i64);
            for (dy, dx) in [(0i64, 1i64), (0, -1), (1, 0), (-1, 0)] {
                let (y, x) = (qy + dy, qx + dx);
                if y < 0 || x < 0 || y >= b.h as i64 || x >= b.w as i64 {
                    continue;
                }
                let pn = y as usize * b.w + x as usize;
                if refs[pn] != NONE {
                    continue;
                }
                let (ay, ax) = (y + oy, x + ox);
                if ay < 0 || ax < 0 || ay >= a.h as i64 || ax >= a.w as i64 {
                    continue;
                }
                let pa = ay as usize * a.w + ax as usize;
                if a.labels[pa] != b.labels[pn] || eq36(a, pa, b, pn, r) >= t {
                    continue;
                }
                refs[pn] = pa as u32;
                remaining -= 1;
                stack.push(pn);
            }
        }
    }
    refs
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute force: the minimum over border pixels of the 3-4 path length between two
    /// pixels `(a, b)` apart, `4·min(a, b) + 3·(max(a, b) − min(a, b))`.
    fn brute(labels: &[u32], h: usize, w: usize) -> Vec<u32> {
        let mut border = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let l = labels[y * w + x];
                let nb = [(0i64, 1i64), (0, -1), (1, 0), (-1, 0)]
                    .iter()
                    .any(|(dy, dx)| {
                        let (yy, xx) = (y as i64 + dy, x as i64 + dx);
                        yy >= 0
                            && xx >= 0
                            && yy < h as i64
                            && xx < w as i64
                            && labels[yy as usize * w + xx as usize] != l
                    });
                if nb {
                    border.push((y as i64, x as i64));
                }
            }
        }
        (0..h * w)
            .map(|i| {
                let (y, x) = ((i / w) as i64, (i % w) as i64);
                border
                    .iter()
                    .map(|(by, bx)| {
                        let (a, b) = ((y - by).abs(), (x - bx).abs());
                        (4 * a.min(b) + 3 * (a.max(b) - a.min(b))) as u32
                    })
                    .min()
                    .unwrap_or(FAR)
            })
            .collect()
    }

    #[test]
    fn chamfer_known_values() {
        // A 1-pixel island of label 1 in a 7×7 map: the island and its 4-neighbours are
        // border pixels; the rest follow 3 per axis step and 4 per diagonal step.
        let (h, w) = (7, 7);
        let mut l = vec![0u32; h * w];
        l[3 * w + 3] = 1;
        let d = chamfer34(&l, h, w);
        assert_eq!(d[3 * w + 3], 0);
        assert_eq!(d[3 * w + 4], 0);
        assert_eq!(d[2 * w + 2], 3); // diagonal of the island touches (2,3) and (3,2)
        assert_eq!(d[3 * w + 5], 3);
        assert_eq!(d[3 * w + 6], 6);
        assert_eq!(d[w + 1], 7);
        assert_eq!(d[0], 11);
        assert_eq!(chamfer34(&[2u32; 12], 3, 4), vec![FAR; 12]);
    }

    #[test]
    fn chamfer_equals_brute_force() {
        let (h, w) = (23, 31);
        let mut rng = Rng::keyed(1, 2, 3);
        // Blobs: a few random discs of label 1 and 2 on 0.
        let mut l = vec![0u32; h * w];
        for k in 0..6 {
            let (cy, cx, rad) = (
                rng.below(h as u64) as i64,
                rng.below(w as u64) as i64,
                2 + rng.below(5) as i64,
            );
            for y in 0..h as i64 {
                for x in 0..w as i64 {
                    if (y - cy).pow(2) + (x - cx).pow(2) <= rad * rad {
                        l[y as usize * w + x as usize] = 1 + k % 2;
                    }
                }
            }
        }
        assert_eq!(chamfer34(&l, h, w), brute(&l, h, w));
    }

    fn stripes(h: usize, w: usize, period: usize, phase: usize) -> Vec<u32> {
        (0..h * w)
            .map(|i| u32::from((i % w + phase) % period < period / 2))
            .collect()
    }

    #[test]
    fn smart_init_respects_labels_and_copies_regions() {
        let (eh, ew, h, w) = (30, 40, 36, 50);
        let la = stripes(eh, ew, 10, 0);
        let lb = stripes(h, w, 10, 3);
        let a = LabelMap::new(&la, eh, ew);
        let b = LabelMap::new(&lb, h, w);
        let refs = smart_init(&a, &b, 5, 7);
        assert!(refs
            .iter()
            .enumerate()
            .all(|(i, &e)| e != NONE && la[e as usize] == lb[i]));
        // Coherent: most horizontal neighbours are copied from horizontal exemplar neighbours.
        let coherent = (0..h * w)
            .filter(|&i| i % w + 1 < w && refs[i + 1] == refs[i] + 1)
            .count();
        assert!(coherent as f64 > 0.8 * (h * (w - 1)) as f64, "{coherent}");
        // Different seeds give different outputs.
        assert_ne!(refs, smart_init(&a, &b, 5, 8));
        // The same on one thread as on several (the pruned search is exact).
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        assert_eq!(refs, pool.install(|| smart_init(&a, &b, 5, 7)));
    }

    #[test]
    fn pruned_eq36_is_exact_within_the_cutoff() {
        let (h, w) = (24, 30);
        let (la, lb) = (stripes(h, w, 6, 0), stripes(h, w, 7, 2));
        let (a, b) = (LabelMap::new(&la, h, w), LabelMap::new(&lb, h, w));
        for (pa, pb) in [(0, 0), (37, 400), (301, 55), (719, 719)] {
            let full = eq36(&a, pa, &b, pb, 2);
            assert_eq!(
                eq36_below(&a, pa, &b, pb, 2, full).to_bits(),
                full.to_bits()
            );
            if full > 0.0 {
                let cut = eq36_below(&a, pa, &b, pb, 2, full * 0.5);
                assert!(cut > full * 0.5 && cut <= full, "{cut} {full}");
            }
        }
    }

    #[test]
    fn random_init_respects_labels() {
        let la = stripes(20, 20, 6, 0);
        let lb = stripes(25, 30, 4, 1);
        let by = pixels_by_label(&la, 2);
        let refs = random_init(&lb, &by, 3, 0);
        assert!(refs
            .iter()
            .enumerate()
            .all(|(i, &e)| la[e as usize] == lb[i]));
    }
}
