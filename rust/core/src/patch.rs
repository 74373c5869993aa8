//! Nearest-neighbour fields between two images: PatchMatch (Barnes, Shechtman, Finkelstein,
//! Goldman 2009, "PatchMatch: a randomized correspondence algorithm for structural image
//! editing") and exact search, the reference it is measured against.
//!
//! For every target pixel that needs a match, the field holds the centre of a source patch of
//! `patch_size × patch_size` pixels whose distance to the target patch centred there is
//! (approximately, for PatchMatch) minimal. Distances are weighted sums of squared differences
//! over all channels. Source patches always lie wholly inside the source; target patches are
//! clipped at the target border (only the part inside is compared), so every target pixel gets
//! a match.
//!
//! Parallelism and determinism: an iteration splits the target into stripes of
//! [`STRIPE_ROWS`] rows — a property of the image, not of the thread pool. Inside a stripe the
//! scan is sequential (raster order on even iterations, reverse on odd ones, as in the paper),
//! so propagation runs at full strength; across a stripe border a pixel reads its neighbour's
//! match from the previous iteration. Every pixel draws its random numbers from its own
//! stream keyed by `(seed, level, iteration, pixel)`. Together these make the result
//! bit-identical for any number of threads.

// The hot helpers are `#[inline(always)]` on purpose: only code inlined into
// `Level::stripe_avx2` is compiled with AVX2 enabled.
#![allow(clippy::inline_always)]

use std::borrow::Cow;
use std::sync::atomic::{AtomicU64, Ordering};

use rayon::prelude::*;

use std::collections::BinaryHeap;

use crate::error::{invalid, Result};
use crate::image::{prescale, Image};
use crate::kdtree::{KdTree, Pca};
use crate::rng::Rng;

/// Rows per work unit of one PatchMatch iteration. Fixed, so that results do not depend on
/// the thread count.
pub const STRIPE_ROWS: usize = 16;

/// Forces the portable (non-AVX2) code path; for tests and for timing the difference.
pub static FORCE_PORTABLE: std::sync::atomic::AtomicBool =
    std::sync::atomic::AtomicBool::new(false);

/// Marks a target pixel that needs no match.
pub const NONE: u32 = u32::MAX;

/// How to compute the field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Randomised search with propagation (approximate, fast).
    PatchMatch,
    /// Brute force over every allowed source patch (exact, `O(source × target)`).
    Exact,
    /// PatchMatch started from propagation-assisted kd-tree search (He & Sun 2012): every
    /// target patch first tries [`KD_CANDIDATES`] source patches that are nearest to it in a
    /// [`KD_DIMS`]-dimensional PCA space of the source patches (best-bin-first, at most
    /// [`KD_BUDGET`] points compared), then the PatchMatch iterations propagate the good
    /// ones. Much closer to exact than PatchMatch between images that share no coherent
    /// structure, for the cost of projecting every patch. Full resolution only (`levels`
    /// is ignored).
    KdTree,
}

/// Dimensions of the PCA space of [`Method::KdTree`].
pub const KD_DIMS: usize = 16;
/// Candidates per target pixel from the kd-tree, ranked by true patch distance.
pub const KD_CANDIDATES: usize = 4;
/// Source points compared in the reduced space per target pixel (best-bin-first budget).
pub const KD_BUDGET: usize = 64;
/// Source patches sampled (evenly) to fit the PCA basis.
const KD_PCA_SAMPLES: usize = 2048;

/// Parameters of [`nnf`]. Validated before any work starts.
#[derive(Clone, Debug)]
pub struct NnfParams {
    /// Side of the square patches; odd. Default 7.
    pub patch_size: usize,
    /// PatchMatch iterations per pyramid level (each one propagation + random search pass).
    /// Default 5, the paper's "4–5 iterations suffice". Ignored by exact search.
    pub iterations: usize,
    /// Pyramid levels for coarse-to-fine PatchMatch; 1 (the default) matches at full
    /// resolution only. Levels stop early when the source gets smaller than a patch.
    pub levels: usize,
    /// Seed of every random choice.
    pub seed: u64,
    /// PatchMatch or exact search.
    pub method: Method,
}

impl Default for NnfParams {
    fn default() -> Self {
        Self {
            patch_size: 7,
            iterations: 5,
            levels: 1,
            seed: 0,
            method: Method::PatchMatch,
        }
    }
}

/// The inputs of [`nnf`]: two images with the same channel count and optional constraints.
#[derive(Clone, Copy, Debug)]
pub struct NnfInput<'a> {
    /// Where patches come from.
    pub source: Image<'a>,
    /// Where patches are matched.
    pub target: Image<'a>,
    /// One non-negative weight per channel (default: all 1).
    pub weights: Option<&'a [f32]>,
    /// `source.h × source.w`: source pixels that may serve as patch centres.
    pub source_mask: Option<&'a [bool]>,
    /// `target.h × target.w`: target pixels that need a match (default: all).
    pub target_mask: Option<&'a [bool]>,
    /// `target.h × target.w × 2` initial (row, col) source centres; `-1` rows mean "random".
    pub init: Option<&'a [i32]>,
    /// Forward enrichment (Barnes et al. 2010, "The generalized PatchMatch correspondence
    /// algorithm", §3.2): `source.h × source.w × k` flat source indices of each source
    /// pixel's most similar other source patches (from [`crate::knn::knn`]). Each iteration
    /// then also tries the neighbours of a pixel's current match, which is what finds good
    /// matches when source and target share no coherent structure. Full resolution only.
    pub source_knn: Option<(&'a [u32], usize)>,
    /// `source.h × source.w` non-negative cost added to the distance of every patch centred
    /// there, e.g. the occurrence penalty of Kaspar et al. 2015 that keeps texture
    /// optimisation from reusing a few source patches everywhere. Full resolution only.
    pub source_cost: Option<&'a [f32]>,
}

impl<'a> NnfInput<'a> {
    /// Matches `target` against `source` with no weights, masks, initial field, enrichment
    /// or costs; set those fields with struct-update syntax.
    #[must_use]
    pub fn new(source: Image<'a>, target: Image<'a>) -> Self {
        Self {
            source,
            target,
            weights: None,
            source_mask: None,
            target_mask: None,
            init: None,
            source_knn: None,
            source_cost: None,
        }
    }
}

/// A nearest-neighbour field.
#[derive(Clone, Debug, PartialEq)]
pub struct Nnf {
    /// Target height.
    pub h: usize,
    /// Target width.
    pub w: usize,
    /// Source width (to decode `idx`).
    pub source_w: usize,
    /// Per target pixel, the flat source index `row * source_w + col` of the matched patch
    /// centre, or [`NONE`].
    pub idx: Vec<u32>,
    /// Per target pixel, the weighted squared distance of its match (`+inf` for [`NONE`]).
    pub dist: Vec<f32>,
    /// Number of candidate patches whose distance was evaluated (for throughput figures).
    pub evaluations: u64,
}

impl Nnf {
    /// The field as `h × w × 2` (row, col) pairs, `-1` where no match was asked for.
    #[must_use]
    pub fn to_rowcol(&self) -> Vec<i32> {
        let sw = self.source_w as u32;
        self.idx
            .iter()
            .flat_map(|&i| {
                if i == NONE {
                    [-1, -1]
                } else {
                    [(i / sw) as i32, (i % sw) as i32]
                }
            })
            .collect()
    }
}

/// Source positions inside a level are packed as `row << 16 | col`: decoding is two shifts
/// instead of two divisions by the width, which the hot loop does for every candidate.
#[inline(always)]
fn pack(y: usize, x: usize) -> u32 {
    ((y as u32) << 16) | x as u32
}

#[inline(always)]
fn unpack(p: u32) -> (usize, usize) {
    ((p >> 16) as usize, (p & 0xFFFF) as usize)
}

/// Largest source side the packed positions can hold.
pub const MAX_SOURCE_SIDE: usize = 0xFFFF;

#[derive(Clone, Copy, Debug)]
struct Cell {
    idx: u32,
    d: f32,
}

const EMPTY: Cell = Cell {
    idx: NONE,
    d: f32::INFINITY,
};

/// Whether the AVX2 kernel may be used (the CPU has it and [`FORCE_PORTABLE`] is off).
pub(crate) fn avx2_enabled() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        !FORCE_PORTABLE.load(Ordering::Relaxed) && std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// A patch-distance kernel. Each row is split into chunks of eight values (the last one
/// zero-padded); chunk `j` of every row adds its squared differences lane by lane into
/// accumulator `j mod 3`. Rows are never reduced on their own, so a patch's additions form
/// three short independent chains instead of one long serial one; the three are combined and
/// reduced only when a total is needed. Implementations must give bit-identical results.
pub(crate) trait Kernel {
    type Acc: Copy;
    fn zero() -> Self::Acc;
    fn add_row(acc: &mut Self::Acc, a: &[f32], b: &[f32]);
    fn total(acc: &Self::Acc) -> f32;

    /// `base` plus the distance between the `rows × len` values at `t[t0 + k·ts..]` and
    /// `s[s0 + k·ss..]` (`k < rows`), abandoned if it has reached `cutoff` after two rows.
    /// (One check only: on unrelated images most candidates survive the first rows, and each
    /// check is a horizontal sum and a badly predicted branch. Abandoning never changes a
    /// result, only the time: partial sums of squares never exceed the full one.) `NC` is `len.div_ceil(8)`; both slices must hold at
    /// least [`PAD`] values past the end of their last row, which implementations may read
    /// (and ignore). Same result, bit for bit, as [`Self::add_row`] row by row.
    #[inline(always)]
    fn patch<const NC: usize>(
        t: &[f32],
        (t0, ts): (usize, usize),
        s: &[f32],
        (s0, ss): (usize, usize),
        (rows, len): (usize, usize),
        base: f32,
        cutoff: f32,
    ) -> f32 {
        let mut acc = Self::zero();
        for k in 0..rows {
            let (a, b) = (t0 + k * ts, s0 + k * ss);
            Self::add_row(&mut acc, &t[a..a + len], &s[b..b + len]);
            if k == 1 && rows > 2 {
                let partial = base + Self::total(&acc);
                if partial >= cutoff {
                    return partial;
                }
            }
        }
        base + Self::total(&acc)
    }
}

/// Zero floats appended to a level's source and target buffers, so that a fixed-width kernel
/// ([`Kernel::patch`]) may load whole 8-lane chunks past the end of a patch row.
const PAD: usize = 8;

/// The portable kernel.
pub(crate) struct Portable;

impl Kernel for Portable {
    type Acc = [[f32; 8]; 3];

    #[inline(always)]
    fn zero() -> Self::Acc {
        [[0.0; 8]; 3]
    }

    #[inline(always)]
    fn add_row(acc: &mut Self::Acc, a: &[f32], b: &[f32]) {
        let n = a.len().min(b.len());
        for (chunk, start) in (0..n).step_by(8).enumerate() {
            let lanes = &mut acc[chunk % 3];
            for (i, lane) in lanes.iter_mut().enumerate().take((n - start).min(8)) {
                let d = a[start + i] - b[start + i];
                *lane += d * d;
            }
        }
    }

    #[inline(always)]
    fn total(acc: &Self::Acc) -> f32 {
        let mut v = [0f32; 8];
        for (i, lane) in v.iter_mut().enumerate() {
            *lane = (acc[0][i] + acc[1][i]) + acc[2][i];
        }
        ((v[0] + v[4]) + (v[1] + v[5])) + ((v[2] + v[6]) + (v[3] + v[7]))
    }
}

/// AVX2 intrinsics doing exactly what [`Portable`] does lane by lane: subtract, multiply, add
/// (no fused multiply-add, whose single rounding would change results); the tail chunk is a
/// masked load whose empty lanes add `+0.0`, which changes nothing.
#[cfg(target_arch = "x86_64")]
pub(crate) struct Avx2;

#[cfg(target_arch = "x86_64")]
impl Kernel for Avx2 {
    type Acc = [std::arch::x86_64::__m256; 3];

    #[inline(always)]
    fn zero() -> Self::Acc {
        // SAFETY: only reached from `Level::stripe_avx2`, which requires AVX2.
        unsafe { [std::arch::x86_64::_mm256_setzero_ps(); 3] }
    }

    #[inline(always)]
    fn add_row(acc: &mut Self::Acc, a: &[f32], b: &[f32]) {
        use std::arch::x86_64::{
            __m256, _mm256_add_ps, _mm256_cmpgt_epi32, _mm256_loadu_ps, _mm256_maskload_ps,
            _mm256_mul_ps, _mm256_set1_epi32, _mm256_setr_epi32, _mm256_sub_ps,
        };
        let n = a.len().min(b.len());
        let full = n / 8 * 8;
        // SAFETY: AVX2 is enabled (see `zero`); full loads read below `full <= n`, and the
        // masked load touches only the `n - full` lanes inside both slices.
        unsafe {
            let sq = |i: usize| -> __m256 {
                let d = _mm256_sub_ps(
                    _mm256_loadu_ps(a.as_ptr().add(i)),
                    _mm256_loadu_ps(b.as_ptr().add(i)),
                );
                _mm256_mul_ps(d, d)
            };
            // Chunk j goes to accumulator j mod 3, as in `Portable`; the indices are static
            // so the three accumulators stay in registers.
            let [mut a0, mut a1, mut a2] = *acc;
            let mut i = 0;
            while i + 24 <= full {
                a0 = _mm256_add_ps(a0, sq(i));
                a1 = _mm256_add_ps(a1, sq(i + 8));
                a2 = _mm256_add_ps(a2, sq(i + 16));
                i += 24;
            }
            // 0, 1 or 2 full chunks left, then maybe a partial one: the next slots in order.
            let left = (full - i) / 8;
            let rest = (n - full) as i32;
            let tail = if rest > 0 {
                let mask = _mm256_cmpgt_epi32(
                    _mm256_set1_epi32(rest),
                    _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
                );
                let d = _mm256_sub_ps(
                    _mm256_maskload_ps(a.as_ptr().add(full), mask),
                    _mm256_maskload_ps(b.as_ptr().add(full), mask),
                );
                Some(_mm256_mul_ps(d, d))
            } else {
                None
            };
            match (left, tail) {
                (0, Some(t)) => a0 = _mm256_add_ps(a0, t),
                (1, None) => a0 = _mm256_add_ps(a0, sq(i)),
                (1, Some(t)) => {
                    a0 = _mm256_add_ps(a0, sq(i));
                    a1 = _mm256_add_ps(a1, t);
                }
                (2, None) => {
                    a0 = _mm256_add_ps(a0, sq(i));
                    a1 = _mm256_add_ps(a1, sq(i + 8));
                }
                (2, Some(t)) => {
                    a0 = _mm256_add_ps(a0, sq(i));
                    a1 = _mm256_add_ps(a1, sq(i + 8));
                    a2 = _mm256_add_ps(a2, t);
                }
                _ => {}
            }
            *acc = [a0, a1, a2];
        }
    }

    #[inline(always)]
    fn patch<const NC: usize>(
        t: &[f32],
        (t0, ts): (usize, usize),
        s: &[f32],
        (s0, ss): (usize, usize),
        (rows, len): (usize, usize),
        base: f32,
        cutoff: f32,
    ) -> f32 {
        use std::arch::x86_64::{
            _mm256_add_ps, _mm256_and_ps, _mm256_castsi256_ps, _mm256_cmpgt_epi32, _mm256_loadu_ps,
            _mm256_mul_ps, _mm256_set1_epi32, _mm256_setr_epi32, _mm256_setzero_ps, _mm256_sub_ps,
        };
        assert!(NC >= 1 && len.div_ceil(8) == NC && rows >= 1);
        assert!(t0 + (rows - 1) * ts + 8 * NC <= t.len());
        assert!(s0 + (rows - 1) * ss + 8 * NC <= s.len());
        // SAFETY: AVX2 is enabled (see `zero`); the asserts above keep every load of `8 * NC`
        // values per row inside the slices.
        unsafe {
            // The last chunk's lanes past `len` hold the next pixels' values: zeroing their
            // differences adds +0.0, as the masked loads of `add_row` do.
            let mask = _mm256_castsi256_ps(_mm256_cmpgt_epi32(
                _mm256_set1_epi32((len - 8 * (NC - 1)) as i32),
                _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
            ));
            let (tr, sr) = (t.as_ptr().add(t0), s.as_ptr().add(s0));
            let [mut a0, mut a1, mut a2] = [_mm256_setzero_ps(); 3];
            // Patch row k: chunk j into accumulator j mod 3.
            macro_rules! row {
                ($k:expr) => {
                    for j in 0..NC {
                        let mut d = _mm256_sub_ps(
                            _mm256_loadu_ps(tr.add($k * ts + 8 * j)),
                            _mm256_loadu_ps(sr.add($k * ss + 8 * j)),
                        );
                        if j + 1 == NC {
                            d = _mm256_and_ps(d, mask);
                        }
                        let sq = _mm256_mul_ps(d, d);
                        match j % 3 {
                            0 => a0 = _mm256_add_ps(a0, sq),
                            1 => a1 = _mm256_add_ps(a1, sq),
                            _ => a2 = _mm256_add_ps(a2, sq),
                        }
                    }
                };
            }
            row!(0);
            if rows > 1 {
                row!(1);
                if rows > 2 {
                    let partial = base + Self::total(&[a0, a1, a2]);
                    if partial >= cutoff {
                        return partial;
                    }
                    for k in 2..rows {
                        row!(k);
                    }
                }
            }
            base + Self::total(&[a0, a1, a2])
        }
    }

    #[inline(always)]
    fn total(acc: &Self::Acc) -> f32 {
        use std::arch::x86_64::{
            _mm256_add_ps, _mm256_castps256_ps128, _mm256_extractf128_ps, _mm_add_ps,
            _mm_cvtss_f32, _mm_shuffle_ps,
        };
        // SAFETY: AVX2 is enabled (see `zero`).
        unsafe {
            let v = _mm256_add_ps(_mm256_add_ps(acc[0], acc[1]), acc[2]);
            // (v0+v4, v1+v5, v2+v6, v3+v7), then (s0+s1) + (s2+s3) as in `Portable::total`.
            let s = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps::<1>(v));
            let s01 = _mm_cvtss_f32(_mm_add_ps(s, _mm_shuffle_ps::<0b01>(s, s)));
            let s23 = _mm_cvtss_f32(_mm_add_ps(
                _mm_shuffle_ps::<0b10>(s, s),
                _mm_shuffle_ps::<0b11>(s, s),
            ));
            s01 + s23
        }
    }
}

/// One resolution of a matching problem: prescaled buffers, dimensions and constraints.
/// What one pass over the stripes shares.
struct Pass<'p> {
    /// The field before this iteration, read across stripe borders.
    prev: &'p [Cell],
    seed: u64,
    level: usize,
    it: usize,
}

struct Level<'a> {
    /// Source values, followed by [`PAD`] zeros.
    src: Vec<f32>,
    sh: usize,
    sw: usize,
    /// Target values, followed by [`PAD`] zeros.
    tgt: Vec<f32>,
    th: usize,
    tw: usize,
    c: usize,
    r: usize,
    /// Per source pixel: may be a patch centre (mask and border both allow it).
    allowed: Vec<bool>,
    allowed_list: Vec<u32>,
    /// Whether a source mask restricts centres beyond the border (else `allowed` need not be
    /// read, which saves a cache miss per random candidate).
    masked: bool,
    /// Per target pixel: needs a match.
    need: Option<Cow<'a, [bool]>>,
    /// Source self-similarity lists for enrichment, `k` packed positions per source pixel.
    knn: Option<(Vec<u32>, usize)>,
    /// Additive cost per source centre.
    cost: Option<&'a [f32]>,
}

impl Level<'_> {
    fn new<'b>(
        src: Cow<'b, [f32]>,
        (sh, sw): (usize, usize),
        tgt: Cow<'b, [f32]>,
        (th, tw): (usize, usize),
        c: usize,
        r: usize,
        source_mask: Option<&[bool]>,
        need: Option<Cow<'b, [bool]>>,
    ) -> Level<'b> {
        let mut allowed = vec![false; sh * sw];
        let mut allowed_list = Vec::new();
        if sh > 2 * r && sw > 2 * r {
            for y in r..sh - r {
                for x in r..sw - r {
                    let i = y * sw + x;
                    if source_mask.is_none_or(|m| m[i]) {
                        allowed[i] = true;
                        allowed_list.push(pack(y, x));
                    }
                }
            }
        }
        let pad = |buf: Cow<'b, [f32]>| {
            let mut v = buf.into_owned();
            v.extend_from_slice(&[0.0; PAD]);
            v
        };
        Level {
            src: pad(src),
            sh,
            sw,
            tgt: pad(tgt),
            th,
            tw,
            c,
            r,
            allowed,
            allowed_list,
            need,
            knn: None,
            cost: None,
            masked: source_mask.is_some(),
        }
    }

    #[inline]
    fn needs(&self, i: usize) -> bool {
        self.need.as_ref().is_none_or(|m| m[i])
    }

    /// Distance between the target patch at `(ty, tx)` and the source patch centred at `s`,
    /// abandoning the sum once it reaches `cutoff`.
    #[inline(always)]
    fn dist(&self, ty: usize, tx: usize, s: u32, cutoff: f32) -> f32 {
        self.dist_with::<Portable>(ty, tx, s, cutoff)
    }

    #[inline(always)]
    fn dist_with<K: Kernel>(&self, ty: usize, tx: usize, s: u32, cutoff: f32) -> f32 {
        let (sy, sx) = unpack(s);
        let r = self.r;
        let dy0 = ty.min(r);
        let dy1 = (self.th - 1 - ty).min(r);
        let dx0 = tx.min(r);
        let dx1 = (self.tw - 1 - tx).min(r);
        let len = (dx0 + dx1 + 1) * self.c;
        let base = self.cost.map_or(0.0, |c| c[sy * self.sw + sx]);
        if base >= cutoff {
            return base;
        }
        let mut acc = K::zero();
        let rows = dy0 + dy1 + 1;
        for k in 0..rows {
            let t0 = ((ty - dy0 + k) * self.tw + tx - dx0) * self.c;
            let s0 = ((sy - dy0 + k) * self.sw + sx - dx0) * self.c;
            K::add_row(&mut acc, &self.tgt[t0..t0 + len], &self.src[s0..s0 + len]);
            // Early termination, checked every other row: the check is a horizontal sum and an
            // unpredictable branch, both worth amortising.
            if k % 2 == 1 && k + 1 < rows {
                let partial = base + K::total(&acc);
                if partial >= cutoff {
                    return partial;
                }
            }
        }
        base + K::total(&acc)
    }

    /// [`Self::dist_with`] for a target patch wholly inside the target, by the fixed-width
    /// kernel [`Kernel::patch`] (`NC` chunks of eight values per patch row).
    #[inline(always)]
    fn dist_interior<K: Kernel, const NC: usize>(
        &self,
        ty: usize,
        tx: usize,
        s: u32,
        cutoff: f32,
    ) -> f32 {
        let (sy, sx) = unpack(s);
        let (r, c) = (self.r, self.c);
        let base = self.cost.map_or(0.0, |c| c[sy * self.sw + sx]);
        if base >= cutoff {
            return base;
        }
        K::patch::<NC>(
            &self.tgt,
            (((ty - r) * self.tw + tx - r) * c, self.tw * c),
            &self.src,
            (((sy - r) * self.sw + sx - r) * c, self.sw * c),
            (2 * r + 1, (2 * r + 1) * c),
            base,
            cutoff,
        )
    }

    #[inline(always)]
    fn valid(&self, y: i64, x: i64) -> Option<u32> {
        let r = self.r as i64;
        if y < r || x < r || y >= (self.sh as i64) - r || x >= (self.sw as i64) - r {
            return None;
        }
        let (y, x) = (y as usize, x as usize);
        (!self.masked || self.allowed[y * self.sw + x]).then_some(pack(y, x))
    }

    fn random_allowed(&self, rng: &mut Rng) -> u32 {
        self.allowed_list[rng.below(self.allowed_list.len() as u64) as usize]
    }

    /// Starting field: `guess(pixel)` where it proposes an allowed centre, random elsewhere.
    fn initialise(
        &self,
        seed: u64,
        level: usize,
        guess: impl Fn(usize) -> Option<u32> + Sync,
    ) -> Vec<Cell> {
        let mut cells = vec![EMPTY; self.th * self.tw];
        cells
            .par_chunks_mut(self.tw)
            .enumerate()
            .for_each(|(y, row)| {
                for (x, cell) in row.iter_mut().enumerate() {
                    let i = y * self.tw + x;
                    if !self.needs(i) {
                        continue;
                    }
                    let idx = guess(i).unwrap_or_else(|| {
                        let mut rng =
                            Rng::keyed(seed, (level as u64) << 32 | 0xFFFF_FFFF, i as u64);
                        self.random_allowed(&mut rng)
                    });
                    *cell = Cell {
                        idx,
                        d: f32::INFINITY,
                    };
                }
            });
        self.fill_distances(&mut cells);
        cells
    }

    /// Chunks of eight values per patch row for the fixed-width kernel, or 0 for rows too
    /// long for it (more than 32 values), which take the general one.
    fn chunks(&self) -> usize {
        match (2 * self.r + 1) * self.c {
            n @ 1..=32 => n.div_ceil(8),
            _ => 0,
        }
    }

    /// Sets the distance of every cell with a match, on the fastest kernel.
    fn fill_distances(&self, cells: &mut [Cell]) {
        #[cfg(target_arch = "x86_64")]
        let fast = avx2_enabled();
        cells
            .par_chunks_mut(self.tw)
            .enumerate()
            .for_each(|(y, row)| {
                macro_rules! run {
                    ($nc:literal) => {{
                        #[cfg(target_arch = "x86_64")]
                        if fast {
                            // SAFETY: the CPU supports AVX2 (checked just above).
                            unsafe { self.distances_avx2::<$nc>(y, row) }
                        } else {
                            self.distances::<Portable, $nc>(y, row);
                        }
                        #[cfg(not(target_arch = "x86_64"))]
                        self.distances::<Portable, $nc>(y, row);
                    }};
                }
                match self.chunks() {
                    1 => run!(1),
                    2 => run!(2),
                    3 => run!(3),
                    4 => run!(4),
                    _ => run!(0),
                }
            });
    }

    /// [`Self::distances`] with the AVX2 kernel, compiled for AVX2; bit-identical results.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn distances_avx2<const NC: usize>(&self, y: usize, row: &mut [Cell]) {
        self.distances::<Avx2, NC>(y, row);
    }

    /// The distances of target row `y`'s matches.
    #[inline(always)]
    fn distances<K: Kernel, const NC: usize>(&self, y: usize, row: &mut [Cell]) {
        let r = self.r;
        for (x, cell) in row.iter_mut().enumerate() {
            if cell.idx == NONE {
                continue;
            }
            let interior = y >= r && x >= r && y + r < self.th && x + r < self.tw;
            cell.d = if NC > 0 && interior {
                self.dist_interior::<K, NC>(y, x, cell.idx, f32::INFINITY)
            } else {
                self.dist_with::<K>(y, x, cell.idx, f32::INFINITY)
            };
        }
    }

    /// One PatchMatch iteration (propagation + random search) over the whole target.
    fn iterate(&self, cells: &mut [Cell], seed: u64, level: usize, it: usize) -> u64 {
        let prev = cells.to_vec();
        let evals = AtomicU64::new(0);
        let tw = self.tw;
        #[cfg(target_arch = "x86_64")]
        let fast = avx2_enabled();
        cells
            .par_chunks_mut(STRIPE_ROWS * tw)
            .enumerate()
            .for_each(|(stripe, chunk)| {
                let pass = Pass {
                    prev: &prev,
                    seed,
                    level,
                    it,
                };
                // The fixed-width kernel takes rows of up to four 8-lane chunks.
                macro_rules! run {
                    ($nc:literal) => {{
                        #[cfg(target_arch = "x86_64")]
                        let count = if fast {
                            // SAFETY: the CPU supports AVX2 (checked just above).
                            unsafe { self.stripe_avx2::<$nc>(chunk, stripe, &pass) }
                        } else {
                            self.stripe::<Portable, $nc>(chunk, stripe, &pass)
                        };
                        #[cfg(not(target_arch = "x86_64"))]
                        let count = self.stripe::<Portable, $nc>(chunk, stripe, &pass);
                        count
                    }};
                }
                let count = match self.chunks() {
                    1 => run!(1),
                    2 => run!(2),
                    3 => run!(3),
                    4 => run!(4),
                    _ => run!(0),
                };
                evals.fetch_add(count, Ordering::Relaxed);
            });
        evals.into_inner()
    }

    /// [`Self::stripe`] with the AVX2 kernel, compiled for AVX2; bit-identical results.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn stripe_avx2<const NC: usize>(
        &self,
        chunk: &mut [Cell],
        stripe: usize,
        pass: &Pass<'_>,
    ) -> u64 {
        self.stripe::<Avx2, NC>(chunk, stripe, pass)
    }

    /// Evaluates candidate `cand` for target pixel `(y, x)`, keeping it if it beats `best`.
    /// A method, not a closure: a closure the compiler does not inline is compiled without
    /// AVX2, and every intrinsic in it becomes a call.
    #[inline(always)]
    fn try_candidate<K: Kernel, const NC: usize>(
        &self,
        (y, x, interior): (usize, usize, bool),
        count: &mut u64,
        cand: Option<u32>,
        best: &mut Cell,
    ) {
        if let Some(s) = cand {
            if s != best.idx {
                *count += 1;
                let d = if NC > 0 && interior {
                    self.dist_interior::<K, NC>(y, x, s, best.d)
                } else {
                    self.dist_with::<K>(y, x, s, best.d)
                };
                if d < best.d {
                    *best = Cell { idx: s, d };
                }
            }
        }
    }

    /// Propagation and random search over one stripe; returns the candidates evaluated.
    #[inline(always)]
    fn stripe<K: Kernel, const NC: usize>(
        &self,
        chunk: &mut [Cell],
        stripe: usize,
        pass: &Pass<'_>,
    ) -> u64 {
        let tw = self.tw;
        let reverse = pass.it % 2 == 1;
        let step: i64 = if reverse { 1 } else { -1 };
        let search_radius = self.sh.max(self.sw) as i64;
        let (ymax, xmax) = ((self.sh - 1 - self.r) as i64, (self.sw - 1 - self.r) as i64);
        let y0 = stripe * STRIPE_ROWS;
        let rows = chunk.len() / tw;
        let mut count = 0u64;
        for yy in 0..rows {
            let ly = if reverse { rows - 1 - yy } else { yy };
            let y = y0 + ly;
            for xx in 0..tw {
                let x = if reverse { tw - 1 - xx } else { xx };
                let li = ly * tw + x;
                let mut best = chunk[li];
                if best.idx == NONE {
                    continue;
                }
                let r = self.r;
                let at = (y, x, y >= r && x >= r && y + r < self.th && x + r < tw);
                // Propagation: the neighbour one step back along the scan, shifted.
                let nx = x as i64 + step;
                if nx >= 0 && nx < tw as i64 {
                    let n = chunk[ly * tw + nx as usize].idx;
                    if n != NONE {
                        let (sy, sx) = unpack(n);
                        self.try_candidate::<K, NC>(
                            at,
                            &mut count,
                            self.valid(sy as i64, sx as i64 - step),
                            &mut best,
                        );
                    }
                }
                let nly = ly as i64 + step;
                let ny = y as i64 + step;
                let n = if nly >= 0 && nly < rows as i64 {
                    chunk[nly as usize * tw + x].idx
                } else if ny >= 0 && ny < self.th as i64 {
                    pass.prev[ny as usize * tw + x].idx
                } else {
                    NONE
                };
                if n != NONE {
                    let (sy, sx) = unpack(n);
                    self.try_candidate::<K, NC>(
                        at,
                        &mut count,
                        self.valid(sy as i64 - step, sx as i64),
                        &mut best,
                    );
                }
                // Forward enrichment: the source neighbours of the current match.
                if let Some((table, k)) = &self.knn {
                    let (by, bx) = unpack(best.idx);
                    let b = by * self.sw + bx;
                    for &j in &table[b * k..(b + 1) * k] {
                        let (jy, jx) = unpack(j);
                        self.try_candidate::<K, NC>(
                            at,
                            &mut count,
                            self.valid(jy as i64, jx as i64),
                            &mut best,
                        );
                    }
                }
                // Random search around the current best, radius halving (alpha = 1/2). The
                // centre is fixed for the whole sequence (Barnes et al. 2009, Eq. 1), so all
                // samples are drawn first. (Prefetching their rows here measured no faster
                // once the kernel got cheaper: the 3 MB source of the benchmark sits in L2/L3.)
                let mut rng = Rng::keyed(
                    pass.seed,
                    (pass.level as u64) << 32 | pass.it as u64,
                    (y * tw + x) as u64,
                );
                let (by, bx) = unpack(best.idx);
                let (by, bx) = (by as i64, bx as i64);
                let r = self.r as i64;
                let mut samples = [NONE; 40];
                let mut ns = 0;
                let mut rad = search_radius;
                while rad >= 1 && ns < samples.len() {
                    let ylo = (by - rad).max(r);
                    let yhi = (by + rad).min(ymax);
                    let xlo = (bx - rad).max(r);
                    let xhi = (bx + rad).min(xmax);
                    // Window sides are at most MAX_SOURCE_SIDE, so the 32-bit draw is exact.
                    let cy = ylo + rng.below_u32((yhi - ylo + 1) as u32) as i64;
                    let cx = xlo + rng.below_u32((xhi - xlo + 1) as u32) as i64;
                    // Without a source mask every point of the window is an allowed centre:
                    // the window lies inside the border and contains the current best.
                    let cand = if self.masked {
                        self.valid(cy, cx)
                    } else {
                        Some(pack(cy as usize, cx as usize))
                    };
                    if let Some(s) = cand {
                        samples[ns] = s;
                        ns += 1;
                    }
                    rad /= 2;
                }
                for &s in &samples[..ns] {
                    self.try_candidate::<K, NC>(at, &mut count, Some(s), &mut best);
                }
                chunk[li] = best;
            }
        }
        count
    }

    /// The `p × p × c` values of the source patch centred at `s` (wholly inside the source).
    #[inline]
    fn source_patch(&self, s: u32, out: &mut [f32]) {
        let (sy, sx) = unpack(s);
        let (r, c) = (self.r, self.c);
        let len = (2 * r + 1) * c;
        for (k, o) in out.chunks_exact_mut(len).enumerate() {
            let s0 = ((sy - r + k) * self.sw + sx - r) * c;
            o.copy_from_slice(&self.src[s0..s0 + len]);
        }
    }

    /// Replaces every cell's match by the best of it and [`KD_CANDIDATES`] source patches
    /// found near the target patch in a PCA space of the source patches (see
    /// [`Method::KdTree`]); returns the candidates evaluated. Target patches clipped by the
    /// border take the PCA mean where they have no pixels, which projects to zero there.
    fn kd_seed(&self, cells: &mut [Cell]) -> u64 {
        const CHUNK: usize = 256;
        let (r, c) = (self.r, self.c);
        let p = 2 * r + 1;
        let dim = p * p * c;
        let n = self.allowed_list.len();
        let step = n.div_ceil(KD_PCA_SAMPLES).max(1);
        let pca = Pca::fit(n.div_ceil(step), dim, KD_DIMS, |i, out| {
            self.source_patch(self.allowed_list[i * step], out);
        });
        let d = pca.d;
        let mut points = vec![0f32; n * d];
        points
            .par_chunks_mut(CHUNK * d)
            .enumerate()
            .for_each(|(ci, chunk)| {
                let mut v = vec![0f32; dim];
                for (j, o) in chunk.chunks_exact_mut(d).enumerate() {
                    self.source_patch(self.allowed_list[ci * CHUNK + j], &mut v);
                    pca.project(&v, o);
                }
            });
        let tree = KdTree::build(&points, d);
        let tw = self.tw;
        cells
            .par_chunks_mut(tw)
            .enumerate()
            .map(|(y, row)| {
                let mut v = vec![0f32; dim];
                let mut q = vec![0f32; d];
                let (mut found, mut heap) = (Vec::new(), BinaryHeap::new());
                let mut count = 0u64;
                for (x, cell) in row.iter_mut().enumerate() {
                    if cell.idx == NONE {
                        continue;
                    }
                    for (k, o) in v.chunks_exact_mut(p * c).enumerate() {
                        let ty = (y + k) as i64 - r as i64;
                        for (j, px) in o.chunks_exact_mut(c).enumerate() {
                            let tx = (x + j) as i64 - r as i64;
                            if ty < 0 || tx < 0 || ty >= self.th as i64 || tx >= tw as i64 {
                                let m0 = (k * p + j) * c;
                                px.copy_from_slice(&pca.mean[m0..m0 + c]);
                            } else {
                                let t0 = (ty as usize * tw + tx as usize) * c;
                                px.copy_from_slice(&self.tgt[t0..t0 + c]);
                            }
                        }
                    }
                    pca.project(&v, &mut q);
                    tree.search(&q, KD_CANDIDATES, KD_BUDGET, &mut found, &mut heap);
                    for &(_, id) in &found {
                        let s = self.allowed_list[id as usize];
                        if s != cell.idx {
                            count += 1;
                            let dist = self.dist(y, x, s, cell.d);
                            if dist < cell.d {
                                *cell = Cell { idx: s, d: dist };
                            }
                        }
                    }
                }
                count
            })
            .sum()
    }

    /// Exact search: every allowed source centre for every target pixel that needs one.
    fn exact(&self) -> (Vec<Cell>, u64) {
        let mut cells = vec![EMPTY; self.th * self.tw];
        cells
            .par_chunks_mut(self.tw)
            .enumerate()
            .for_each(|(y, row)| {
                for (x, cell) in row.iter_mut().enumerate() {
                    if !self.needs(y * self.tw + x) {
                        continue;
                    }
                    let mut best = Cell {
                        idx: NONE,
                        d: f32::INFINITY,
                    };
                    for &s in &self.allowed_list {
                        let d = self.dist(y, x, s, best.d);
                        if d < best.d {
                            best = Cell { idx: s, d };
                        }
                    }
                    *cell = best;
                }
            });
        let n = self.allowed_list.len() as u64 * self.need_count() as u64;
        (cells, n)
    }

    fn need_count(&self) -> usize {
        self.need
            .as_ref()
            .map_or(self.th * self.tw, |m| m.iter().filter(|v| **v).count())
    }

    /// Half-resolution copy: 2×2 box average of images, AND of the source mask, OR of the
    /// target mask.
    fn coarser(&self, source_mask: Option<&[bool]>) -> (Level<'static>, Option<Vec<bool>>) {
        let (src, sh, sw) = half(&self.src, self.sh, self.sw, self.c);
        let (tgt, th, tw) = half(&self.tgt, self.th, self.tw, self.c);
        let smask = source_mask.map(|m| half_mask(m, self.sh, self.sw, true));
        let need = self
            .need
            .as_ref()
            .map(|m| Cow::Owned(half_mask(m, self.th, self.tw, false)));
        let lvl = Level::new(
            Cow::Owned(src),
            (sh, sw),
            Cow::Owned(tgt),
            (th, tw),
            self.c,
            self.r,
            smask.as_deref(),
            need,
        );
        (lvl, smask)
    }
}

fn half(buf: &[f32], h: usize, w: usize, c: usize) -> (Vec<f32>, usize, usize) {
    let (nh, nw) = (h / 2, w / 2);
    let mut out = vec![0f32; nh * nw * c];
    out.par_chunks_mut(nw * c).enumerate().for_each(|(y, row)| {
        for x in 0..nw {
            for k in 0..c {
                let at = |yy: usize, xx: usize| buf[(yy * w + xx) * c + k];
                row[x * c + k] = 0.25
                    * (at(2 * y, 2 * x)
                        + at(2 * y, 2 * x + 1)
                        + at(2 * y + 1, 2 * x)
                        + at(2 * y + 1, 2 * x + 1));
            }
        }
    });
    (out, nh, nw)
}

fn half_mask(m: &[bool], h: usize, w: usize, all: bool) -> Vec<bool> {
    let (nh, nw) = (h / 2, w / 2);
    let mut out = Vec::with_capacity(nh * nw);
    for y in 0..nh {
        for x in 0..nw {
            let q = [
                m[2 * y * w + 2 * x],
                m[2 * y * w + 2 * x + 1],
                m[(2 * y + 1) * w + 2 * x],
                m[(2 * y + 1) * w + 2 * x + 1],
            ];
            out.push(if all {
                q.iter().all(|v| *v)
            } else {
                q.iter().any(|v| *v)
            });
        }
    }
    out
}

/// Checks every argument of [`nnf`] and returns the prescaled finest level.
fn validate<'a>(input: &NnfInput<'a>, params: &NnfParams) -> Result<Level<'a>> {
    let (s, t) = (input.source, input.target);
    let p = params.patch_size;
    if p == 0 || p % 2 == 0 {
        return Err(invalid(
            "patch_size",
            format!("expected an odd size >= 1, got {p}"),
        ));
    }
    if p > s.h || p > s.w {
        return Err(invalid(
            "patch_size",
            format!(
                "{p} does not fit in the source image of {}×{} pixels",
                s.h, s.w
            ),
        ));
    }
    if s.h > MAX_SOURCE_SIDE || s.w > MAX_SOURCE_SIDE {
        return Err(invalid(
            "source",
            format!(
                "expected at most {MAX_SOURCE_SIDE} pixels per side, got {}×{}",
                s.h, s.w
            ),
        ));
    }
    if t.c != s.c {
        return Err(invalid(
            "target",
            format!("expected {} channels like source, got {}", s.c, t.c),
        ));
    }
    if params.levels == 0 {
        return Err(invalid(
            "levels",
            "expected at least 1 pyramid level, got 0",
        ));
    }
    s.check_finite("source")?;
    t.check_finite("target")?;
    if let Some(m) = input.source_mask {
        if m.len() != s.h * s.w {
            return Err(invalid(
                "source_mask",
                format!(
                    "expected {}×{} values like source, got {}",
                    s.h,
                    s.w,
                    m.len()
                ),
            ));
        }
    }
    if let Some(m) = input.target_mask {
        if m.len() != t.h * t.w {
            return Err(invalid(
                "target_mask",
                format!(
                    "expected {}×{} values like target, got {}",
                    t.h,
                    t.w,
                    m.len()
                ),
            ));
        }
        if !m.iter().any(|v| *v) {
            return Err(invalid(
                "target_mask",
                "no target pixel is selected (the mask is empty)",
            ));
        }
    }
    let src = prescale(&s, input.weights)?;
    let tgt = prescale(&t, input.weights)?;
    let level = Level::new(
        Cow::Owned(src),
        (s.h, s.w),
        Cow::Owned(tgt),
        (t.h, t.w),
        s.c,
        p / 2,
        input.source_mask,
        input.target_mask.map(Cow::Borrowed),
    );
    if level.allowed_list.is_empty() {
        return Err(invalid(
            "source_mask",
            format!("no source patch may be used: the mask selects no pixel at least {} pixels from the border", p / 2),
        ));
    }
    if let Some((table, k)) = input.source_knn {
        if k == 0 || table.len() != s.h * s.w * k {
            return Err(invalid(
                "source_knn",
                format!(
                    "expected {}×{}×k neighbour indices like source, got {} values for k = {k}",
                    s.h,
                    s.w,
                    table.len()
                ),
            ));
        }
        if let Some(bad) = table
            .iter()
            .find(|v| **v != NONE && **v as usize >= s.h * s.w)
        {
            return Err(invalid(
                "source_knn",
                format!("index {bad} is outside the {}×{} source", s.h, s.w),
            ));
        }
    }
    if let Some(cost) = input.source_cost {
        if cost.len() != s.h * s.w {
            return Err(invalid(
                "source_cost",
                format!(
                    "expected {}×{} values like source, got {}",
                    s.h,
                    s.w,
                    cost.len()
                ),
            ));
        }
        if let Some(bad) = cost.iter().find(|v| !v.is_finite() || **v < 0.0) {
            return Err(invalid(
                "source_cost",
                format!("expected finite non-negative costs, got {bad}"),
            ));
        }
    }
    let mut level = level;
    level.knn = input.source_knn.map(|(table, k)| {
        let packed = table
            .iter()
            .map(|&j| {
                if j == NONE {
                    NONE
                } else {
                    pack(j as usize / s.w, j as usize % s.w)
                }
            })
            .collect();
        (packed, k)
    });
    level.cost = input.source_cost;
    if let Some(init) = input.init {
        if init.len() != t.h * t.w * 2 {
            return Err(invalid(
                "init",
                format!(
                    "expected a {}×{}×2 field like target, got {} values",
                    t.h,
                    t.w,
                    init.len()
                ),
            ));
        }
        for (i, rc) in init.chunks_exact(2).enumerate() {
            if rc[0] < 0 && rc[1] < 0 {
                continue;
            }
            if level.valid(i64::from(rc[0]), i64::from(rc[1])).is_none() {
                return Err(invalid(
                    "init",
                    format!(
                        "entry at (row {}, col {}) = ({}, {}) is not an allowed source patch centre",
                        i / t.w,
                        i % t.w,
                        rc[0],
                        rc[1]
                    ),
                ));
            }
        }
    }
    Ok(level)
}

/// Computes a nearest-neighbour field from `input.target` to `input.source`.
///
/// See the module documentation for the conventions. Errors name the offending argument:
/// an even or oversized `patch_size`, mismatched channels or mask sizes, NaN or infinite
/// values, an empty target mask, a source mask that leaves no usable patch, an `init` entry
/// that is not an allowed centre.
///
/// # Panics
///
/// Never on valid input; the `expect`s guard invariants of the pyramid built here.
pub fn nnf(input: &NnfInput<'_>, params: &NnfParams) -> Result<Nnf> {
    let finest = validate(input, params)?;
    if params.method == Method::Exact {
        let (cells, evaluations) = finest.exact();
        return Ok(to_nnf(&finest, &cells, evaluations));
    }
    if params.method == Method::KdTree {
        let mut cells = finest.initialise(params.seed, 0, |i| {
            let init = input.init?;
            finest.valid(i64::from(init[2 * i]), i64::from(init[2 * i + 1]))
        });
        let mut evaluations = finest.kd_seed(&mut cells);
        for it in 0..params.iterations {
            crate::cancel::check()?;
            evaluations += finest.iterate(&mut cells, params.seed, 0, it);
        }
        return Ok(to_nnf(&finest, &cells, evaluations));
    }
    // Build the pyramid, finest first, while the source can still hold a patch.
    let mut levels = vec![finest];
    let mut masks: Vec<Option<Vec<bool>>> = vec![input.source_mask.map(<[bool]>::to_vec)];
    while levels.len() < params.levels && input.init.is_none() {
        let last = levels.last().expect("pyramid has a level");
        if last.sh / 2 < params.patch_size
            || last.sw / 2 < params.patch_size
            || last.th < 2
            || last.tw < 2
        {
            break;
        }
        let (next, m) = last.coarser(masks.last().expect("mask per level").as_deref());
        if next.allowed_list.is_empty() || next.need_count() == 0 {
            break;
        }
        levels.push(next);
        masks.push(m);
    }
    let mut evaluations = 0u64;
    let mut cells: Vec<Cell> = Vec::new();
    for li in (0..levels.len()).rev() {
        crate::cancel::check()?;
        let lvl = &levels[li];
        cells = if li + 1 == levels.len() {
            match input.init {
                Some(init) => lvl.initialise(params.seed, li, |i| {
                    let (r, c) = (init[2 * i], init[2 * i + 1]);
                    lvl.valid(i64::from(r), i64::from(c))
                }),
                None => lvl.initialise(params.seed, li, |_| None),
            }
        } else {
            let coarse = &levels[li + 1];
            let prev = &cells;
            lvl.initialise(params.seed, li, |i| {
                let (y, x) = (i / lvl.tw, i % lvl.tw);
                let (py, px) = ((y / 2).min(coarse.th - 1), (x / 2).min(coarse.tw - 1));
                let n = prev[py * coarse.tw + px].idx;
                if n == NONE {
                    return None;
                }
                let (sy, sx) = unpack(n);
                let (sy, sx) = (sy as i64, sx as i64);
                let r = lvl.r as i64;
                let cy = (2 * sy + (y - 2 * py) as i64).clamp(r, lvl.sh as i64 - 1 - r);
                let cx = (2 * sx + (x - 2 * px) as i64).clamp(r, lvl.sw as i64 - 1 - r);
                lvl.valid(cy, cx)
            })
        };
        for it in 0..params.iterations {
            crate::cancel::check()?;
            evaluations += lvl.iterate(&mut cells, params.seed, li, it);
        }
    }
    Ok(to_nnf(&levels[0], &cells, evaluations))
}

fn to_nnf(lvl: &Level<'_>, cells: &[Cell], evaluations: u64) -> Nnf {
    Nnf {
        h: lvl.th,
        w: lvl.tw,
        source_w: lvl.sw,
        idx: cells
            .iter()
            .map(|c| {
                if c.idx == NONE {
                    NONE
                } else {
                    let (y, x) = unpack(c.idx);
                    (y * lvl.sw + x) as u32
                }
            })
            .collect(),
        dist: cells.iter().map(|c| c.d).collect(),
        evaluations,
    }
}

/// The distance [`nnf`] assigns to matching target pixel `(ty, tx)` with the source patch
/// centred at `(sy, sx)`; unweighted. For tests and metrics.
#[must_use]
pub fn patch_distance(
    source: &Image<'_>,
    target: &Image<'_>,
    patch_size: usize,
    (ty, tx): (usize, usize),
    (sy, sx): (usize, usize),
) -> f32 {
    let r = patch_size as i64 / 2;
    let mut acc = 0f32;
    for dy in -r..=r {
        for dx in -r..=r {
            let (y, x) = (ty as i64 + dy, tx as i64 + dx);
            if y < 0 || x < 0 || y >= target.h as i64 || x >= target.w as i64 {
                continue;
            }
            let a = target.pixel(y as usize, x as usize);
            let b = source.pixel((sy as i64 + dy) as usize, (sx as i64 + dx) as usize);
            acc += a.iter().zip(b).map(|(u, v)| (u - v) * (u - v)).sum::<f32>();
        }
    }
    acc
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// A smooth-plus-noise test texture with structure at several scales.
    pub(crate) fn texture(h: usize, w: usize, c: usize, seed: u64) -> Vec<f32> {
        let mut rng = Rng::keyed(seed, 0, 0);
        let mut v = Vec::with_capacity(h * w * c);
        for y in 0..h {
            for x in 0..w {
                for k in 0..c {
                    let (fy, fx) = (y as f32, x as f32);
                    let base = ((fx * 0.31 + k as f32).sin() * (fy * 0.17).cos()
                        + (0.05 * (fx + 2.0 * fy)).sin())
                        * 0.4
                        + 0.5;
                    v.push(base + (rng.below(1000) as f32 / 1000.0 - 0.5) * 0.1);
                }
            }
        }
        v
    }

    fn run(
        src: &[f32],
        sh: usize,
        sw: usize,
        tgt: &[f32],
        th: usize,
        tw: usize,
        params: &NnfParams,
    ) -> Nnf {
        let input = NnfInput::new(
            Image::new("source", src, sh, sw, 3).unwrap(),
            Image::new("target", tgt, th, tw, 3).unwrap(),
        );
        nnf(&input, params).unwrap()
    }

    #[test]
    fn kernel_total_matches_naive_sum() {
        for n in [1usize, 5, 8, 13, 21, 24, 29, 50] {
            let a: Vec<f32> = (0..n).map(|i| i as f32 * 0.1).collect();
            let b: Vec<f32> = (0..n).map(|i| (i * i) as f32 * 0.01).collect();
            let naive: f32 = a.iter().zip(&b).map(|(x, y)| (x - y) * (x - y)).sum();
            let mut acc = Portable::zero();
            Portable::add_row(&mut acc, &a, &b);
            Portable::add_row(&mut acc, &b, &a);
            assert!(
                (Portable::total(&acc) - 2.0 * naive).abs() <= 1e-4 * naive.max(1.0),
                "n = {n}"
            );
        }
    }

    #[test]
    fn exact_finds_the_true_minimum() {
        let (sh, sw, th, tw) = (20, 24, 9, 11);
        let src = texture(sh, sw, 3, 1);
        let tgt = texture(th, tw, 3, 2);
        let f = run(
            &src,
            sh,
            sw,
            &tgt,
            th,
            tw,
            &NnfParams {
                method: Method::Exact,
                patch_size: 5,
                ..NnfParams::default()
            },
        );
        let s = Image::new("s", &src, sh, sw, 3).unwrap();
        let t = Image::new("t", &tgt, th, tw, 3).unwrap();
        for ty in 0..th {
            for tx in 0..tw {
                let mut best = f32::INFINITY;
                for sy in 2..sh - 2 {
                    for sx in 2..sw - 2 {
                        best = best.min(patch_distance(&s, &t, 5, (ty, tx), (sy, sx)));
                    }
                }
                let got = f.dist[ty * tw + tx];
                assert!(
                    (got - best).abs() <= 1e-4 * best.max(1.0),
                    "({ty},{tx}): {got} vs {best}"
                );
                let i = f.idx[ty * tw + tx] as usize;
                let d = patch_distance(&s, &t, 5, (ty, tx), (i / sw, i % sw));
                assert!((d - got).abs() <= 1e-4 * d.max(1.0));
            }
        }
    }

    #[test]
    fn patchmatch_recovers_a_shifted_copy() {
        // The target is a crop of the source: every interior pixel has a zero-distance match.
        let (sh, sw) = (64, 64);
        let src = texture(sh, sw, 3, 5);
        let (th, tw, oy, ox) = (32, 40, 13, 9);
        let mut tgt = Vec::with_capacity(th * tw * 3);
        for y in 0..th {
            for x in 0..tw {
                tgt.extend_from_slice(&src[((y + oy) * sw + x + ox) * 3..][..3]);
            }
        }
        let f = run(&src, sh, sw, &tgt, th, tw, &NnfParams::default());
        let exact_hits = (0..th * tw)
            .filter(|&i| {
                let (y, x) = (i / tw, i % tw);
                f.idx[i] as usize == (y + oy) * sw + x + ox
            })
            .count();
        assert!(
            exact_hits as f32 > 0.97 * (th * tw) as f32,
            "{exact_hits} of {}",
            th * tw
        );
    }

    #[test]
    fn identical_for_any_thread_count() {
        let (sh, sw, th, tw) = (70, 50, 45, 61);
        let src = texture(sh, sw, 3, 3);
        let tgt = texture(th, tw, 3, 4);
        let params = NnfParams {
            levels: 3,
            ..NnfParams::default()
        };
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let three = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap();
        let a = one.install(|| run(&src, sh, sw, &tgt, th, tw, &params));
        let b = three.install(|| run(&src, sh, sw, &tgt, th, tw, &params));
        assert_eq!(a.idx, b.idx);
        assert_eq!(
            a.dist.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            b.dist.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        assert_eq!(a.evaluations, b.evaluations);
    }

    #[test]
    fn masks_are_respected() {
        let (sh, sw, th, tw) = (40, 40, 30, 30);
        let src = texture(sh, sw, 3, 8);
        let tgt = texture(th, tw, 3, 9);
        let smask: Vec<bool> = (0..sh * sw).map(|i| (i % sw) < 20).collect();
        let tmask: Vec<bool> = (0..th * tw).map(|i| (i / tw) % 3 == 0).collect();
        let input = NnfInput {
            source_mask: Some(&smask),
            target_mask: Some(&tmask),
            ..NnfInput::new(
                Image::new("source", &src, sh, sw, 3).unwrap(),
                Image::new("target", &tgt, th, tw, 3).unwrap(),
            )
        };
        for method in [Method::PatchMatch, Method::Exact] {
            let f = nnf(
                &input,
                &NnfParams {
                    method,
                    levels: 2,
                    ..NnfParams::default()
                },
            )
            .unwrap();
            for (i, &s) in f.idx.iter().enumerate() {
                if tmask[i] {
                    assert_ne!(s, NONE);
                    let (y, x) = (s as usize / sw, s as usize % sw);
                    assert!(
                        smask[s as usize] && (3..sh - 3).contains(&y) && (3..sw - 3).contains(&x)
                    );
                } else {
                    assert_eq!(s, NONE);
                    assert!(f.dist[i].is_infinite());
                }
            }
        }
    }

    #[test]
    fn bad_arguments_are_named() {
        let src = texture(10, 10, 3, 1);
        let mut input = NnfInput::new(
            Image::new("source", &src, 10, 10, 3).unwrap(),
            Image::new("target", &src, 10, 10, 3).unwrap(),
        );
        let name = |r: Result<Nnf>| match r {
            Err(crate::Error::InvalidArgument { name, .. }) => name,
            other => panic!("expected an invalid argument, got {other:?}"),
        };
        assert_eq!(
            name(nnf(
                &input,
                &NnfParams {
                    patch_size: 4,
                    ..NnfParams::default()
                }
            )),
            "patch_size"
        );
        assert_eq!(
            name(nnf(
                &input,
                &NnfParams {
                    patch_size: 11,
                    ..NnfParams::default()
                }
            )),
            "patch_size"
        );
        let empty = vec![false; 100];
        input.target_mask = Some(&empty);
        assert_eq!(name(nnf(&input, &NnfParams::default())), "target_mask");
        input.target_mask = None;
        input.source_mask = Some(&empty);
        assert_eq!(name(nnf(&input, &NnfParams::default())), "source_mask");
        input.source_mask = None;
        let mut nan = src.clone();
        nan[17] = f32::NAN;
        input.target = Image::new("target", &nan, 10, 10, 3).unwrap();
        assert_eq!(name(nnf(&input, &NnfParams::default())), "target");
        input.target = Image::new("target", &src, 10, 10, 3).unwrap();
        let w = [1.0, -1.0, 1.0];
        input.weights = Some(&w);
        assert_eq!(name(nnf(&input, &NnfParams::default())), "weights");
        input.weights = None;
        let init = vec![0i32; 200];
        input.init = Some(&init);
        assert_eq!(name(nnf(&input, &NnfParams::default())), "init");
    }

    #[test]
    fn source_cost_steers_matches_away() {
        // Target is a crop of the source: the zero-distance match wins, unless it costs.
        let (sh, sw) = (40, 40);
        let src = texture(sh, sw, 3, 21);
        let (th, tw) = (12, 12);
        let mut tgt = Vec::new();
        for y in 0..th {
            for x in 0..tw {
                tgt.extend_from_slice(&src[((y + 10) * sw + x + 10) * 3..][..3]);
            }
        }
        let mut cost = vec![0f32; sh * sw];
        let mut input = NnfInput::new(
            Image::new("source", &src, sh, sw, 3).unwrap(),
            Image::new("target", &tgt, th, tw, 3).unwrap(),
        );
        let params = NnfParams {
            method: Method::Exact,
            ..NnfParams::default()
        };
        let free = nnf(&input, &params).unwrap();
        let at = |i: usize| ((i / tw) + 10) * sw + (i % tw) + 10;
        assert!((0..th * tw).all(|i| free.idx[i] as usize == at(i)));
        for i in 0..th * tw {
            cost[at(i)] = 1e6;
        }
        input.source_cost = Some(&cost);
        let taxed = nnf(&input, &params).unwrap();
        assert!((0..th * tw).all(|i| taxed.idx[i] as usize != at(i) && taxed.dist[i] < 1e6));
        let pm = nnf(&input, &NnfParams::default()).unwrap();
        assert!((0..th * tw).all(|i| pm.idx[i] as usize != at(i)));
        let mut negative = cost.clone();
        negative[0] = -1.0;
        input.source_cost = Some(&negative);
        assert!(nnf(&input, &params).is_err());
    }

    /// `Kernel::patch` with `NC` fixed, for every kernel, on the same data.
    fn patch_all<const NC: usize>(
        t: &[f32],
        s: &[f32],
        (rows, len): (usize, usize),
        (ts, ss): (usize, usize),
        (base, cutoff): (f32, f32),
    ) -> Vec<f32> {
        let args = ((1, ts), (2, ss), (rows, len));
        let mut out = vec![Portable::patch::<NC>(
            t, args.0, s, args.1, args.2, base, cutoff,
        )];
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            #[target_feature(enable = "avx2")]
            unsafe fn avx2<const NC: usize>(
                t: &[f32],
                s: &[f32],
                args: ((usize, usize), (usize, usize), (usize, usize)),
                base: f32,
                cutoff: f32,
            ) -> f32 {
                Avx2::patch::<NC>(t, args.0, s, args.1, args.2, base, cutoff)
            }
            // SAFETY: the CPU has AVX2 (checked above).
            out.push(unsafe { avx2::<NC>(t, s, args, base, cutoff) });
        }
        out
    }

    #[test]
    fn fixed_width_kernel_matches_row_by_row_sums() {
        // Rows of every length a fixed-width kernel takes, rows packed tightly (so the lanes
        // past a row's end hold the next row's values) and with slack, every cutoff regime.
        let mut rng = Rng::keyed(77, 0, 0);
        let mut val = || rng.below(1 << 20) as f32 / (1 << 16) as f32 - 8.0;
        for len in 1..=32 {
            for rows in [1, 2, 3, 7, 9] {
                for slack in [0, 5] {
                    let (ts, ss) = (len + slack, len + 2 * slack);
                    let t: Vec<f32> = (0..1 + rows * ts + PAD).map(|_| val()).collect();
                    let s: Vec<f32> = (0..2 + rows * ss + PAD).map(|_| val()).collect();
                    let mut acc = Portable::zero();
                    for k in 0..rows {
                        let (a, b) = (1 + k * ts, 2 + k * ss);
                        Portable::add_row(&mut acc, &t[a..a + len], &s[b..b + len]);
                    }
                    let full = 0.5 + Portable::total(&acc);
                    for cutoff in [f32::INFINITY, full, full * 0.5, 0.25] {
                        let ctx = (rows, len);
                        let got = match len.div_ceil(8) {
                            1 => patch_all::<1>(&t, &s, ctx, (ts, ss), (0.5, cutoff)),
                            2 => patch_all::<2>(&t, &s, ctx, (ts, ss), (0.5, cutoff)),
                            3 => patch_all::<3>(&t, &s, ctx, (ts, ss), (0.5, cutoff)),
                            _ => patch_all::<4>(&t, &s, ctx, (ts, ss), (0.5, cutoff)),
                        };
                        for d in &got {
                            if cutoff > full {
                                assert_eq!(d.to_bits(), full.to_bits(), "len {len} rows {rows}");
                            } else {
                                assert!(*d >= cutoff && *d <= full, "len {len} rows {rows}");
                            }
                        }
                        assert!(got.windows(2).all(|w| w[0].to_bits() == w[1].to_bits()));
                    }
                }
            }
        }
    }

    #[test]
    fn simd_and_portable_paths_agree_bit_for_bit() {
        let (sh, sw, th, tw) = (50, 60, 40, 45);
        let src = texture(sh, sw, 3, 31);
        let tgt = texture(th, tw, 3, 32);
        let params = NnfParams {
            levels: 2,
            ..NnfParams::default()
        };
        FORCE_PORTABLE.store(true, Ordering::Relaxed);
        let portable = run(&src, sh, sw, &tgt, th, tw, &params);
        FORCE_PORTABLE.store(false, Ordering::Relaxed);
        let fast = run(&src, sh, sw, &tgt, th, tw, &params);
        assert_eq!(portable.idx, fast.idx);
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&portable.dist), bits(&fast.dist));
    }

    #[test]
    fn simd_and_portable_agree_for_every_row_shape() {
        // Rows of 1..=60 values: every count of full chunks and every tail length.
        for (p, c) in [(1, 1), (3, 1), (3, 3), (5, 4), (7, 2), (9, 3), (11, 5)] {
            let (sh, sw, th, tw) = (30, 34, 17, 19);
            let src = texture(sh, sw, c, 40 + p as u64);
            let tgt = texture(th, tw, c, 50 + c as u64);
            let input = NnfInput::new(
                Image::new("source", &src, sh, sw, c).unwrap(),
                Image::new("target", &tgt, th, tw, c).unwrap(),
            );
            let params = NnfParams {
                patch_size: p,
                iterations: 3,
                ..NnfParams::default()
            };
            FORCE_PORTABLE.store(true, Ordering::Relaxed);
            let portable = nnf(&input, &params).unwrap();
            FORCE_PORTABLE.store(false, Ordering::Relaxed);
            let fast = nnf(&input, &params).unwrap();
            assert_eq!(portable.idx, fast.idx, "p = {p}, c = {c}");
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&portable.dist), bits(&fast.dist), "p = {p}, c = {c}");
        }
    }
}
