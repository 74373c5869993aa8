//! Guided quilting, the start of texture correction (Assa & Cohen-Or §3, after Fang & Hart 2007;
//! `phloem.leaves.correct_texture`).
//!
//! The pixels a warp distorted (the *hole*) are covered in raster order by square blocks, each
//! copied rigidly from the unwarped source, so at the source's scale. A block's source position
//! is searched within `radius` px (both axes) of where the warp maps the block's centre; it
//! minimises the squared difference, over a `rim`-pixel frame around the block and the block
//! itself, between the source and the target values already known (undistorted pixels and
//! earlier blocks; with `alpha_known` the last channel everywhere), plus `bias` per squared pixel
//! of leaving the warp's position, so ties go to the warp (Efros & Freeman's image quilting
//! with the warp as guide). The source reads as 0 outside its bounds.
//!
//! The loop is sequential: each block depends on the ones placed before it, which is why it
//! is in Rust rather than a Python loop over `cv2.matchTemplate` (docs/pipelines/leaves/correction.md).

use crate::cancel;
use crate::error::{invalid, Result};
use crate::image::Image;

/// How [`guided_quilt`] places its blocks.
#[derive(Clone, Copy, Debug)]
pub struct QuiltParams {
    /// Side of a block, in pixels (at least 1).
    pub block: usize,
    /// Width of the frame of known pixels compared around a block.
    pub rim: usize,
    /// Search radius around the warp's position, in pixels.
    pub radius: usize,
    /// Cost per squared pixel of distance from the warp's position.
    pub bias: f32,
    /// Whether the last channel (alpha) is known over the hole too.
    pub alpha_known: bool,
}

/// Rounds half to even, like `numpy.rint`, so that the Rust and NumPy versions agree.
fn rint(v: f32) -> i64 {
    v.round_ties_even() as i64
}

/// Source `(row, col)` of every hole pixel after guided quilting; `(-1, -1)` elsewhere.
///
/// `target` and `source` share their channel count; `hole` is `target.h × target.w`; `field`
/// holds `(dx, dy)` per target pixel: pixel `(y, x)` was sampled at source `(y + dy, x + dx)`.
///
/// # Errors
///
/// `source` with other channels than `target`, `hole` or `field` of the wrong length, a
/// non-finite `field` or a `block` of 0.
pub fn guided_quilt(
    target: &Image<'_>,
    source: &Image<'_>,
    hole: &[bool],
    field: &[f32],
    params: &QuiltParams,
) -> Result<Vec<i32>> {
    let (h, w, nc) = (target.h, target.w, target.c);
    if source.c != nc {
        return Err(invalid(
            "source",
            format!("expected {nc} channels like target, got {}", source.c),
        ));
    }
    if hole.len() != h * w {
        return Err(invalid(
            "hole",
            format!("expected {h}×{w} values like target, got {}", hole.len()),
        ));
    }
    if field.len() != h * w * 2 {
        return Err(invalid(
            "field",
            format!("expected {h}×{w}×2 values like target, got {}", field.len()),
        ));
    }
    if field.iter().any(|v| !v.is_finite()) {
        return Err(invalid("field", "expected finite displacements"));
    }
    if params.block == 0 {
        return Err(invalid("block", "expected a block side >= 1"));
    }
    let mut pos = vec![-1i32; h * w * 2];
    let Some(first) = hole.iter().position(|&v| v) else {
        return Ok(pos);
    };
    let (b, o, r) = (params.block, params.rim, params.radius);
    let mut cur = target.data.to_vec();
    // Per value, whether it is known; alpha (the last channel) is known everywhere if so told.
    let mut known: Vec<bool> = (0..h * w * nc)
        .map(|i| (params.alpha_known && i % nc == nc - 1) || !hole[i / nc])
        .collect();
    let y0 = first / w;
    let (mut y1, mut x0, mut x1) = (y0, w, 0);
    for (i, _) in hole.iter().enumerate().filter(|(_, &v)| v) {
        y1 = i / w;
        x0 = x0.min(i % w);
        x1 = x1.max(i % w);
    }
    let pad = (r + b + o) as i64;
    let side = 2 * r + 1;
    let mut cost = vec![0f32; side * side];
    // The source zero-padded by `pad` on every side, so no candidate needs a bounds check.
    let (hp, wp) = (source.h + 2 * pad as usize, source.w + 2 * pad as usize);
    let mut padded = vec![0f32; hp * wp * nc];
    for y in 0..source.h {
        let at = ((y + pad as usize) * wp + pad as usize) * nc;
        padded[at..at + source.w * nc]
            .copy_from_slice(&source.data[y * source.w * nc..(y + 1) * source.w * nc]);
    }
    // The known values of the current template: offset into `padded` from the template's
    // top-left, and value.
    let (mut offs, mut vals) = (Vec::new(), Vec::new());
    let mut by = y0;
    while by <= y1 {
        cancel::check()?;
        let mut bx = x0;
        while bx <= x1 {
            let (ey, ex) = ((by + b).min(h), (bx + b).min(w));
            let any = (by..ey).any(|y| hole[y * w + bx..y * w + ex].iter().any(|&v| v));
            if !any {
                bx += b;
                continue;
            }
            let (ty0, tx0) = (by.saturating_sub(o), bx.saturating_sub(o));
            let (ty1, tx1) = ((by + b + o).min(h), (bx + b + o).min(w));
            let (th, tw) = ((ty1 - ty0) as i64, (tx1 - tx0) as i64);
            let (cy, cx) = ((by + b / 2).min(h - 1), (bx + b / 2).min(w - 1));
            let (fdx, fdy) = (field[(cy * w + cx) * 2], field[(cy * w + cx) * 2 + 1]);
            // Top-left of the candidate window in the padded source, clipped to it.
            let span = 2 * r as i64;
            let wy =
                (rint(ty0 as f32 + fdy) + pad - r as i64).clamp(0, hp as i64 - th - span) as usize;
            let wx =
                (rint(tx0 as f32 + fdx) + pad - r as i64).clamp(0, wp as i64 - tw - span) as usize;
            offs.clear();
            vals.clear();
            for ty in ty0..ty1 {
                for tx in tx0..tx1 {
                    let base = (ty * w + tx) * nc;
                    for ch in 0..nc {
                        if known[base + ch] {
                            offs.push(((ty - ty0) * wp + (tx - tx0)) * nc + ch);
                            vals.push(cur[base + ch]);
                        }
                    }
                }
            }
            for ky in 0..side {
                for kx in 0..side {
                    let at = ((wy + ky) * wp + wx + kx) * nc;
                    let window = &padded[at..];
                    let mut sum = 0f32;
                    for (&off, &v) in offs.iter().zip(&vals) {
                        let d = v - window[off];
                        sum += d * d;
                    }
                    let (dy, dx) = (ky as f32 - r as f32, kx as f32 - r as f32);
                    cost[ky * side + kx] = sum + params.bias * (dy * dy + dx * dx);
                }
            }
            // First minimum in raster order, as `numpy.argmin` takes it.
            let mut best = 0;
            for (k, &c) in cost.iter().enumerate() {
                if c < cost[best] {
                    best = k;
                }
            }
            let oy = (wy + best / side) as i64 - pad - ty0 as i64;
            let ox = (wx + best % side) as i64 - pad - tx0 as i64;
            for y in by..ey {
                for x in bx..ex {
                    let i = y * w + x;
                    if !hole[i] {
                        continue;
                    }
                    let (sy, sx) = (y as i64 + oy, x as i64 + ox);
                    // Inside the padded window by construction.
                    let at = ((sy + pad) as usize * wp + (sx + pad) as usize) * nc;
                    cur[i * nc..(i + 1) * nc].copy_from_slice(&padded[at..at + nc]);
                    known[i * nc..(i + 1) * nc].fill(true);
                    pos[2 * i] = sy as i32;
                    pos[2 * i + 1] = sx as i32;
                }
            }
            bx += b;
        }
        by += b;
    }
    Ok(pos)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(data: &[f32], h: usize, w: usize, c: usize) -> Image<'_> {
        Image::new("image", data, h, w, c).unwrap()
    }

    /// A `h × w` hole over rows `ys` and columns `xs`.
    fn square_hole(
        h: usize,
        w: usize,
        ys: std::ops::Range<usize>,
        xs: std::ops::Range<usize>,
    ) -> Vec<bool> {
        (0..h * w)
            .map(|i| ys.contains(&(i / w)) && xs.contains(&(i % w)))
            .collect()
    }

    /// Quilts a one-channel image into itself.
    fn quilt_itself(data: &[f32], h: usize, w: usize, hole: &[bool], field: &[f32]) -> Vec<i32> {
        guided_quilt(
            &img(data, h, w, 1),
            &img(data, h, w, 1),
            hole,
            field,
            &params(),
        )
        .unwrap()
    }

    fn params() -> QuiltParams {
        QuiltParams {
            block: 3,
            rim: 1,
            radius: 3,
            bias: 1e-4,
            alpha_known: false,
        }
    }

    #[test]
    fn an_identity_warp_copies_the_source_back_in_place() {
        let (h, w) = (12, 14);
        let data: Vec<f32> = (0..h * w)
            .map(|i| ((i * 7919) % 23) as f32 / 23.0)
            .collect();
        let hole = square_hole(h, w, 4..9, 5..10);
        let pos = quilt_itself(&data, h, w, &hole, &vec![0f32; h * w * 2]);
        for i in 0..h * w {
            if hole[i] {
                assert_eq!(
                    (pos[2 * i], pos[2 * i + 1]),
                    ((i / w) as i32, (i % w) as i32)
                );
            } else {
                assert_eq!((pos[2 * i], pos[2 * i + 1]), (-1, -1));
            }
        }
    }

    #[test]
    fn a_block_follows_the_known_rim_not_a_wrong_warp() {
        // Stripes of period 4; the warp points 2 px off (half a period), the rim says where.
        let (h, w) = (10, 24);
        let data: Vec<f32> = (0..h * w)
            .map(|i| if (i % w) % 4 < 2 { 1.0 } else { 0.0 })
            .collect();
        let hole = square_hole(h, w, 3..6, 9..12);
        let field: Vec<f32> = (0..h * w).flat_map(|_| [2.0f32, 0.0]).collect();
        let pos = quilt_itself(&data, h, w, &hole, &field);
        for i in (0..h * w).filter(|&i| hole[i]) {
            let (sy, sx) = (pos[2 * i] as usize, pos[2 * i + 1] as usize);
            assert!(sy < h, "pixel {i}");
            assert_eq!(
                sx % 4 < 2,
                (i % w) % 4 < 2,
                "pixel {i}: a stripe of the other colour"
            );
        }
    }

    #[test]
    fn bad_input_names_the_argument() {
        let data = vec![0f32; 16];
        let t = img(&data, 4, 4, 1);
        let two = vec![0f32; 32];
        let s2 = img(&two, 4, 4, 2);
        let hole = vec![true; 16];
        let field = vec![0f32; 32];
        let name = |r: Result<Vec<i32>>| match r {
            Err(crate::Error::InvalidArgument { name, .. }) => name,
            other => panic!("expected an error, got {other:?}"),
        };
        assert_eq!(
            name(guided_quilt(&t, &s2, &hole, &field, &params())),
            "source"
        );
        assert_eq!(
            name(guided_quilt(&t, &t, &hole[..3], &field, &params())),
            "hole"
        );
        assert_eq!(
            name(guided_quilt(&t, &t, &hole, &field[..5], &params())),
            "field"
        );
        let nan = vec![f32::NAN; 32];
        assert_eq!(name(guided_quilt(&t, &t, &hole, &nan, &params())), "field");
        let p = QuiltParams {
            block: 0,
            ..params()
        };
        assert_eq!(name(guided_quilt(&t, &t, &hole, &field, &p)), "block");
        assert!(guided_quilt(&t, &t, &[false; 16], &field, &params())
            .unwrap()
            .iter()
            .all(|&v| v == -1));
    }
}
