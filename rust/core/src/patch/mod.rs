//! Nearest-neighbour fields between two images: PatchMatch (Barnes, Shechtman, Finkelstein,
//! Goldman 2009, "PatchMatch: a randomized correspondence algorithm for structural image
//! editing"), PatchMatch seeded by kd-tree search (He & Sun 2012), and exact search, the
//! reference the other two are measured against.
//!
//! For every target pixel that needs a match, the field holds the centre of a source patch of
//! `patch_size × patch_size` pixels whose distance to the target patch centred there is
//! (approximately, for PatchMatch) minimal. Distances are weighted sums of squared differences
//! over all channels. Source patches always lie wholly inside the source; target patches are
//! clipped at the target border (only the part inside is compared), so every target pixel gets
//! a match; a tileable target is a torus instead, whose patches wrap around its borders.
//!
//! Parallelism and determinism: an iteration splits the target into stripes of
//! [`STRIPE_ROWS`] rows — a property of the image, not of the thread pool. Inside a stripe the
//! scan is sequential (raster order on even iterations, reverse on odd ones, as in the paper),
//! so propagation runs at full strength; across a stripe border a pixel reads its neighbour's
//! match from the previous iteration. Every pixel draws its random numbers from its own
//! stream keyed by `(seed, level, iteration, pixel)`. Together these make the result
//! bit-identical for any number of threads.
//!
//! Layout: this file holds the API, its parameters and their validation; `level` one
//! resolution of the problem and the distances every method shares, `patchmatch` the
//! propagation and random search, `kd_seed` the kd-tree start, `exact` brute force. The SIMD
//! kernels live in [`crate::distance`].

mod exact;
mod kd_seed;
mod level;
mod patchmatch;

use std::borrow::Cow;

use crate::error::{invalid, Result};
use crate::image::{prescale, Image};

use level::{pack, unpack, Cell, Level};

/// The kernels' switch to the portable path ([`crate::distance::FORCE_PORTABLE`]).
pub use crate::distance::FORCE_PORTABLE;

/// Rows per work unit of one PatchMatch iteration. Fixed, so that results do not depend on
/// the thread count.
pub const STRIPE_ROWS: usize = 16;

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
pub(crate) const KD_PCA_SAMPLES: usize = 2048;

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
    /// The target is a torus (a tileable texture): a target patch near an edge continues on
    /// the opposite side instead of being clipped, and propagation crosses the wrap. Source
    /// patches still lie wholly inside the source. Default false.
    pub tileable: bool,
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
            tileable: false,
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

/// Largest source side the packed positions can hold.
pub const MAX_SOURCE_SIDE: usize = 0xFFFF;

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
    // Matching an image against itself (same buffer and shape) keeps one prescaled copy.
    let same = std::ptr::eq(s.data, t.data) && (s.h, s.w) == (t.h, t.w);
    s.check_finite("source")?;
    if !same {
        t.check_finite("target")?;
    }
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
    let tgt = if same {
        None
    } else {
        Some(Cow::Owned(prescale(&t, input.weights)?))
    };
    let level = Level::new(
        Cow::Owned(src),
        (s.h, s.w),
        tgt,
        (t.h, t.w),
        s.c,
        p / 2,
        input.source_mask,
        input.target_mask.map(Cow::Borrowed),
        input.tileable,
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
    distance_at(source, target, patch_size, (ty, tx), (sy, sx), false)
}

/// [`patch_distance`], on a torus target with `tileable` (offsets wrap around the target).
fn distance_at(
    source: &Image<'_>,
    target: &Image<'_>,
    patch_size: usize,
    (ty, tx): (usize, usize),
    (sy, sx): (usize, usize),
    tileable: bool,
) -> f32 {
    use crate::vote::wrap_or_skip;
    let r = patch_size as i64 / 2;
    let mut acc = 0f32;
    for dy in -r..=r {
        for dx in -r..=r {
            let y = wrap_or_skip(ty as i64 + dy, target.h, tileable);
            let x = wrap_or_skip(tx as i64 + dx, target.w, tileable);
            let (Some(y), Some(x)) = (y, x) else {
                continue;
            };
            let a = target.pixel(y, x);
            let b = source.pixel((sy as i64 + dy) as usize, (sx as i64 + dx) as usize);
            acc += a.iter().zip(b).map(|(u, v)| (u - v) * (u - v)).sum::<f32>();
        }
    }
    acc
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::distance::FORCE_PORTABLE;
    use crate::rng::Rng;
    use std::sync::atomic::Ordering;

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
    fn self_matching_on_one_buffer_equals_matching_a_copy() {
        // Completion's call: the image against itself, a hole to match, the rest as sources,
        // over two pyramid levels and several stripes (the rows read across stripe borders).
        let (h, w) = (70, 45);
        let img = texture(h, w, 3, 5);
        let copy = img.clone();
        let need: Vec<bool> = (0..h * w).map(|i| (20..50).contains(&(i / w))).collect();
        let source: Vec<bool> = need.iter().map(|v| !v).collect();
        for levels in [1, 2] {
            let params = NnfParams {
                patch_size: 5,
                iterations: 3,
                levels,
                seed: 9,
                method: Method::PatchMatch,
            };
            let fields = [&img, &copy].map(|t| {
                let input = NnfInput {
                    source_mask: Some(&source),
                    target_mask: Some(&need),
                    ..NnfInput::new(
                        Image::new("source", &img, h, w, 3).unwrap(),
                        Image::new("target", t, h, w, 3).unwrap(),
                    )
                };
                nnf(&input, &params).unwrap()
            });
            assert_eq!(fields[0].idx, fields[1].idx);
            let bits = |f: &Nnf| f.dist.iter().map(|d| d.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&fields[0]), bits(&fields[1]));
        }
    }

    /// Asserts that every distance of `f` is the minimum of `dist(target pixel, source
    /// centre)` over all source centres of 5×5 patches of an `sh × sw` source.
    fn assert_exact(
        f: &Nnf,
        (sh, sw): (usize, usize),
        (th, tw): (usize, usize),
        dist: impl Fn((usize, usize), (usize, usize)) -> f32,
    ) {
        for ty in 0..th {
            for tx in 0..tw {
                let mut best = f32::INFINITY;
                for sy in 2..sh - 2 {
                    for sx in 2..sw - 2 {
                        best = best.min(dist((ty, tx), (sy, sx)));
                    }
                }
                let got = f.dist[ty * tw + tx];
                assert!(
                    (got - best).abs() <= 1e-4 * best.max(1.0),
                    "({ty},{tx}): {got} vs {best}"
                );
                let i = f.idx[ty * tw + tx] as usize;
                let d = dist((ty, tx), (i / sw, i % sw));
                assert!((d - got).abs() <= 1e-4 * d.max(1.0));
            }
        }
    }

    #[test]
    fn tileable_exact_is_the_minimum_over_wrapped_patches() {
        // Every target pixel, the corners included, compares its whole wrapped patch; both
        // the general and the fixed-width kernels (c = 1 and c = 5 rows) are exercised.
        for c in [1, 5] {
            let (sh, sw, th, tw) = (18, 21, 9, 11);
            let src = texture(sh, sw, c, 11);
            let tgt = texture(th, tw, c, 12);
            let (s, t) = (
                Image::new("source", &src, sh, sw, c).unwrap(),
                Image::new("target", &tgt, th, tw, c).unwrap(),
            );
            let input = NnfInput {
                tileable: true,
                ..NnfInput::new(s, t)
            };
            let params = NnfParams {
                method: Method::Exact,
                patch_size: 5,
                ..NnfParams::default()
            };
            let f = nnf(&input, &params).unwrap();
            assert_exact(&f, (sh, sw), (th, tw), |tp, sp| {
                distance_at(&s, &t, 5, tp, sp, true)
            });
        }
    }

    #[test]
    fn tileable_patchmatch_finds_patches_across_the_wrap() {
        // The source is a 2×2 tiling of a periodic tile, the target that tile rolled: on the
        // torus every target patch, those across the wrap included, has an exact copy.
        let (h, w, p) = (40, 36, 7);
        let tile = texture(h, w, 3, 13);
        let (sh, sw) = (2 * h, 2 * w);
        let mut src = Vec::with_capacity(sh * sw * 3);
        for y in 0..sh {
            for x in 0..sw {
                src.extend_from_slice(&tile[((y % h) * w + x % w) * 3..][..3]);
            }
        }
        let mut tgt = Vec::with_capacity(h * w * 3);
        for y in 0..h {
            for x in 0..w {
                tgt.extend_from_slice(&tile[(((y + 17) % h) * w + (x + 5) % w) * 3..][..3]);
            }
        }
        let input = NnfInput {
            tileable: true,
            ..NnfInput::new(
                Image::new("source", &src, sh, sw, 3).unwrap(),
                Image::new("target", &tgt, h, w, 3).unwrap(),
            )
        };
        let params = NnfParams {
            patch_size: p,
            iterations: 6,
            levels: 2,
            ..NnfParams::default()
        };
        let f = nnf(&input, &params).unwrap();
        let wrap_rows: Vec<usize> = (0..h * w)
            .filter(|i| {
                let (y, x) = (i / w, i % w);
                y < 3 || x < 3 || y + 3 >= h || x + 3 >= w
            })
            .collect();
        let exact = wrap_rows.iter().filter(|&&i| f.dist[i] == 0.0).count();
        assert!(
            exact as f32 > 0.9 * wrap_rows.len() as f32,
            "{exact} of {} patches across the wrap found exactly",
            wrap_rows.len()
        );
        // The same run on one thread and on three gives the same field.
        for n in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap();
            assert_eq!(pool.install(|| nnf(&input, &params).unwrap()).idx, f.idx);
        }
        // The kd-tree start reads the wrapped target patches too.
        let kd = nnf(
            &input,
            &NnfParams {
                method: Method::KdTree,
                ..params.clone()
            },
        )
        .unwrap();
        let kd_exact = wrap_rows.iter().filter(|&&i| kd.dist[i] == 0.0).count();
        assert!(kd_exact as f32 > 0.9 * wrap_rows.len() as f32);
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
        assert_exact(&f, (sh, sw), (th, tw), |tp, sp| {
            patch_distance(&s, &t, 5, tp, sp)
        });
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
