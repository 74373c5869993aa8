//! The discrete k-coherence solver of one pyramid level (§3.3.5): the M-step (Eq. 3.4) over
//! the coherence candidates plus a random search, and the E-step (Eq. 3.5) that turns the
//! forward-shifted matches covering each pixel into its reference.

// `#[inline(always)]` on the distance helpers is deliberate: only code inlined into
// `m_pixel_avx2` is compiled with AVX2 enabled (see `crate::distance`).
#![allow(clippy::inline_always)]

use rayon::prelude::*;

#[cfg(target_arch = "x86_64")]
use crate::distance::Avx2;
use crate::distance::{avx2_enabled, Kernel, Portable};
use crate::error::Result;
use crate::image::{mirror_pad, wrap_pad, Image};
use crate::knn::{self, coherence_candidates, knn, shift, Knn, KnnParams};
use crate::patch::NONE;
use crate::rng::Rng;

use super::{init, level_iterations, Selection, TbnParams};

/// E-step vote weights are `max(d, floor)^−ROBUST_POWER` for a match at distance `d`.
const ROBUST_POWER: f32 = 0.6;
/// Passes of the approximate k-NN search per level (more gain nothing measurable).
const KNN_ITERATIONS: usize = 2;

#[inline]
pub(super) fn out_index(y: i64, x: i64, h: usize, w: usize, tileable: bool) -> Option<usize> {
    if tileable {
        Some(y.rem_euclid(h as i64) as usize * w + x.rem_euclid(w as i64) as usize)
    } else if y < 0 || x < 0 || y >= h as i64 || x >= w as i64 {
        None
    } else {
        Some(y as usize * w + x as usize)
    }
}

/// A padded image whose `p × p` patches are contiguous rows of `p · c` values.
struct Padded {
    data: Vec<f32>,
    pw: usize,
    w: usize,
    c: usize,
}

impl Padded {
    #[inline]
    fn row(&self, i: usize, k: usize, p: usize) -> &[f32] {
        let (y, x) = (i / self.w, i % self.w);
        &self.data[((y + k) * self.pw + x) * self.c..][..p * self.c]
    }

    #[inline]
    fn centre(&self, i: usize, r: usize) -> &[f32] {
        let (y, x) = (i / self.w, i % self.w);
        &self.data[((y + r) * self.pw + x + r) * self.c..][..self.c]
    }
}

#[inline]
fn ssd(a: &[f32], b: &[f32]) -> f32 {
    // Eight lanes, so the compiler vectorises without reassociating a single sum.
    let mut acc = [0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            let d = x[l] - y[l];
            acc[l] += d * d;
        }
    }
    let mut s: f32 = acc.iter().sum();
    for (x, y) in ra.iter().zip(rb) {
        s += (x - y) * (x - y);
    }
    s
}

/// The weighted medoid of `votes` (exemplar index, weight): the vote `e` minimising
/// `Σ_j w_j · ‖e − e_j‖` over the first `c0` channels of `aug` (pixel stride `ca`); ties go
/// to the smallest index. Sorts `votes` and merges repeats (summing their weights) in place.
fn weighted_medoid(votes: &mut Vec<(u32, f32)>, aug: &[f32], ca: usize, c0: usize) -> u32 {
    votes.sort_unstable_by_key(|v| v.0);
    votes.dedup_by(|b, a| {
        if a.0 == b.0 {
            a.1 += b.1;
            true
        } else {
            false
        }
    });
    let px = |e: u32| &aug[e as usize * ca..e as usize * ca + c0];
    let mut best = votes[0].0;
    let mut bc = f32::INFINITY;
    for &(e, _) in votes.iter() {
        let a = px(e);
        let mut cost = 0f32;
        for &(f, wf) in votes.iter() {
            if f != e {
                cost += wf * ssd(a, px(f)).sqrt();
                if cost >= bc {
                    break;
                }
            }
        }
        if cost < bc {
            bc = cost;
            best = e;
        }
    }
    best
}

/// `N_lr` distance (the patch without its centre) between output pixel `i` of `s` and
/// exemplar pixel `j` of `e`, stopping early once past `cutoff` (checked every other row; the
/// centre is subtracted from the start, so a partial sum never overestimates).
#[inline(always)]
fn patch_dist<K: Kernel>(s: &Padded, i: usize, e: &Padded, j: usize, p: usize, cutoff: f32) -> f32 {
    let r = p / 2;
    let centre = ssd(s.centre(i, r), e.centre(j, r));
    let mut acc = K::zero();
    for k in 0..p {
        K::add_row(&mut acc, s.row(i, k, p), e.row(j, k, p));
        if k % 2 == 1 && k + 1 < p {
            let partial = K::total(&acc) - centre;
            if partial >= cutoff {
                return partial;
            }
        }
    }
    K::total(&acc) - centre
}

/// What the M-step of one iteration shares.
struct MStep<'b> {
    s: &'b Padded,
    cands: &'b [u32],
    m: usize,
    refs: &'b [u32],
    key: u64,
}

/// One pyramid level's exemplar side.
pub(super) struct ExLevel {
    pub(super) h: usize,
    pub(super) w: usize,
    /// Augmented channels: weighted exemplar channels then scaled one-hot labels.
    pub(super) aug: Vec<f32>,
    pub(super) labels: Vec<u32>,
    pub(super) by_label: Vec<Vec<u32>>,
}

/// The solver at one pyramid level.
pub(super) struct Level<'a> {
    el: &'a ExLevel,
    labels_out: &'a [u32],
    h: usize,
    w: usize,
    ca: usize,
    c0: usize,
    p: usize,
    ex_pad: Padded,
    table: Option<Knn>,
    params: &'a TbnParams,
    depth: usize,
    lv: f32,
}

impl<'a> Level<'a> {
    #[allow(clippy::too_many_arguments)]
    pub(super) fn new(
        el: &'a ExLevel,
        labels_out: &'a [u32],
        h: usize,
        w: usize,
        ca: usize,
        c0: usize,
        p: usize,
        params: &'a TbnParams,
        level: usize,
    ) -> Result<Self> {
        let r = p / 2;
        // A coarse level can be too small to hold k - 1 neighbours outside each patch's
        // excluded window; it then searches coherence candidates only (k = 1). Every other
        // k-NN failure is an error, not a silent fallback.
        let table = if params.k > 1 && knn::fits(el.h, el.w, r, params.k - 1) {
            let img = Image::new("exemplar", &el.aug, el.h, el.w, ca)?;
            knn(
                &img,
                None,
                &KnnParams {
                    patch_size: p,
                    k: params.k - 1,
                    iterations: KNN_ITERATIONS,
                    exact: false,
                    exclude: r,
                    seed: params.seed ^ (level as u64).wrapping_mul(0x9E37),
                },
            )
            .map(Some)?
        } else {
            None
        };
        Ok(Self {
            el,
            labels_out,
            h,
            w,
            ca,
            c0,
            p,
            ex_pad: Padded {
                data: mirror_pad(&el.aug, el.h, el.w, ca, r),
                pw: el.w + 2 * r,
                w: el.w,
                c: ca,
            },
            table,
            params,
            depth: level,
            lv: (params.label_weight / 2.0).sqrt(),
        })
    }

    /// `concat(B, B'_ref)`, padded by mirroring (or wrapping for tileable outputs).
    fn output_image(&self, refs: &[u32]) -> Padded {
        let (ca, c0) = (self.ca, self.c0);
        let mut s = vec![0f32; self.h * self.w * ca];
        s.par_chunks_mut(ca).enumerate().for_each(|(i, px)| {
            let e = refs[i] as usize;
            px[..c0].copy_from_slice(&self.el.aug[e * ca..e * ca + c0]);
            px[c0 + self.labels_out[i] as usize] = self.lv;
        });
        let r = self.p / 2;
        let data = if self.params.tileable {
            wrap_pad(&s, self.h, self.w, ca, r)
        } else {
            mirror_pad(&s, self.h, self.w, ca, r)
        };
        Padded {
            data,
            pw: self.w + 2 * r,
            w: self.w,
            c: ca,
        }
    }

    /// Eq. 3.4 for output pixel `i`: the best same-label candidate and its distance, or
    /// `NONE` when neither a candidate nor the current reference has the pixel's label.
    #[inline(always)]
    fn m_pixel_with<K: Kernel>(&self, ms: &MStep<'_>, i: usize) -> (u32, f32) {
        let (p, eh, ew) = (self.p, self.el.h, self.el.w);
        let lb = self.labels_out[i];
        let mut best = NONE;
        let mut bd = f32::INFINITY;
        for &c in &ms.cands[i * ms.m..(i + 1) * ms.m] {
            if c == NONE {
                break;
            }
            if self.el.labels[c as usize] != lb {
                continue;
            }
            let d = patch_dist::<K>(ms.s, i, &self.ex_pad, c as usize, p, bd);
            if d < bd {
                bd = d;
                best = c;
            }
        }
        if best == NONE {
            let cur = ms.refs[i];
            if self.el.labels[cur as usize] != lb {
                return (NONE, f32::INFINITY);
            }
            best = cur;
            bd = patch_dist::<K>(ms.s, i, &self.ex_pad, cur as usize, p, f32::INFINITY);
        }
        if self.params.random_search {
            let mut rng = Rng::keyed(self.params.seed, ms.key, i as u64);
            let (by, bx) = ((best as usize / ew) as i64, (best as usize % ew) as i64);
            let mut rad = eh.max(ew) as i64;
            while rad >= 1 {
                let y = rng.range_inclusive((by - rad).max(0), (by + rad).min(eh as i64 - 1));
                let x = rng.range_inclusive((bx - rad).max(0), (bx + rad).min(ew as i64 - 1));
                let c = y as usize * ew + x as usize;
                if self.el.labels[c] == lb {
                    let d = patch_dist::<K>(ms.s, i, &self.ex_pad, c, p, bd);
                    if d < bd {
                        bd = d;
                        best = c as u32;
                    }
                }
                rad /= 2;
            }
        }
        (best, bd)
    }

    /// [`Self::m_pixel_with`] with the fastest kernel the CPU has.
    fn m_pixel(&self, ms: &MStep<'_>, i: usize, fast: bool) -> (u32, f32) {
        #[cfg(target_arch = "x86_64")]
        if fast {
            // SAFETY: `fast` is only true when the CPU supports AVX2 (`avx2_enabled`).
            return unsafe { self.m_pixel_avx2(ms, i) };
        }
        let _ = fast;
        self.m_pixel_with::<Portable>(ms, i)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn m_pixel_avx2(&self, ms: &MStep<'_>, i: usize) -> (u32, f32) {
        self.m_pixel_with::<Avx2>(ms, i)
    }

    /// Whether iteration `it` at this level picks medoids (else nearest to the average).
    fn medoid(&self, it: usize) -> bool {
        match self.params.selection {
            Selection::Average => false,
            Selection::Medoid => true,
            Selection::Hybrid => {
                self.depth != 0 || it + 1 < level_iterations(self.params.iterations, 0)
            }
        }
    }

    /// One M-step + E-step.
    pub(super) fn iterate(&self, refs: &[u32], it: usize) -> Result<Vec<u32>> {
        let (h, w, p) = (self.h, self.w, self.p);
        let (eh, ew) = (self.el.h, self.el.w);
        let r = (p / 2) as i64;
        let seed = self.params.seed;
        let key = (self.depth as u64) << 32 | it as u64;
        let (cands, m) = coherence_candidates(
            refs,
            h,
            w,
            eh,
            ew,
            self.table.as_ref(),
            p,
            self.params.wrap,
            self.params.wrap,
        )?;
        crate::cancel::check()?;
        let s = self.output_image(refs);
        // X†: every other row and column, at an offset drawn per iteration, at the coarse
        // levels; every pixel at the finest, which decides the output's fine coherence.
        let st = if self.depth == 0 { 1 } else { 2 };
        let mut grid_rng = Rng::keyed(seed, key, u64::MAX);
        let (gy, gx) = (
            grid_rng.below(st as u64) as usize,
            grid_rng.below(st as u64) as usize,
        );
        let labels_in = &self.el.labels;
        let labels_out = self.labels_out;

        // M-step (Eq. 3.4).
        let ms = MStep {
            s: &s,
            cands: &cands,
            m,
            refs,
            key,
        };
        let fast = avx2_enabled();
        let mut matches = vec![NONE; h * w];
        let mut mdist = vec![f32::INFINITY; h * w];
        matches
            .par_chunks_mut(w)
            .zip(mdist.par_chunks_mut(w))
            .enumerate()
            .for_each(|(y, (row, drow))| {
                if y % st != gy || crate::cancel::cancelled() {
                    return;
                }
                for x in (gx..w).step_by(st) {
                    let (best, bd) = self.m_pixel(&ms, y * w + x, fast);
                    if best != NONE {
                        row[x] = best;
                        drow[x] = bd;
                    }
                }
            });
        crate::cancel::check()?;

        // E-step (Eq. 3.5). Each vote weighs its match's N_lr distance to the power −0.6
        // (Kwatra et al. 2005's robust weights), floored at a tenth of the median: a plain
        // mean pulls every pixel towards mid-tones where votes disagree. The variants tried
        // instead are in docs/engines/tbn.md.
        let pw = ROBUST_POWER;
        let floor = {
            let mut d: Vec<f32> = mdist.iter().copied().filter(|v| v.is_finite()).collect();
            let n = d.len();
            if n == 0 {
                1.0
            } else {
                (*d.select_nth_unstable_by(n / 2, f32::total_cmp).1 * 0.1).max(1e-8)
            }
        };
        let vote_weight: Vec<f32> = mdist
            .par_iter()
            .map(|d| {
                if d.is_finite() {
                    d.max(floor).powf(-pw)
                } else {
                    0.0
                }
            })
            .collect();
        let (ca, c0) = (self.ca, self.c0);
        let aug = &self.el.aug;
        let mut out = vec![NONE; h * w];
        let medoid = self.medoid(it);
        out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            if crate::cancel::cancelled() {
                return;
            }
            let mut avg = vec![0f32; c0];
            let mut votes: Vec<u32> = Vec::with_capacity(p * p);
            let mut wvotes: Vec<(u32, f32)> = Vec::with_capacity(p * p);
            for (x, slot) in row.iter_mut().enumerate() {
                let i = y * w + x;
                let lb = labels_out[i];
                avg.fill(0.0);
                votes.clear();
                wvotes.clear();
                let mut wsum = 0f32;
                for dy in -r..=r {
                    for dx in -r..=r {
                        let Some(j) =
                            out_index(y as i64 + dy, x as i64 + dx, h, w, self.params.tileable)
                        else {
                            continue;
                        };
                        let e = shift(matches[j], -dy, -dx, eh, ew, self.params.wrap);
                        if e == NONE {
                            continue;
                        }
                        let wt = vote_weight[j];
                        if medoid {
                            if labels_in[e as usize] == lb {
                                wvotes.push((e, wt));
                            }
                        } else {
                            for (a, v) in avg
                                .iter_mut()
                                .zip(&aug[e as usize * ca..e as usize * ca + c0])
                            {
                                *a += wt * v;
                            }
                            wsum += wt;
                            votes.push(e);
                        }
                    }
                }
                let mut best = NONE;
                let mut bd = f32::INFINITY;
                if medoid {
                    if !wvotes.is_empty() {
                        best = weighted_medoid(&mut wvotes, aug, ca, c0);
                    }
                } else if !votes.is_empty() {
                    let inv = 1.0 / wsum;
                    for v in &mut avg {
                        *v *= inv;
                    }
                    let cs = cands[i * m..(i + 1) * m].iter().take_while(|&&c| c != NONE);
                    for &c in votes.iter().chain(cs) {
                        if labels_in[c as usize] != lb {
                            continue;
                        }
                        let d = ssd(&avg, &aug[c as usize * ca..c as usize * ca + c0]);
                        if d < bd {
                            bd = d;
                            best = c;
                        }
                    }
                }
                if best == NONE {
                    // Nothing of this label voted: keep the reference if it is of the right
                    // label, or take a random exemplar pixel that is.
                    let cur = refs[i];
                    best = if labels_in[cur as usize] == lb {
                        cur
                    } else {
                        init::pick(&self.el.by_label, lb, seed, key ^ 0xE, i)
                    };
                }
                *slot = best;
            }
        });
        crate::cancel::check()?;
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn medoid_matches_a_brute_force() {
        // 30 exemplar pixels, 5 channels of which the first 3 count; votes with repeats.
        let (ca, c0) = (5, 3);
        for trial in 0..20u64 {
            let mut rng = Rng::keyed(trial, 1, 2);
            let aug: Vec<f32> = (0..30 * ca)
                .map(|_| rng.below(1000) as f32 / 1000.0)
                .collect();
            let n = 1 + rng.below(12) as usize;
            let votes: Vec<(u32, f32)> = (0..n)
                .map(|_| (rng.below(30) as u32, 0.1 + rng.below(100) as f32 / 50.0))
                .collect();
            let px = |e: u32| &aug[e as usize * ca..e as usize * ca + c0];
            let cost = |e: u32| -> f64 {
                votes
                    .iter()
                    .map(|&(f, w)| {
                        let d: f64 = px(e)
                            .iter()
                            .zip(px(f))
                            .map(|(a, b)| f64::from(a - b).powi(2))
                            .sum();
                        f64::from(w) * d.sqrt()
                    })
                    .sum()
            };
            let brute = votes
                .iter()
                .map(|v| v.0)
                .min_by(|&a, &b| cost(a).total_cmp(&cost(b)).then(a.cmp(&b)))
                .unwrap();
            let got = weighted_medoid(&mut votes.clone(), &aug, ca, c0);
            assert!(
                got == brute || (cost(got) - cost(brute)).abs() < 1e-5,
                "trial {trial}: {got} vs {brute}"
            );
        }
    }
}
