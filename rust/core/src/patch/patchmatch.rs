//! PatchMatch iterations (Barnes et al. 2009): propagation from the scan-order neighbours,
//! forward enrichment from the source's own nearest patches (Barnes et al. 2010), and random
//! search with a halving radius, over stripes of [`STRIPE_ROWS`] rows.

#![allow(clippy::inline_always)]

use std::sync::atomic::{AtomicU64, Ordering};

use rayon::prelude::*;

#[cfg(target_arch = "x86_64")]
use crate::distance::Avx2;
use crate::distance::{avx2_enabled, Kernel, Portable};
use crate::rng::Rng;

use super::level::{pack, unpack, Cell, Level, EMPTY};
use super::{NONE, STRIPE_ROWS};

/// What one pass over the stripes shares.
struct Pass<'p> {
    /// Per stripe, the row of the field before this iteration that the stripe reads across
    /// its border: the one above it on forward scans, the one below on reverse scans.
    prev: &'p [Cell],
    seed: u64,
    level: usize,
    it: usize,
}

impl Level<'_> {
    /// One PatchMatch iteration (propagation + random search) over the whole target.
    pub(super) fn iterate(&self, cells: &mut [Cell], seed: u64, level: usize, it: usize) -> u64 {
        let tw = self.tw;
        // Only the rows next to a stripe are read from the previous field, so only they are
        // kept (a sixteenth of the field).
        let reverse = it % 2 == 1;
        let mut prev = vec![EMPTY; self.th.div_ceil(STRIPE_ROWS) * tw];
        for (stripe, row) in prev.chunks_exact_mut(tw).enumerate() {
            let y = if reverse {
                (stripe + 1) * STRIPE_ROWS
            } else {
                (stripe * STRIPE_ROWS).wrapping_sub(1)
            };
            // On a torus the first stripe reads the last row and the last stripe the first.
            let y = match (self.tileable, reverse) {
                (true, false) if stripe == 0 => self.th - 1,
                (true, true) if y >= self.th => 0,
                _ => y,
            };
            if y < self.th {
                row.copy_from_slice(&cells[y * tw..(y + 1) * tw]);
            }
        }
        let evals = AtomicU64::new(0);
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
                let at = (y, x, self.interior(y, x));
                // Propagation: the neighbour one step back along the scan, shifted; on a
                // torus the scan's first pixel reads the row's last one (as last iteration
                // left it, the scan inside a stripe being sequential).
                let mut nx = x as i64 + step;
                if self.tileable {
                    nx = nx.rem_euclid(tw as i64);
                }
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
                } else if self.tileable || (ny >= 0 && ny < self.th as i64) {
                    pass.prev[stripe * tw + x].idx
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
                // samples are drawn first.
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
}
