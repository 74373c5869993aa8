//! Weighted patch voting: every output pixel becomes the weighted mean of the values that the
//! overlapping matched source patches put there. This is the colour update of texture
//! optimisation (Kwatra, Essa, Bobick, Kwatra 2005, Eq. 4 with weights `|z_p − x_p|^(r−2)`) and
//! of space-time completion (Wexler, Shechtman, Irani 2007, Eq. 3); the caller chooses the
//! per-patch weights.
//!
//! The loop is written in gather form (each output pixel reads the patches that cover it), so
//! pixels are independent, the sum order is fixed and the result does not depend on threads.

use rayon::prelude::*;

use crate::error::{invalid, Result};
use crate::image::Image;
use crate::patch::NONE;

/// Output of [`vote`].
#[derive(Clone, Debug)]
pub struct Voted {
    /// `h × w × c` voted values; pixels no patch covers are 0.
    pub image: Vec<f32>,
    /// `h × w` sum of the weights that reached each pixel (0 where nothing did).
    pub weight: Vec<f32>,
}

/// Converts a `h × w × 2` (row, col) field into flat source indices, checking every entry is
/// a patch centre whose patch lies inside the `sh × sw` source (`-1, -1` means no match).
pub fn idx_from_rowcol(field: &[i32], sh: usize, sw: usize, patch_size: usize) -> Result<Vec<u32>> {
    let r = (patch_size / 2) as i32;
    field
        .chunks_exact(2)
        .enumerate()
        .map(|(i, rc)| {
            if rc[0] == -1 && rc[1] == -1 {
                return Ok(NONE);
            }
            if rc[0] < r || rc[1] < r || rc[0] >= sh as i32 - r || rc[1] >= sw as i32 - r {
                return Err(invalid(
                    "field",
                    format!("entry {i} = ({}, {}) is not a centre of a {patch_size}×{patch_size} patch inside the {sh}×{sw} source", rc[0], rc[1]),
                ));
            }
            Ok(rc[0] as u32 * sw as u32 + rc[1] as u32)
        })
        .collect()
}

/// Votes source patches into an `h × w` image.
///
/// `idx[i]` is the source centre matched to target pixel `i` (or [`NONE`]); `weights[i]` the
/// weight of that patch (default 1). Weights must be finite and non-negative.
pub fn vote(
    source: &Image<'_>,
    idx: &[u32],
    h: usize,
    w: usize,
    weights: Option<&[f32]>,
    patch_size: usize,
) -> Result<Voted> {
    vote_mode(source, idx, h, w, weights, patch_size, 0, None, false)
}

/// [`vote`], then `mean_shift` steps of weighted mean-shift from the weighted mean towards the
/// dominant mode of each pixel's votes, as Wexler, Shechtman and Irani (2007, §3.2) propose
/// so that disagreeing votes do not blur the result. Each step weighs vote `v` by
/// `w · exp(−|v − m|² / s²)`, with `s²` the weighted mean of `|v − m|²` around the current
/// estimate `m` (a Gaussian kernel whose bandwidth follows the votes' own spread; votes that
/// agree stay put). `mean_shift = 0` is [`vote`] exactly. Weights as in [`vote`].
///
/// With `pixels` (`h × w`), only the pixels where it is true are computed, the others get
/// value and weight 0; each computed pixel is bit-identical to the full vote's, so a caller
/// that keeps only a region (completion keeps its hole) pays for that region, not the image.
///
/// With `tileable`, the output is a torus: a patch centred near an edge also votes on the
/// opposite side, so the votes agree across the wrap and the result tiles.
#[allow(clippy::too_many_arguments)]
pub fn vote_mode(
    source: &Image<'_>,
    idx: &[u32],
    h: usize,
    w: usize,
    weights: Option<&[f32]>,
    patch_size: usize,
    mean_shift: usize,
    pixels: Option<&[bool]>,
    tileable: bool,
) -> Result<Voted> {
    if patch_size == 0 || patch_size % 2 == 0 {
        return Err(invalid(
            "patch_size",
            format!("expected an odd size >= 1, got {patch_size}"),
        ));
    }
    if idx.len() != h * w {
        return Err(invalid(
            "field",
            format!("expected {h}×{w} entries, got {}", idx.len()),
        ));
    }
    if let Some(wt) = weights {
        if wt.len() != h * w {
            return Err(invalid(
                "weights",
                format!(
                    "expected {h}×{w} patch weights like the field, got {}",
                    wt.len()
                ),
            ));
        }
        if let Some(bad) = wt.iter().find(|v| !v.is_finite() || **v < 0.0) {
            return Err(invalid(
                "weights",
                format!("expected finite non-negative weights, got {bad}"),
            ));
        }
    }
    if let Some(m) = pixels {
        if m.len() != h * w {
            return Err(invalid(
                "pixels",
                format!("expected {h}×{w} values like the field, got {}", m.len()),
            ));
        }
    }
    let r = patch_size / 2;
    let (c, sw) = (source.c, source.w);
    let mut image = vec![0f32; h * w * c];
    let mut weight = vec![0f32; h * w];
    image
        .par_chunks_mut(w * c)
        .zip(weight.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (row, wrow))| {
            let mut acc = vec![0f32; c];
            // This pixel's votes: `c` values then the weight, per covering patch.
            let mut votes: Vec<f32> = Vec::new();
            let wanted = pixels.map(|m| &m[y * w..(y + 1) * w]);
            if wanted.is_some_and(|m| !m.contains(&true)) {
                return;
            }
            for x in 0..w {
                if wanted.is_some_and(|m| !m[x]) {
                    continue;
                }
                votes.clear();
                acc.fill(0.0);
                let mut total = 0f32;
                // Centres in unwrapped coordinates, in the same order with or without the
                // wrap, so a plain vote's sums are unchanged.
                let (ri, yi, xi) = (r as i64, y as i64, x as i64);
                for cy in yi - ri..=yi + ri {
                    let Some(wy) = wrap_or_skip(cy, h, tileable) else {
                        continue;
                    };
                    for cx in xi - ri..=xi + ri {
                        let Some(wx) = wrap_or_skip(cx, w, tileable) else {
                            continue;
                        };
                        let ci = wy * w + wx;
                        let s = idx[ci];
                        if s == NONE {
                            continue;
                        }
                        let wt = weights.map_or(1.0, |v| v[ci]);
                        if wt == 0.0 {
                            continue;
                        }
                        // Source pixel at the same offset from the source centre.
                        let (sy, sx) = (
                            (s as usize / sw) as i64 + yi - cy,
                            (s as usize % sw) as i64 + xi - cx,
                        );
                        let (sy, sx) = (sy as usize, sx as usize);
                        let px = &source.data[(sy * sw + sx) * c..][..c];
                        for (a, v) in acc.iter_mut().zip(px) {
                            *a += wt * v;
                        }
                        total += wt;
                        if mean_shift > 0 {
                            votes.extend_from_slice(px);
                            votes.push(wt);
                        }
                    }
                }
                if total > 0.0 {
                    for (o, a) in row[x * c..(x + 1) * c].iter_mut().zip(&acc) {
                        *o = a / total;
                    }
                    if mean_shift > 0 {
                        shift_to_mode(&mut row[x * c..(x + 1) * c], &votes, mean_shift);
                    }
                }
                wrow[x] = total;
            }
        });
    Ok(Voted { image, weight })
}

/// Coordinate `v` of an axis of length `n`: wrapped around on a torus, `None` outside
/// otherwise.
#[inline]
pub(crate) fn wrap_or_skip(v: i64, n: usize, wrap: bool) -> Option<usize> {
    if wrap {
        Some(v.rem_euclid(n as i64) as usize)
    } else if v < 0 || v >= n as i64 {
        None
    } else {
        Some(v as usize)
    }
}

/// Moves `m` (the weighted mean of `votes`, `m.len()` values then a weight per vote) by
/// `steps` mean-shift steps; see [`vote_mode`]. Sums in `f64` in vote order.
fn shift_to_mode(m: &mut [f32], votes: &[f32], steps: usize) {
    let c = m.len();
    let mut cur: Vec<f64> = m.iter().map(|v| f64::from(*v)).collect();
    let mut next = vec![0f64; c];
    for _ in 0..steps {
        let d2 = |v: &[f32]| -> f64 {
            v.iter()
                .zip(&cur)
                .map(|(a, b)| (f64::from(*a) - b).powi(2))
                .sum()
        };
        let (mut spread, mut total) = (0f64, 0f64);
        for v in votes.chunks_exact(c + 1) {
            let wt = f64::from(v[c]);
            spread += wt * d2(&v[..c]);
            total += wt;
        }
        let s2 = spread / total;
        if s2 <= 0.0 {
            break; // all votes agree
        }
        next.fill(0.0);
        let mut kt = 0f64;
        for v in votes.chunks_exact(c + 1) {
            let k = f64::from(v[c]) * (-d2(&v[..c]) / s2).exp();
            for (n, a) in next.iter_mut().zip(&v[..c]) {
                *n += k * f64::from(*a);
            }
            kt += k;
        }
        if kt <= 0.0 {
            break;
        }
        for (a, n) in cur.iter_mut().zip(&next) {
            *a = n / kt;
        }
    }
    for (o, a) in m.iter_mut().zip(&cur) {
        *o = *a as f32;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identity_field_reproduces_the_source() {
        let (h, w, c, p) = (12, 15, 2, 5);
        let src: Vec<f32> = (0..h * w * c).map(|i| (i as f32 * 0.37).sin()).collect();
        let img = Image::new("source", &src, h, w, c).unwrap();
        // Interior pixels map to themselves; border pixels have no valid centre.
        let idx: Vec<u32> = (0..h * w)
            .map(|i| {
                let (y, x) = (i / w, i % w);
                if (2..h - 2).contains(&y) && (2..w - 2).contains(&x) {
                    i as u32
                } else {
                    NONE
                }
            })
            .collect();
        let v = vote(&img, &idx, h, w, None, p).unwrap();
        for i in 0..h * w {
            assert!(v.weight[i] > 0.0);
            for k in 0..c {
                assert!((v.image[i * c + k] - src[i * c + k]).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn weights_average_conflicting_votes() {
        // Columns 0..5 hold 0, columns 5..9 hold 1.
        let src: Vec<f32> = (0..27).map(|i| if i % 9 < 5 { 0.0 } else { 1.0 }).collect();
        let img = Image::new("source", &src, 3, 9, 1).unwrap();
        // Target 1×2: pixel 0 matched to centre (1,1) (zeros), pixel 1 to (1,7) (ones).
        let idx = [10u32, 16];
        let v = vote(&img, &idx, 1, 2, Some(&[1.0, 3.0]), 3).unwrap();
        assert!((v.image[0] - 0.75).abs() < 1e-6 && (v.image[1] - 0.75).abs() < 1e-6);
        assert!((v.weight[0] - 4.0).abs() < 1e-6);
    }

    #[test]
    fn mean_shift_moves_to_the_majority() {
        // Pixel 0 is covered by three votes: 0 (weight 3 in total) and 1 (weight 1).
        let src: Vec<f32> = (0..27).map(|i| if i % 9 < 5 { 0.0 } else { 1.0 }).collect();
        let img = Image::new("source", &src, 3, 9, 1).unwrap();
        let idx = [10u32, 16];
        let mean = vote_mode(&img, &idx, 1, 2, Some(&[3.0, 1.0]), 3, 0, None, false).unwrap();
        assert!((mean.image[0] - 0.25).abs() < 1e-6);
        let shifted = vote_mode(&img, &idx, 1, 2, Some(&[3.0, 1.0]), 3, 3, None, false).unwrap();
        assert!(shifted.image[0] < 0.05, "{}", shifted.image[0]);
        assert_eq!(shifted.weight, mean.weight);
    }

    #[test]
    fn masked_vote_equals_full_vote_on_its_pixels() {
        let (h, w, c, p) = (23, 31, 3, 5);
        let src: Vec<f32> = (0..h * w * c).map(|i| (i as f32 * 0.61).sin()).collect();
        let img = Image::new("source", &src, h, w, c).unwrap();
        let mut rng = crate::rng::Rng::keyed(7, 0, 0);
        let idx: Vec<u32> = (0..h * w)
            .map(|_| {
                if rng.below(5) == 0 {
                    return NONE;
                }
                let y = 2 + rng.below((h - 4) as u64) as usize;
                let x = 2 + rng.below((w - 4) as u64) as usize;
                (y * w + x) as u32
            })
            .collect();
        let wts: Vec<f32> = (0..h * w).map(|i| (i % 7) as f32 * 0.3).collect();
        let pixels: Vec<bool> = (0..h * w).map(|i| (i * 37) % 11 < 3).collect();
        for shift in [0, 3] {
            let full = vote_mode(&img, &idx, h, w, Some(&wts), p, shift, None, false).unwrap();
            let part =
                vote_mode(&img, &idx, h, w, Some(&wts), p, shift, Some(&pixels), false).unwrap();
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            for (i, &at) in pixels.iter().enumerate() {
                let (pv, fv) = (
                    &part.image[i * c..(i + 1) * c],
                    &full.image[i * c..(i + 1) * c],
                );
                if at {
                    assert_eq!(part.weight[i].to_bits(), full.weight[i].to_bits());
                    assert_eq!(bits(pv), bits(fv));
                } else {
                    assert_eq!(part.weight[i].to_bits(), 0);
                    assert!(pv.iter().all(|v| v.to_bits() == 0));
                }
            }
        }
        assert!(vote_mode(&img, &idx, h, w, None, p, 0, Some(&pixels[1..]), false).is_err());
    }

    #[test]
    fn wrap_or_skip_wraps_only_on_a_torus() {
        assert_eq!(wrap_or_skip(-1, 5, true), Some(4));
        assert_eq!(wrap_or_skip(5, 5, true), Some(0));
        assert_eq!(wrap_or_skip(-7, 5, true), Some(3));
        assert_eq!(wrap_or_skip(-1, 5, false), None);
        assert_eq!(wrap_or_skip(5, 5, false), None);
        assert_eq!(wrap_or_skip(4, 5, false), Some(4));
    }

    #[test]
    fn tileable_vote_wraps_and_commutes_with_rolling() {
        let (h, w, c, p) = (9, 11, 2, 5);
        let (sh, sw) = (14, 16);
        let src: Vec<f32> = (0..sh * sw * c).map(|i| (i as f32 * 0.43).sin()).collect();
        let img = Image::new("source", &src, sh, sw, c).unwrap();
        // One patch, centred on the corner pixel: on a torus it covers all four corners.
        let mut idx = vec![NONE; h * w];
        idx[0] = (5 * sw + 6) as u32;
        let v = vote_mode(&img, &idx, h, w, None, p, 0, None, true).unwrap();
        let covered = |y: usize, x: usize| v.weight[y * w + x] > 0.0;
        assert!(covered(0, 0) && covered(h - 1, w - 1) && covered(h - 2, 1) && covered(2, w - 2));
        assert!(!covered(3, 0) && !covered(0, 3) && !covered(h - 3, w - 3));
        // Pixel (h − 1, w − 2) is offset (−1, −2) from the centre: source (4, 4).
        let (y, x) = (h - 1, w - 2);
        assert_eq!(
            &v.image[(y * w + x) * c..][..c],
            &src[(4 * sw + 4) * c..][..c]
        );
        // A dense random field: rolling the field rolls the vote, bit for bit.
        let mut rng = crate::rng::Rng::keyed(3, 0, 0);
        let idx: Vec<u32> = (0..h * w)
            .map(|_| {
                let y = 2 + rng.below((sh - 4) as u64) as usize;
                let x = 2 + rng.below((sw - 4) as u64) as usize;
                (y * sw + x) as u32
            })
            .collect();
        let wts: Vec<f32> = (0..h * w).map(|i| 0.5 + (i % 5) as f32).collect();
        let (dy, dx) = (4, 7);
        let roll = |v: &[u32]| -> Vec<u32> {
            (0..h * w)
                .map(|i| v[((i / w + h - dy) % h) * w + (i % w + w - dx) % w])
                .collect()
        };
        let rolled_w: Vec<f32> = (0..h * w)
            .map(|i| wts[((i / w + h - dy) % h) * w + (i % w + w - dx) % w])
            .collect();
        let a = vote_mode(&img, &idx, h, w, Some(&wts), p, 2, None, true).unwrap();
        let b = vote_mode(&img, &roll(&idx), h, w, Some(&rolled_w), p, 2, None, true).unwrap();
        for i in 0..h * w {
            let j = ((i / w + dy) % h) * w + (i % w + dx) % w;
            assert_eq!(a.weight[i].to_bits(), b.weight[j].to_bits());
            for k in 0..c {
                assert_eq!(a.image[i * c + k].to_bits(), b.image[j * c + k].to_bits());
            }
        }
        // Every pixel of a torus is covered by p² patches.
        assert!(a.weight.iter().all(|t| *t > 0.0));
    }

    #[test]
    fn rejects_bad_fields() {
        assert!(idx_from_rowcol(&[0, 0], 10, 10, 3).is_err());
        assert!(idx_from_rowcol(&[1, 8], 10, 10, 3).is_ok());
        assert!(idx_from_rowcol(&[1, 9], 10, 10, 3).is_err());
        assert_eq!(idx_from_rowcol(&[-1, -1], 10, 10, 3).unwrap(), vec![NONE]);
    }
}
