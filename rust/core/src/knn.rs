//! k nearest patches inside one exemplar, and the k-coherence candidate sets built from them
//! (Tong, Zhang, Liu, Wang, Shum 2002, "Synthesis of bidirectional texture functions on
//! arbitrary surfaces"; used by the texture-by-numbers solver of Laitoch 2018, §3.3.6).
//!
//! Every exemplar pixel has a patch: the exemplar is mirrored by `patch_size / 2` pixels at its
//! border, so pixels near the edge take part too. A pixel's neighbours exclude itself and every
//! pixel within `exclude` (Chebyshev distance) of it, so that the lists hold other places in
//! the exemplar rather than the same place shifted by one pixel.
//!
//! The thesis used FLANN's approximate search. phloem offers exact brute force and an
//! approximate search of its own: k-PatchMatch (Barnes et al. 2010, "The generalized
//! PatchMatch correspondence algorithm") with neighbour-of-neighbour enrichment. Its passes are
//! Jacobi-style (each reads only the previous pass), so the result is independent of threads.

// `#[inline(always)]` on the distance helpers is deliberate: only code inlined into
// `Pass::run_avx2` is compiled with AVX2 enabled.
#![allow(clippy::inline_always)]

use rayon::prelude::*;

#[cfg(target_arch = "x86_64")]
use crate::distance::Avx2;
use crate::distance::{avx2_enabled, Kernel, Portable};
use crate::error::{invalid, Result};
use crate::image::{mirror_pad, prescale, Image};
use crate::patch::NONE;
use crate::rng::Rng;

/// Parameters of [`knn`].
#[derive(Clone, Debug)]
pub struct KnnParams {
    /// Side of the square patches; odd. Default 7.
    pub patch_size: usize,
    /// Neighbours per pixel. Default 4.
    pub k: usize,
    /// Passes of the approximate search. Default 6.
    pub iterations: usize,
    /// Exact brute force instead of the approximate search (`O(N²)`; small exemplars only).
    pub exact: bool,
    /// Pixels within this Chebyshev distance of a pixel are not its neighbours. Default
    /// `patch_size / 2`.
    pub exclude: usize,
    /// Seed of every random choice.
    pub seed: u64,
}

impl Default for KnnParams {
    fn default() -> Self {
        Self {
            patch_size: 7,
            k: 4,
            iterations: 6,
            exact: false,
            exclude: 3,
            seed: 0,
        }
    }
}

/// The `k` nearest neighbours of every exemplar pixel, nearest first.
#[derive(Clone, Debug)]
pub struct Knn {
    /// Exemplar height.
    pub h: usize,
    /// Exemplar width.
    pub w: usize,
    /// Neighbours per pixel.
    pub k: usize,
    /// `h × w × k` flat exemplar indices.
    pub idx: Vec<u32>,
    /// `h × w × k` patch distances (weighted sums of squared differences).
    pub dist: Vec<f32>,
}

/// Moves exemplar pixel `e` by `(dy, dx)`: wrapped around an `eh × ew` exemplar, or [`NONE`]
/// when it leaves it without `wrap`.
#[inline]
#[must_use]
pub fn shift(e: u32, dy: i64, dx: i64, eh: usize, ew: usize, wrap: bool) -> u32 {
    if e == NONE {
        return NONE;
    }
    let (mut y, mut x) = ((e as usize / ew) as i64 + dy, (e as usize % ew) as i64 + dx);
    if wrap {
        y = y.rem_euclid(eh as i64);
        x = x.rem_euclid(ew as i64);
    } else if y < 0 || x < 0 || y >= eh as i64 || x >= ew as i64 {
        return NONE;
    }
    (y as usize * ew + x as usize) as u32
}

struct Padded {
    data: Vec<f32>,
    pw: usize,
    w: usize,
    c: usize,
    p: usize,
}

impl Padded {
    #[inline(always)]
    fn dist(&self, a: u32, b: u32, cutoff: f32) -> f32 {
        self.dist_with::<Portable>(a, b, cutoff)
    }

    /// Patch distance with early termination every other row (see `distance::Kernel`).
    #[inline(always)]
    fn dist_with<K: Kernel>(&self, a: u32, b: u32, cutoff: f32) -> f32 {
        let (ay, ax) = (a as usize / self.w, a as usize % self.w);
        let (by, bx) = (b as usize / self.w, b as usize % self.w);
        let len = self.p * self.c;
        let mut acc = K::zero();
        for k in 0..self.p {
            let a0 = ((ay + k) * self.pw + ax) * self.c;
            let b0 = ((by + k) * self.pw + bx) * self.c;
            K::add_row(&mut acc, &self.data[a0..a0 + len], &self.data[b0..b0 + len]);
            if k % 2 == 1 && k + 1 < self.p {
                let partial = K::total(&acc);
                if partial >= cutoff {
                    return partial;
                }
            }
        }
        K::total(&acc)
    }
}

/// What one pass of the search shares.
#[derive(Clone, Copy)]
struct Pass<'a> {
    pad: &'a Padded,
    h: usize,
    w: usize,
    k: usize,
    exclude: usize,
    prev: &'a [u32],
    radius0: i64,
    seed: u64,
    it: usize,
}

impl Pass<'_> {
    #[inline(always)]
    fn far(&self, a: usize, b: usize) -> bool {
        (a / self.w)
            .abs_diff(b / self.w)
            .max((a % self.w).abs_diff(b % self.w))
            > self.exclude
    }

    /// Brute force for pixel `a`.
    #[inline(always)]
    fn exact<K: Kernel>(&self, a: usize, d: &mut [f32], i: &mut [u32]) {
        let mut best = Best { d, i };
        for b in 0..self.h * self.w {
            if self.far(a, b) {
                let dd = self.pad.dist_with::<K>(a as u32, b as u32, best.worst());
                best.offer(b as u32, dd);
            }
        }
    }

    /// Offers `b` as a neighbour of `a`. A method, not a closure: a closure that the compiler
    /// does not inline is compiled without AVX2, and every intrinsic in it becomes a call.
    #[inline(always)]
    fn consider<K: Kernel>(&self, a: usize, b: u32, best: &mut Best<'_>) {
        if b != NONE && self.far(a, b as usize) {
            let dd = self.pad.dist_with::<K>(a as u32, b, best.worst());
            best.offer(b, dd);
        }
    }

    /// One approximate pass for pixel `a`: propagation, enrichment, random search.
    #[inline(always)]
    fn refine<K: Kernel>(&self, a: usize, d: &mut [f32], i: &mut [u32]) {
        let (h, w, k) = (self.h, self.w, self.k);
        let prev_i = self.prev;
        let mut best = Best { d, i };
        let (ay, ax) = ((a / w) as i64, (a % w) as i64);
        // Propagation from the 4-neighbours' lists, shifted back by the offset.
        for (oy, ox) in [(0i64, -1i64), (0, 1), (-1, 0), (1, 0)] {
            let (ny, nx) = (ay + oy, ax + ox);
            if ny < 0 || nx < 0 || ny >= h as i64 || nx >= w as i64 {
                continue;
            }
            for &b in &prev_i[(ny as usize * w + nx as usize) * k..][..k] {
                if b == NONE {
                    continue;
                }
                let (by, bx) = ((b as usize / w) as i64 - oy, (b as usize % w) as i64 - ox);
                if by >= 0 && bx >= 0 && by < h as i64 && bx < w as i64 {
                    self.consider::<K>(a, (by as usize * w + bx as usize) as u32, &mut best);
                }
            }
        }
        // Enrichment: neighbours of neighbours.
        for j in 0..k {
            let b = prev_i[a * k + j];
            if b == NONE {
                continue;
            }
            for &b2 in &prev_i[b as usize * k..][..k] {
                self.consider::<K>(a, b2, &mut best);
            }
        }
        // Random search around the current best, radius halving.
        let mut rng = Rng::keyed(self.seed, self.it as u64, a as u64);
        let b0 = best.i[0];
        if b0 != NONE {
            let (by, bx) = ((b0 as usize / w) as i64, (b0 as usize % w) as i64);
            let mut rad = self.radius0;
            while rad >= 1 {
                let y = rng.range_inclusive((by - rad).max(0), (by + rad).min(h as i64 - 1));
                let x = rng.range_inclusive((bx - rad).max(0), (bx + rad).min(w as i64 - 1));
                self.consider::<K>(a, (y as usize * w + x as usize) as u32, &mut best);
                rad /= 2;
            }
        }
    }

    /// Runs `exact` or `refine` for pixel `a` with the fastest kernel the CPU has.
    fn run(&self, exact: bool, fast: bool, a: usize, d: &mut [f32], i: &mut [u32]) {
        #[cfg(target_arch = "x86_64")]
        if fast {
            // SAFETY: `fast` is only true when the CPU supports AVX2 (`avx2_enabled`).
            unsafe { self.run_avx2(exact, a, d, i) };
            return;
        }
        let _ = fast;
        if exact {
            self.exact::<Portable>(a, d, i);
        } else {
            self.refine::<Portable>(a, d, i);
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn run_avx2(&self, exact: bool, a: usize, d: &mut [f32], i: &mut [u32]) {
        if exact {
            self.exact::<Avx2>(a, d, i);
        } else {
            self.refine::<Avx2>(a, d, i);
        }
    }
}

/// A sorted list of at most `k` (distance, index) pairs.
struct Best<'a> {
    d: &'a mut [f32],
    i: &'a mut [u32],
}

impl Best<'_> {
    #[inline]
    fn worst(&self) -> f32 {
        self.d[self.d.len() - 1]
    }

    #[inline]
    fn offer(&mut self, j: u32, dist: f32) {
        let k = self.d.len();
        if dist >= self.d[k - 1] || self.i.contains(&j) {
            return;
        }
        let mut pos = k - 1;
        while pos > 0 && self.d[pos - 1] > dist {
            self.d[pos] = self.d[pos - 1];
            self.i[pos] = self.i[pos - 1];
            pos -= 1;
        }
        self.d[pos] = dist;
        self.i[pos] = j;
    }
}

/// Whether an `h × w` exemplar holds `k` neighbours for every pixel outside the window of
/// `exclude` pixels around it (what [`knn`] needs).
#[must_use]
pub fn fits(h: usize, w: usize, exclude: usize, k: usize) -> bool {
    let excluded_max = (2 * exclude + 1).min(h) * (2 * exclude + 1).min(w);
    h * w > excluded_max && h * w - excluded_max >= k
}

/// Computes the `k` nearest patches of every exemplar pixel (see the module docs).
pub fn knn(exemplar: &Image<'_>, weights: Option<&[f32]>, params: &KnnParams) -> Result<Knn> {
    let p = params.patch_size;
    if p == 0 || p % 2 == 0 {
        return Err(invalid(
            "patch_size",
            format!("expected an odd size >= 1, got {p}"),
        ));
    }
    let (h, w, c) = (exemplar.h, exemplar.w, exemplar.c);
    if params.k == 0 {
        return Err(invalid("k", "expected at least 1 neighbour, got 0"));
    }
    let ex = params.exclude;
    if !fits(h, w, ex, params.k) {
        return Err(invalid(
            "k",
            format!("{} neighbours cannot be found in a {h}×{w} exemplar when {ex} pixels around each are excluded", params.k),
        ));
    }
    exemplar.check_finite("exemplar")?;
    let r = p / 2;
    let scaled = prescale(exemplar, weights)?;
    let pad = Padded {
        data: mirror_pad(&scaled, h, w, c, r),
        pw: w + 2 * r,
        w,
        c,
        p,
    };
    let n = h * w;
    let k = params.k;

    let mut dist = vec![f32::INFINITY; n * k];
    let mut idx = vec![NONE; n * k];
    let fast = avx2_enabled();
    let pass = Pass {
        pad: &pad,
        h,
        w,
        k,
        exclude: ex,
        prev: &[],
        radius0: h.max(w) as i64,
        seed: params.seed,
        it: 0,
    };
    if params.exact {
        dist.par_chunks_mut(k)
            .zip(idx.par_chunks_mut(k))
            .enumerate()
            .for_each(|(a, (d, i))| pass.run(true, fast, a, d, i));
        return Ok(Knn { h, w, k, idx, dist });
    }

    // Random start: k distinct far-enough pixels.
    dist.par_chunks_mut(k)
        .zip(idx.par_chunks_mut(k))
        .enumerate()
        .for_each(|(a, (d, i))| {
            let mut rng = Rng::keyed(params.seed, u64::MAX, a as u64);
            let mut best = Best { d, i };
            let mut tries = 0;
            while best.i.contains(&NONE) && tries < 64 * k {
                let b = rng.below(n as u64) as usize;
                if pass.far(a, b) {
                    best.offer(b as u32, pad.dist(a as u32, b as u32, f32::INFINITY));
                }
                tries += 1;
            }
        });
    for it in 0..params.iterations {
        crate::cancel::check()?;
        let prev_i = idx.clone();
        let pass = Pass {
            prev: &prev_i,
            it,
            ..pass
        };
        dist.par_chunks_mut(k)
            .zip(idx.par_chunks_mut(k))
            .enumerate()
            .for_each(|(a, (d, i))| pass.run(false, fast, a, d, i));
    }
    Ok(Knn { h, w, k, idx, dist })
}

/// k-coherence candidate sets (Laitoch 2018, §3.3.6) for an output image of references.
///
/// `refs` holds, per output pixel of an `h × w` image, the flat exemplar index its value was
/// copied from (or [`NONE`]). For each output pixel `p0` and each `p` in its `patch_size`
/// window, the reference of `p` forward-shifted by `p0 − p` is a coherence candidate; with
/// `knn`, each candidate's neighbours join the set. With `wrap`, shifts that leave the
/// exemplar wrap around; without, they are dropped. With `out_wrap` the window itself wraps
/// around the output (a tileable output: the pixels across its edges are neighbours too).
/// Returns `h × w × m` indices, each set
/// deduplicated in discovery order and padded with [`NONE`], where
/// `m = patch_size² × (1 + knn.k)`.
pub fn coherence_candidates(
    refs: &[u32],
    h: usize,
    w: usize,
    eh: usize,
    ew: usize,
    knn: Option<&Knn>,
    patch_size: usize,
    wrap: bool,
    out_wrap: bool,
) -> Result<(Vec<u32>, usize)> {
    if patch_size == 0 || patch_size % 2 == 0 {
        return Err(invalid(
            "patch_size",
            format!("expected an odd size >= 1, got {patch_size}"),
        ));
    }
    if refs.len() != h * w {
        return Err(invalid(
            "refs",
            format!("expected {h}×{w} references, got {}", refs.len()),
        ));
    }
    if let Some(bad) = refs.iter().find(|v| **v != NONE && **v as usize >= eh * ew) {
        return Err(invalid(
            "refs",
            format!("reference {bad} is outside the {eh}×{ew} exemplar"),
        ));
    }
    if let Some(t) = knn {
        if t.h != eh || t.w != ew {
            return Err(invalid(
                "knn",
                format!(
                    "expected a table for the {eh}×{ew} exemplar, got {}×{}",
                    t.h, t.w
                ),
            ));
        }
    }
    let r = (patch_size / 2) as i64;
    let kk = knn.map_or(0, |t| t.k);
    let m = patch_size * patch_size * (1 + kk);
    let mut out = vec![NONE; h * w * m];
    out.par_chunks_mut(m).enumerate().for_each(|(i, set)| {
        if crate::cancel::cancelled() {
            return;
        }
        let (y0, x0) = ((i / w) as i64, (i % w) as i64);
        let mut n = 0usize;
        let mut push = |v: u32, set: &mut [u32]| {
            if !set[..n].contains(&v) {
                set[n] = v;
                n += 1;
            }
        };
        for oy in -r..=r {
            for ox in -r..=r {
                let (mut y, mut x) = (y0 + oy, x0 + ox);
                if out_wrap {
                    y = y.rem_euclid(h as i64);
                    x = x.rem_euclid(w as i64);
                } else if y < 0 || x < 0 || y >= h as i64 || x >= w as i64 {
                    continue;
                }
                let e = refs[y as usize * w + x as usize];
                if e == NONE {
                    continue;
                }
                let cand = shift(e, -oy, -ox, eh, ew, wrap);
                if cand == NONE {
                    continue;
                }
                push(cand, set);
                if let Some(t) = knn {
                    for &b in &t.idx[cand as usize * t.k..][..t.k] {
                        if b != NONE {
                            push(b, set);
                        }
                    }
                }
            }
        }
    });
    Ok((out, m))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tex(h: usize, w: usize) -> Vec<f32> {
        let mut rng = Rng::keyed(3, 0, 0);
        (0..h * w * 3)
            .map(|i| {
                let (y, x) = ((i / 3 / w) as f32, (i / 3 % w) as f32);
                ((x * 0.4).sin() * (y * 0.3).cos()) * 0.5 + rng.below(100) as f32 / 400.0
            })
            .collect()
    }

    #[test]
    fn exact_lists_are_sorted_far_and_optimal() {
        let (h, w) = (14, 13);
        let d = tex(h, w);
        let img = Image::new("exemplar", &d, h, w, 3).unwrap();
        let params = KnnParams {
            patch_size: 5,
            k: 3,
            exact: true,
            exclude: 2,
            ..KnnParams::default()
        };
        let t = knn(&img, None, &params).unwrap();
        let pad = Padded {
            data: mirror_pad(&d, h, w, 3, 2),
            pw: w + 4,
            w,
            c: 3,
            p: 5,
        };
        for a in 0..h * w {
            let mut all: Vec<f32> = (0..h * w)
                .filter(|&b| (a / w).abs_diff(b / w).max((a % w).abs_diff(b % w)) > 2)
                .map(|b| pad.dist(a as u32, b as u32, f32::INFINITY))
                .collect();
            all.sort_by(f32::total_cmp);
            for (j, want) in all.iter().take(3).enumerate() {
                assert!((t.dist[a * 3 + j] - want).abs() <= 1e-5 * want.max(1.0));
            }
        }
    }

    #[test]
    fn approximate_recall_is_high() {
        let (h, w) = (40, 40);
        let d = tex(h, w);
        let img = Image::new("exemplar", &d, h, w, 3).unwrap();
        let base = KnnParams {
            patch_size: 5,
            k: 4,
            exclude: 2,
            iterations: 8,
            ..KnnParams::default()
        };
        let exact = knn(
            &img,
            None,
            &KnnParams {
                exact: true,
                ..base.clone()
            },
        )
        .unwrap();
        let approx = knn(&img, None, &base).unwrap();
        // Quality by distance: the approximate k-th distance is rarely worse than exact.
        let mean = |v: &[f32]| v.iter().map(|x| f64::from(*x)).sum::<f64>() / v.len() as f64;
        let (me, ma) = (mean(&exact.dist), mean(&approx.dist));
        assert!(
            ma <= me * 1.10,
            "approximate mean distance {ma} vs exact {me}"
        );
    }

    #[test]
    fn candidates_forward_shift() {
        // A 3×3 output copied as a block from (5, 5) of a 10×10 exemplar: every pixel's
        // coherence candidates all agree on the same exemplar pixel.
        let (eh, ew) = (10usize, 10usize);
        let refs: Vec<u32> = (0..9)
            .map(|i| ((5 + i / 3) * ew + 5 + i % 3) as u32)
            .collect();
        let (c, m) = coherence_candidates(&refs, 3, 3, eh, ew, None, 3, false, false).unwrap();
        assert_eq!(m, 9);
        for i in 0..9 {
            assert_eq!(c[i * m], refs[i]);
            assert!(c[i * m + 1..(i + 1) * m].iter().all(|v| *v == NONE));
        }
    }

    #[test]
    fn candidates_wrap_around_a_tileable_output() {
        // A 4×4 output copied as a block from (2, 2) of a 10×10 exemplar. Across the output's
        // left edge, pixel (1, 3) is the neighbour (1, -1) of (1, 0): its reference shifted one
        // column right, (3, 6), is a candidate of (1, 0) only when the output wraps.
        let (eh, ew) = (10usize, 10usize);
        let refs: Vec<u32> = (0..16)
            .map(|i| ((2 + i / 4) * ew + 2 + i % 4) as u32)
            .collect();
        let across = (3 * ew + 6) as u32;
        let (plain, m) = coherence_candidates(&refs, 4, 4, eh, ew, None, 3, false, false).unwrap();
        let (wrapped, _) = coherence_candidates(&refs, 4, 4, eh, ew, None, 3, false, true).unwrap();
        let at = |c: &[u32]| c[4 * m..5 * m].to_vec();
        assert!(!at(&plain).contains(&across));
        assert!(at(&wrapped).contains(&across));
        // Inside the output both agree.
        assert_eq!(plain[5 * m..6 * m], wrapped[5 * m..6 * m]);
    }

    #[test]
    fn simd_and_portable_paths_agree() {
        use crate::distance::FORCE_PORTABLE;
        use std::sync::atomic::Ordering;
        let (h, w) = (30, 33);
        let d = tex(h, w);
        let img = Image::new("exemplar", &d, h, w, 3).unwrap();
        for exact in [false, true] {
            let params = KnnParams {
                patch_size: 5,
                k: 3,
                exact,
                ..KnnParams::default()
            };
            FORCE_PORTABLE.store(true, Ordering::Relaxed);
            let portable = knn(&img, None, &params).unwrap();
            FORCE_PORTABLE.store(false, Ordering::Relaxed);
            let fast = knn(&img, None, &params).unwrap();
            assert_eq!(portable.idx, fast.idx);
            assert_eq!(
                portable
                    .dist
                    .iter()
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>(),
                fast.dist.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
            );
        }
    }
}
