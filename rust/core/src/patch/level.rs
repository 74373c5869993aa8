//! One resolution of a matching problem ([`Level`]): prescaled, padded buffers, the allowed
//! source centres, and the patch distances every search method shares; plus the 2×2
//! halving that builds the coarse-to-fine pyramid.

#![allow(clippy::inline_always)]

use std::borrow::Cow;

use rayon::prelude::*;

#[cfg(target_arch = "x86_64")]
use crate::distance::Avx2;
use crate::distance::{avx2_enabled, Kernel, Portable, PAD};
use crate::image::wrap_pad;
use crate::rng::Rng;

use super::NONE;

/// Source positions inside a level are packed as `row << 16 | col`: decoding is two shifts
/// instead of two divisions by the width, which the hot loop does for every candidate. Sides
/// are at most [`super::MAX_SOURCE_SIDE`].
#[inline(always)]
pub(super) fn pack(y: usize, x: usize) -> u32 {
    ((y as u32) << 16) | x as u32
}

#[inline(always)]
pub(super) fn unpack(p: u32) -> (usize, usize) {
    ((p >> 16) as usize, (p & 0xFFFF) as usize)
}

/// One target pixel's match: the packed source centre (or [`NONE`]) and its distance.
#[derive(Clone, Copy, Debug)]
pub(super) struct Cell {
    pub(super) idx: u32,
    pub(super) d: f32,
}

pub(super) const EMPTY: Cell = Cell {
    idx: NONE,
    d: f32::INFINITY,
};

/// One resolution of a matching problem: prescaled buffers, dimensions and constraints.
pub(super) struct Level<'a> {
    /// Source values, followed by [`PAD`] zeros.
    pub(super) src: Vec<f32>,
    pub(super) sh: usize,
    pub(super) sw: usize,
    /// Target values, followed by [`PAD`] zeros; `None` when the target is the source
    /// (self-matching, as completion does), which then is neither copied nor halved twice.
    /// A tileable target is stored wrapped by `r` pixels on every side (`tgt_off = r`).
    tgt: Option<Vec<f32>>,
    pub(super) th: usize,
    pub(super) tw: usize,
    /// The target is a torus: patches near an edge continue on the opposite side, so every
    /// target patch is whole (never clipped) and propagation crosses the wrap.
    pub(super) tileable: bool,
    /// Pixels of padding before the target's first row and column in `tgt` (0 or `r`).
    tgt_off: usize,
    /// Row length of `tgt` in pixels (`tw + 2 * tgt_off`).
    tgt_stride: usize,
    pub(super) c: usize,
    pub(super) r: usize,
    /// Per source pixel: may be a patch centre (mask and border both allow it).
    pub(super) allowed: Vec<bool>,
    pub(super) allowed_list: Vec<u32>,
    /// Whether a source mask restricts centres beyond the border (else `allowed` need not be
    /// read, which saves a cache miss per random candidate).
    pub(super) masked: bool,
    /// Per target pixel: needs a match.
    pub(super) need: Option<Cow<'a, [bool]>>,
    /// Source self-similarity lists for enrichment, `k` packed positions per source pixel.
    pub(super) knn: Option<(Vec<u32>, usize)>,
    /// Additive cost per source centre.
    pub(super) cost: Option<&'a [f32]>,
}

impl Level<'_> {
    pub(super) fn new<'b>(
        src: Cow<'b, [f32]>,
        (sh, sw): (usize, usize),
        tgt: Option<Cow<'b, [f32]>>,
        (th, tw): (usize, usize),
        c: usize,
        r: usize,
        source_mask: Option<&[bool]>,
        need: Option<Cow<'b, [bool]>>,
        tileable: bool,
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
        // A torus target gets its own copy grown by the wrap, even when it is the source.
        let tgt_off = if tileable { r } else { 0 };
        let tgt = if tileable {
            let t = tgt.as_deref().unwrap_or(&src[..sh * sw * c]);
            Some(pad(Cow::Owned(wrap_pad(t, th, tw, c, r))))
        } else {
            tgt.map(pad)
        };
        Level {
            src: pad(src),
            sh,
            sw,
            tgt,
            th,
            tw,
            tileable,
            tgt_off,
            tgt_stride: tw + 2 * tgt_off,
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

    /// Target values, followed by [`PAD`] zeros.
    #[inline(always)]
    pub(super) fn tgt(&self) -> &[f32] {
        self.tgt.as_deref().unwrap_or(&self.src)
    }

    /// Whether the target patch at `(y, x)` is whole: inside the target, or anywhere on a
    /// torus.
    #[inline(always)]
    pub(super) fn interior(&self, y: usize, x: usize) -> bool {
        let r = self.r;
        self.tileable || (y >= r && x >= r && y + r < self.th && x + r < self.tw)
    }

    /// The `c` values of target pixel `(y, x)`, wrapped around a tileable target.
    #[inline]
    pub(super) fn target_pixel(&self, y: i64, x: i64) -> Option<&[f32]> {
        let (h, w) = (self.th as i64, self.tw as i64);
        let (y, x) = if self.tileable {
            (y.rem_euclid(h), x.rem_euclid(w))
        } else if y < 0 || x < 0 || y >= h || x >= w {
            return None;
        } else {
            (y, x)
        };
        let o = y as usize + self.tgt_off;
        let t0 = (o * self.tgt_stride + x as usize + self.tgt_off) * self.c;
        Some(&self.tgt()[t0..t0 + self.c])
    }

    #[inline]
    pub(super) fn needs(&self, i: usize) -> bool {
        self.need.as_ref().is_none_or(|m| m[i])
    }

    /// Distance between the target patch at `(ty, tx)` and the source patch centred at `s`,
    /// abandoning the sum once it reaches `cutoff`.
    #[inline(always)]
    pub(super) fn dist(&self, ty: usize, tx: usize, s: u32, cutoff: f32) -> f32 {
        self.dist_with::<Portable>(ty, tx, s, cutoff)
    }

    #[inline(always)]
    pub(super) fn dist_with<K: Kernel>(&self, ty: usize, tx: usize, s: u32, cutoff: f32) -> f32 {
        let (sy, sx) = unpack(s);
        let r = self.r;
        // A tileable target's padded copy holds every patch whole.
        let (dy0, dy1, dx0, dx1) = if self.tileable {
            (r, r, r, r)
        } else {
            (
                ty.min(r),
                (self.th - 1 - ty).min(r),
                tx.min(r),
                (self.tw - 1 - tx).min(r),
            )
        };
        let (o, stride) = (self.tgt_off, self.tgt_stride);
        let len = (dx0 + dx1 + 1) * self.c;
        let base = self.cost.map_or(0.0, |c| c[sy * self.sw + sx]);
        if base >= cutoff {
            return base;
        }
        let mut acc = K::zero();
        let rows = dy0 + dy1 + 1;
        for k in 0..rows {
            let t0 = ((ty + o - dy0 + k) * stride + tx + o - dx0) * self.c;
            let s0 = ((sy - dy0 + k) * self.sw + sx - dx0) * self.c;
            K::add_row(&mut acc, &self.tgt()[t0..t0 + len], &self.src[s0..s0 + len]);
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
    pub(super) fn dist_interior<K: Kernel, const NC: usize>(
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
        let (o, stride) = (self.tgt_off, self.tgt_stride);
        K::patch::<NC>(
            self.tgt(),
            (((ty + o - r) * stride + tx + o - r) * c, stride * c),
            &self.src,
            (((sy - r) * self.sw + sx - r) * c, self.sw * c),
            (2 * r + 1, (2 * r + 1) * c),
            base,
            cutoff,
        )
    }

    #[inline(always)]
    pub(super) fn valid(&self, y: i64, x: i64) -> Option<u32> {
        let r = self.r as i64;
        if y < r || x < r || y >= (self.sh as i64) - r || x >= (self.sw as i64) - r {
            return None;
        }
        let (y, x) = (y as usize, x as usize);
        (!self.masked || self.allowed[y * self.sw + x]).then_some(pack(y, x))
    }

    pub(super) fn random_allowed(&self, rng: &mut Rng) -> u32 {
        self.allowed_list[rng.below(self.allowed_list.len() as u64) as usize]
    }

    /// Starting field: `guess(pixel)` where it proposes an allowed centre, random elsewhere.
    pub(super) fn initialise(
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
    pub(super) fn chunks(&self) -> usize {
        match (2 * self.r + 1) * self.c {
            n @ 1..=32 => n.div_ceil(8),
            _ => 0,
        }
    }

    /// Sets the distance of every cell with a match, on the fastest kernel.
    pub(super) fn fill_distances(&self, cells: &mut [Cell]) {
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
    pub(super) unsafe fn distances_avx2<const NC: usize>(&self, y: usize, row: &mut [Cell]) {
        self.distances::<Avx2, NC>(y, row);
    }

    /// The distances of target row `y`'s matches.
    #[inline(always)]
    pub(super) fn distances<K: Kernel, const NC: usize>(&self, y: usize, row: &mut [Cell]) {
        for (x, cell) in row.iter_mut().enumerate() {
            if cell.idx == NONE {
                continue;
            }
            cell.d = if NC > 0 && self.interior(y, x) {
                self.dist_interior::<K, NC>(y, x, cell.idx, f32::INFINITY)
            } else {
                self.dist_with::<K>(y, x, cell.idx, f32::INFINITY)
            };
        }
    }

    pub(super) fn need_count(&self) -> usize {
        self.need
            .as_ref()
            .map_or(self.th * self.tw, |m| m.iter().filter(|v| **v).count())
    }

    /// Half-resolution copy: 2×2 box average of images, AND of the source mask, OR of the
    /// target mask.
    pub(super) fn coarser(
        &self,
        source_mask: Option<&[bool]>,
    ) -> (Level<'static>, Option<Vec<bool>>) {
        let (src, sh, sw) = half(&self.src, self.sh, self.sw, self.c);
        let (tgt, th, tw) = match &self.tgt {
            Some(t) => {
                let (t, th, tw) = if self.tileable {
                    let logical = self.target_image();
                    half(&logical, self.th, self.tw, self.c)
                } else {
                    half(t, self.th, self.tw, self.c)
                };
                (Some(Cow::Owned(t)), th, tw)
            }
            None => (None, sh, sw),
        };
        let smask = source_mask.map(|m| half_mask(m, self.sh, self.sw, true));
        let need = self
            .need
            .as_ref()
            .map(|m| Cow::Owned(half_mask(m, self.th, self.tw, false)));
        let lvl = Level::new(
            Cow::Owned(src),
            (sh, sw),
            tgt,
            (th, tw),
            self.c,
            self.r,
            smask.as_deref(),
            need,
            self.tileable,
        );
        (lvl, smask)
    }

    /// The target's `th × tw × c` values without the wrap padding.
    fn target_image(&self) -> Vec<f32> {
        let (o, stride, c) = (self.tgt_off, self.tgt_stride, self.c);
        let mut out = Vec::with_capacity(self.th * self.tw * c);
        for y in 0..self.th {
            let t0 = ((y + o) * stride + o) * c;
            out.extend_from_slice(&self.tgt()[t0..t0 + self.tw * c]);
        }
        out
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
