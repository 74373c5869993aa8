//! Where each pixel of a deformed fragment comes from: the sampling maps of Sibbing, Pavić,
//! Kobbelt, "Image synthesis for branching structures", 2010, §5.3.
//!
//! A source fragment is laid rigidly onto its target (a rotation and a shift), and what is left
//! between the two skeletons is taken up by the smooth displacement field of
//! [`crate::field::interpolate_field`] that moves the target's skeleton points onto the rigidly
//! placed source's. [`fragment_maps`] gives, for every pixel of the target's crop, the source
//! image position to sample: `M (p − c + α d(p)) + s`, with `c` the target's centre, `s` the
//! source's and `M` the rigid map from target to source offsets.
//!
//! The field is smooth by construction, so it is solved on a grid coarsened to about 8 cells
//! per fragment radius and upsampled bilinearly. `α` is the largest of 1, ¾, ½, ¼, 0 for which
//! `p ↦ p + α d(p)` keeps a Jacobian determinant of at least ½ over the fragment's disk: at a
//! target furcation whose angle no source furcation has, the full field would fold the fragment
//! onto its skeleton, and the field of scaled constraints is the scaled field.

use crate::error::{invalid, Result};
use crate::field::{interpolate_field, FieldParams};

/// One fragment's placement: its crop, its skeleton and the rigid map onto its source.
#[derive(Clone, Copy, Debug)]
pub struct Placement<'a> {
    /// Crop size (rows, columns).
    pub shape: (usize, usize),
    /// The crop's top-left pixel in the target image (row, column).
    pub origin: (i64, i64),
    /// The target fragment's centre `(x, y)` in the target image.
    pub centre: [f64; 2],
    /// The target's skeleton points `(x, y)` in the target image.
    pub points: &'a [[f64; 2]],
    /// The displacement `(dx, dy)` wanted at each skeleton point.
    pub displacement: &'a [[f64; 2]],
    /// The fragment's radius (px): sets the coarse grid.
    pub radius: f64,
    /// Target offsets to source offsets: `[[m00, m01], [m10, m11]]`.
    pub rigid: [[f64; 2]; 2],
    /// The source fragment's centre `(x, y)` in the source image.
    pub source_centre: [f64; 2],
    /// The fragment's disk over the crop (row-major): where the field must not fold.
    pub disk: &'a [bool],
}

/// The sampling maps of a deformed fragment.
#[derive(Clone, Debug)]
pub struct Maps {
    /// Source column of every crop pixel (row-major).
    pub x: Vec<f32>,
    /// Source row of every crop pixel (row-major).
    pub y: Vec<f32>,
    /// The scale `α` the displacement field was applied with.
    pub alpha: f64,
}

/// Smallest Jacobian determinant the scaled field may leave.
const MIN_DET: f32 = 0.5;

/// The sampling maps of the module documentation for one fragment.
pub fn fragment_maps(p: &Placement<'_>) -> Result<Maps> {
    let (h, w) = p.shape;
    if h == 0 || w == 0 || p.disk.len() != h * w {
        return Err(invalid(
            "disk",
            format!(
                "expected a non-empty {h}×{w} mask, got {} values",
                p.disk.len()
            ),
        ));
    }
    if p.points.is_empty() || p.points.len() != p.displacement.len() {
        return Err(invalid(
            "displacement",
            format!(
                "expected one value per skeleton point ({}), got {}",
                p.points.len(),
                p.displacement.len()
            ),
        ));
    }
    if !(p.radius.is_finite() && p.radius > 0.0) {
        return Err(invalid(
            "radius",
            format!("expected a positive radius, got {}", p.radius),
        ));
    }
    let mut values = p.points.iter().chain(p.displacement).flatten();
    if let Some(v) = values.find(|v| !v.is_finite()) {
        return Err(invalid(
            "points",
            format!("expected finite points and displacements, found {v}"),
        ));
    }
    let field = displacement(p)?;
    let alpha = fold_free(&field, h, w, p.disk);
    let (mut x, mut y) = (vec![0f32; h * w], vec![0f32; h * w]);
    let [[m00, m01], [m10, m11]] = p.rigid;
    let (cx, cy) = (p.centre[0], p.centre[1]);
    let (sx, sy) = (p.source_centre[0], p.source_centre[1]);
    for r in 0..h {
        let py0 = (p.origin.0 + r as i64) as f64 - cy;
        for c in 0..w {
            let i = r * w + c;
            let px = (p.origin.1 + c as i64) as f64 - cx + alpha * f64::from(field[2 * i]);
            let py = py0 + alpha * f64::from(field[2 * i + 1]);
            x[i] = (m00 * px + m01 * py + sx) as f32;
            y[i] = (m10 * px + m11 * py + sy) as f32;
        }
    }
    Ok(Maps { x, y, alpha })
}

/// The displacement field over the crop (`h × w × 2`, row-major): solved on the coarse grid,
/// each coarse cell taking the mean of the displacements that fall in it, then upsampled.
fn displacement(p: &Placement<'_>) -> Result<Vec<f32>> {
    let (h, w) = p.shape;
    let f = (p.radius / 8.0).ceil().max(1.0) as usize;
    let (ch, cw) = (h.div_ceil(f).max(2), w.div_ceil(f).max(2));
    let cell = |v: f64, o: i64, n: usize| -> usize {
        // Ties to even, as NumPy rounds: the same cell as the Python reference.
        ((v - o as f64) / f as f64)
            .round_ties_even()
            .clamp(0.0, (n - 1) as f64) as usize
    };
    let mut cells: Vec<(usize, [f64; 2])> = p
        .points
        .iter()
        .zip(p.displacement)
        .map(|(q, d)| {
            (
                cell(q[1], p.origin.0, ch) * cw + cell(q[0], p.origin.1, cw),
                *d,
            )
        })
        .collect();
    cells.sort_by_key(|&(k, _)| k);
    let (mut pts, mut vals) = (Vec::new(), Vec::new());
    let mut i = 0;
    while i < cells.len() {
        let k = cells[i].0;
        let (mut sum, mut n) = ([0.0f64; 2], 0usize);
        while i < cells.len() && cells[i].0 == k {
            sum[0] += cells[i].1[0];
            sum[1] += cells[i].1[1];
            n += 1;
            i += 1;
        }
        pts.push([(k / cw) as i64, (k % cw) as i64]);
        vals.extend([sum[0] / n as f64, sum[1] / n as f64]);
    }
    let coarse = interpolate_field(
        &vec![true; ch * cw],
        ch,
        cw,
        &pts,
        &vals,
        2,
        &FieldParams::default(),
    )?
    .values;
    if f == 1 {
        let mut out = Vec::with_capacity(h * w * 2);
        for r in 0..h {
            out.extend_from_slice(&coarse[r * cw * 2..(r * cw + w) * 2]);
        }
        return Ok(out);
    }
    // Coarse cell (i, j) sits at fine pixel (i f, j f); beyond the last cell the field is held.
    let at = |v: usize, n: usize| -> (usize, usize, f32) {
        let t = v as f32 / f as f32;
        let i0 = (t.floor() as usize).min(n - 1);
        (i0, (i0 + 1).min(n - 1), t - i0 as f32)
    };
    let cols: Vec<(usize, usize, f32)> = (0..w).map(|c| at(c, cw)).collect();
    let mut out = vec![0f32; h * w * 2];
    for (r, row) in out.chunks_exact_mut(2 * w).enumerate() {
        let (r0, r1, b) = at(r, ch);
        let (top, bottom) = (
            &coarse[r0 * cw * 2..][..cw * 2],
            &coarse[r1 * cw * 2..][..cw * 2],
        );
        for (px, &(c0, c1, a)) in row.chunks_exact_mut(2).zip(&cols) {
            for k in 0..2 {
                let t = top[2 * c0 + k] * (1.0 - a) + top[2 * c1 + k] * a;
                let u = bottom[2 * c0 + k] * (1.0 - a) + bottom[2 * c1 + k] * a;
                px[k] = t * (1.0 - b) + u * b;
            }
        }
    }
    Ok(out)
}

/// The scales tried, largest first.
const ALPHAS: [f32; 4] = [1.0, 0.75, 0.5, 0.25];

/// The largest of [`ALPHAS`] (else 0) by which `field` can be scaled keeping the Jacobian
/// determinant of `p ↦ p + α d(p)` at least [`MIN_DET`] over `disk`. Derivatives as NumPy's
/// `gradient`: central inside, one-sided at the crop's edges.
fn fold_free(field: &[f32], h: usize, w: usize, disk: &[bool]) -> f64 {
    let d = |r: usize, c: usize, k: usize| field[(r * w + c) * 2 + k];
    // The smallest determinant over the disk at each scale, in one pass.
    let mut least = [f32::INFINITY; 4];
    for r in 0..h {
        let (ra, rb) = (r.saturating_sub(1), (r + 1).min(h - 1));
        let sy = (rb - ra) as f32;
        for c in 0..w {
            if !disk[r * w + c] {
                continue;
            }
            let (ca, cb) = (c.saturating_sub(1), (c + 1).min(w - 1));
            let sx = (cb - ca) as f32;
            let dx = |k| {
                if cb == ca {
                    0.0
                } else {
                    (d(r, cb, k) - d(r, ca, k)) / sx
                }
            };
            let dy = |k| {
                if rb == ra {
                    0.0
                } else {
                    (d(rb, c, k) - d(ra, c, k)) / sy
                }
            };
            let (ux, uy, vx, vy) = (dx(0), dy(0), dx(1), dy(1));
            let (a1, a2) = (ux + vy, ux * vy - uy * vx);
            for (m, alpha) in least.iter_mut().zip(ALPHAS) {
                *m = m.min(1.0 + alpha * a1 + alpha * alpha * a2);
            }
        }
    }
    ALPHAS
        .iter()
        .zip(least)
        .find(|&(_, m)| m >= MIN_DET)
        .map_or(0.0, |(&alpha, _)| f64::from(alpha))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn disk(h: usize, w: usize) -> Vec<bool> {
        let (cy, cx, r) = (
            (h - 1) as f64 / 2.0,
            (w - 1) as f64 / 2.0,
            h.min(w) as f64 / 2.0,
        );
        (0..h * w)
            .map(|i| {
                let (y, x) = ((i / w) as f64 - cy, (i % w) as f64 - cx);
                x * x + y * y <= r * r
            })
            .collect()
    }

    fn placement<'a>(
        pts: &'a [[f64; 2]],
        d: &'a [[f64; 2]],
        mask: &'a [bool],
        rigid: [[f64; 2]; 2],
    ) -> Placement<'a> {
        Placement {
            shape: (41, 41),
            origin: (80, 30),
            centre: [50.0, 100.0],
            points: pts,
            displacement: d,
            radius: 20.0,
            rigid,
            source_centre: [7.0, 9.0],
            disk: mask,
        }
    }

    #[test]
    fn a_constant_displacement_is_a_shift_through_the_rigid_map() {
        let pts: Vec<[f64; 2]> = (0..30).map(|i| [35.0 + i as f64, 100.0]).collect();
        let d = vec![[1.5, -2.0]; pts.len()];
        let mask = disk(41, 41);
        let (c, s) = (0.6f64.cos(), 0.6f64.sin());
        let m = fragment_maps(&placement(&pts, &d, &mask, [[c, -s], [s, c]])).unwrap();
        assert!((m.alpha - 1.0).abs() < f64::EPSILON, "alpha {}", m.alpha);
        for (i, (&x, &y)) in m.x.iter().zip(&m.y).enumerate() {
            let (px, py) = (
                (30 + i % 41) as f64 - 50.0 + 1.5,
                (80 + i / 41) as f64 - 100.0 - 2.0,
            );
            assert!((f64::from(x) - (c * px - s * py + 7.0)).abs() < 1e-3);
            assert!((f64::from(y) - (s * px + c * py + 9.0)).abs() < 1e-3);
        }
    }

    #[test]
    fn a_folding_field_is_scaled_down() {
        // Neighbouring skeleton points pulled 12 px towards each other: the full field folds.
        let pts: Vec<[f64; 2]> = (0..30).map(|i| [35.0 + i as f64, 100.0]).collect();
        let d: Vec<[f64; 2]> = (0..30)
            .map(|i| [if i < 15 { 6.0 } else { -6.0 }, 0.0])
            .collect();
        let mask = disk(41, 41);
        let m = fragment_maps(&placement(&pts, &d, &mask, [[1.0, 0.0], [0.0, 1.0]])).unwrap();
        assert!(m.alpha < 1.0, "alpha {}", m.alpha);
    }

    #[test]
    fn errors_name_the_argument() {
        let pts = [[40.0, 100.0]];
        let mask = disk(41, 41);
        let id = [[1.0, 0.0], [0.0, 1.0]];
        let e = fragment_maps(&placement(&pts, &[], &mask, id)).unwrap_err();
        assert!(e.to_string().starts_with("displacement:"), "{e}");
        let nan = [[f64::NAN, 0.0]];
        let e = fragment_maps(&placement(&pts, &nan, &mask, id)).unwrap_err();
        assert!(e.to_string().starts_with("points:"), "{e}");
        let e = fragment_maps(&placement(&pts, &[[0.0, 0.0]], &mask[..10], id)).unwrap_err();
        assert!(e.to_string().starts_with("disk:"), "{e}");
    }
}
