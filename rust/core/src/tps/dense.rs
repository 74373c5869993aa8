//! Dense fields from a registration: the spline evaluated on a pixel grid, its inverse by a
//! spline fit refined with Newton steps, the fold check, and sampling an image by a field.
//!
//! A field holds, for pixel `(row, col)` (centre `(x, y) = (col, row)`), the displacement
//! `(dx, dy)` to the position it samples: `(col + dx, row + dy)`. The spline is evaluated
//! exactly on the nodes of a grid of `step` px (plus the last row and column) and
//! interpolated bilinearly in between: a thin-plate spline with the bending penalty used
//! here curves so little over a few pixels that the interpolation error is far below a
//! pixel (measured in the tests), and it saves a factor `step²` of kernel evaluations.
//! Rows run in parallel and every value's arithmetic is fixed, so the fields are the same for
//! any number of threads.

use rayon::prelude::*;

use crate::cancel;
use crate::error::{invalid, Result};
use crate::image::Image;

use super::rpm::{rpm, to_input, Params, Rpm};
use super::spline::{Basis, Point, Tps};

/// Node coordinates along one axis of `len` pixels.
fn nodes(len: usize, step: usize) -> Vec<usize> {
    let mut v: Vec<usize> = (0..len).step_by(step).collect();
    if v.last() != Some(&(len - 1)) {
        v.push(len - 1);
    }
    v
}

/// `map` evaluated on the node grid of an `h × w` image: positions, row-major over nodes.
fn on_nodes<T: Copy + Default + Send>(
    h: usize,
    w: usize,
    step: usize,
    map: impl Fn(Point) -> T + Sync,
) -> (Vec<usize>, Vec<usize>, Vec<T>) {
    let (ys, xs) = (nodes(h, step), nodes(w, step));
    let mut out = vec![T::default(); ys.len() * xs.len()];
    out.par_chunks_mut(xs.len())
        .zip(ys.par_iter())
        .for_each(|(row, &y)| {
            if cancel::cancelled() {
                return;
            }
            for (o, &x) in row.iter_mut().zip(&xs) {
                *o = map([x as f64, y as f64]);
            }
        });
    (ys, xs, out)
}

/// The displacement field of `map` on an `h × w` grid (see the module notes), `H·W` pairs.
pub fn field(
    h: usize,
    w: usize,
    step: usize,
    map: impl Fn(Point) -> Point + Sync,
) -> Result<Vec<[f32; 2]>> {
    if h == 0 || w == 0 {
        return Err(invalid(
            "size",
            format!("expected a non-empty grid, got {h}×{w}"),
        ));
    }
    let step = step.max(1);
    let (ys, xs, nv) = on_nodes(h, w, step, map);
    cancel::check()?;
    Ok(interpolate(h, w, step, &ys, &xs, &nv))
}

/// The displacement field of an `h × w` grid from positions `nv` on its nodes `ys × xs`.
fn interpolate(
    h: usize,
    w: usize,
    step: usize,
    ys: &[usize],
    xs: &[usize],
    nv: &[Point],
) -> Vec<[f32; 2]> {
    let nx = xs.len();
    let mut out = vec![[0.0f32; 2]; h * w];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let a = (y / step).min(ys.len() - 2 + usize::from(ys.len() == 1));
        let (y0, y1) = (ys[a], ys[(a + 1).min(ys.len() - 1)]);
        let fy = if y1 > y0 {
            (y - y0) as f64 / (y1 - y0) as f64
        } else {
            0.0
        };
        let a1 = (a + 1).min(ys.len() - 1);
        for (x, o) in row.iter_mut().enumerate() {
            let b = (x / step).min(nx - 2 + usize::from(nx == 1));
            let b1 = (b + 1).min(nx - 1);
            let (x0, x1) = (xs[b], xs[b1]);
            let fx = if x1 > x0 {
                (x - x0) as f64 / (x1 - x0) as f64
            } else {
                0.0
            };
            let p00 = nv[a * nx + b];
            let p01 = nv[a * nx + b1];
            let p10 = nv[a1 * nx + b];
            let p11 = nv[a1 * nx + b1];
            for c in 0..2 {
                let top = p00[c] + fx * (p01[c] - p00[c]);
                let bot = p10[c] + fx * (p11[c] - p10[c]);
                let v = top + fy * (bot - top);
                let base = if c == 0 { x } else { y } as f64;
                o[c] = (v - base) as f32;
            }
        }
    });
    out
}

/// The inverse of `f` at `p`: `q` with `f(q) = p`, by Newton steps from `start`.
#[must_use]
pub fn invert(f: &Tps, p: Point, start: Point) -> Point {
    invert_jacobian(f, p, start).0
}

/// [`invert`] and the Jacobian of `f` at the result when the last Newton step evaluated it
/// there (it converged), so the fold check need not evaluate it again.
fn invert_jacobian(f: &Tps, p: Point, start: Point) -> (Point, Option<[[f64; 2]; 2]>) {
    let mut q = start;
    for _ in 0..8 {
        let (fq, j) = f.eval_jacobian(q);
        let r = [fq[0] - p[0], fq[1] - p[1]];
        if r[0].abs() + r[1].abs() < 1e-6 {
            return (q, Some(j));
        }
        let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
        if det.abs() < 1e-12 {
            return (q, Some(j));
        }
        q[0] -= (j[1][1] * r[0] - j[0][1] * r[1]) / det;
        q[1] -= (-j[1][0] * r[0] + j[0][0] * r[1]) / det;
    }
    (q, None)
}

/// Which nodes of an `h × w` grid (row-major over nodes) lie near the set pixels of `mask`:
/// every node of a cell that holds a set pixel; all nodes without a mask.
fn mask_on(mask: Option<&[bool]>, h: usize, w: usize, step: usize) -> Vec<bool> {
    let (ys, xs) = (nodes(h, step), nodes(w, step));
    let nx = xs.len();
    let mut on = vec![mask.is_none(); ys.len() * nx];
    if let Some(m) = mask {
        for y in 0..h {
            for x in 0..w {
                if m[y * w + x] {
                    let (a, b) = ((y / step).min(ys.len() - 1), (x / step).min(nx - 1));
                    for (da, db) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                        let (i, j) = ((a + da).min(ys.len() - 1), (b + db).min(nx - 1));
                        on[i * nx + j] = true;
                    }
                }
            }
        }
    }
    on
}

fn det(j: &[[f64; 2]; 2]) -> f64 {
    j[0][0] * j[1][1] - j[0][1] * j[1][0]
}

/// One image side of a dense registration: size and optional mask of the leaf.
#[derive(Clone, Copy)]
pub struct Side<'a> {
    /// Height and width.
    pub size: (usize, usize),
    /// Where the leaf is, `H·W`; `None` for everywhere.
    pub mask: Option<&'a [bool]>,
}

/// A registration with its dense fields.
pub struct Dense {
    /// TPS-RPM's result (`rpm.tps` replaced by the fold-free spline actually used).
    pub rpm: Rpm,
    /// The spline from the fixed frame to the moving one.
    pub forward_tps: Tps,
    /// The spline fitted for the way back (before the Newton refinement).
    pub inverse_tps: Tps,
    /// Fixed-frame displacements to moving-frame positions, `H_f·W_f`.
    pub forward: Vec<[f32; 2]>,
    /// Moving-frame displacements to fixed-frame positions, `H_m·W_m`.
    pub inverse: Vec<[f32; 2]>,
    /// Times the bending penalty was multiplied by 10 to remove a fold.
    pub refits: usize,
    /// The smallest Jacobian determinant of the forward map over the fixed leaf and over the
    /// preimage of the moving leaf.
    pub min_det: f64,
}

/// Registers `fixed` keypoints onto `moving` ones and builds both dense fields (see
/// [`Dense`]). If the forward map folds (a Jacobian determinant `≤ 0` at a node in or next
/// to the fixed leaf, or at the preimage of one in or next to the moving leaf), the last fit
/// is redone with `λ1` ten times larger, up to 8 times.
pub fn register(
    fixed: &[Point],
    moving: &[Point],
    params: &Params,
    fixed_side: Side<'_>,
    moving_side: Side<'_>,
    step: usize,
) -> Result<Dense> {
    for (name, s) in [("fixed", fixed_side), ("moving", moving_side)] {
        let (h, w) = s.size;
        if h == 0 || w == 0 {
            return Err(invalid(
                name,
                format!("expected a non-empty image, got {h}×{w}"),
            ));
        }
        if s.mask.is_some_and(|m| m.len() != h * w) {
            return Err(invalid(name, "mask does not match the image size"));
        }
    }
    let r = rpm(fixed, moving, params, ("fixed points", "moving points"))?;
    densify(r, fixed_side, moving_side, step)
}

/// The dense part of [`register`], from TPS-RPM's result `r` for the fixed points `fixed`.
pub fn densify(
    mut r: Rpm,
    fixed_side: Side<'_>,
    moving_side: Side<'_>,
    step: usize,
) -> Result<Dense> {
    let step = step.max(1);
    let fr = r.frame;
    let (hf, wf) = fixed_side.size;
    let (hm, wm) = moving_side.size;
    if hf == 0 || wf == 0 || hm == 0 || wm == 0 {
        return Err(invalid("size", "expected non-empty images"));
    }
    let fixed_on = mask_on(fixed_side.mask, hf, wf, step);
    let moving_on = mask_on(moving_side.mask, hm, wm, step);
    let mut lambda1 = r.lambda1;
    let mut refits = 0;
    loop {
        cancel::check()?;
        let mut warped = vec![[0.0; 2]; r.ctrl.len()];
        let t = r
            .basis
            .fit_at_controls(&r.targets, lambda1, r.lambda2, &mut warped);
        let f = to_input(&t, &r.ctrl, fr.cx, fr.cy, fr.scale);
        // The way back: a spline from f(x_i) to x_i, refined by Newton on f itself.
        let back = Basis::new("moving points", &warped)?;
        let xs: Vec<Point> = r
            .ctrl
            .iter()
            .map(|p| [(p[0] - fr.cx[0]) / fr.scale, (p[1] - fr.cx[1]) / fr.scale])
            .collect();
        let gt = back.fit(&xs, lambda1, 0.0);
        let ctrl: Vec<Point> = warped
            .iter()
            .map(|p| [p[0] * fr.scale + fr.cy[0], p[1] * fr.scale + fr.cy[1]])
            .collect();
        let g = to_input(&gt, &ctrl, fr.cy, fr.cx, fr.scale);
        // Each node grid is evaluated once: the forward nodes with their Jacobians give the
        // field and the fold check over the fixed leaf; the Newton-refined inverse nodes give
        // the inverse field and, at the moving leaf's nodes, the preimages to check.
        let (ysf, xsf, fj) = on_nodes(hf, wf, step, |p| f.eval_jacobian(p));
        cancel::check()?;
        let (ysm, xsm, inv_j) = on_nodes(hm, wm, step, |p| invert_jacobian(&f, p, g.eval(p)));
        cancel::check()?;
        let det_f = fj
            .par_iter()
            .zip(fixed_on.par_iter())
            .filter(|(_, &on)| on)
            .map(|((_, j), _)| det(j))
            .reduce(|| f64::INFINITY, f64::min);
        let det_m = inv_j
            .par_iter()
            .zip(moving_on.par_iter())
            .filter(|(_, &on)| on)
            .map(|(&(q, j), _)| det(&j.unwrap_or_else(|| f.eval_jacobian(q).1)))
            .reduce(|| f64::INFINITY, f64::min);
        let det = det_f.min(det_m);
        if det > 0.0 || refits == 8 {
            if det <= 0.0 {
                return Err(invalid(
                    "moving",
                    "the registration folds even with a 10⁸ times stiffer spline; are the two images of the same kind of leaf?",
                ));
            }
            let fwd: Vec<Point> = fj.iter().map(|(p, _)| *p).collect();
            let forward = interpolate(hf, wf, step, &ysf, &xsf, &fwd);
            let inv: Vec<Point> = inv_j.iter().map(|(q, _)| *q).collect();
            let inverse = interpolate(hm, wm, step, &ysm, &xsm, &inv);
            r.tps = f.clone();
            return Ok(Dense {
                rpm: r,
                forward_tps: f,
                inverse_tps: g,
                forward,
                inverse,
                refits,
                min_det: det,
            });
        }
        lambda1 = if lambda1 > 0.0 { lambda1 * 10.0 } else { 1e-3 };
        refits += 1;
    }
}

/// Samples `img` bilinearly at `pixel + field` for every pixel of an `h × w` result
/// (`H·W·C` values); positions outside the image give 0 (transparent), as `phloem.warp` does.
pub fn sample(img: &Image<'_>, field: &[[f32; 2]], h: usize, w: usize) -> Result<Vec<f32>> {
    if field.len() != h * w {
        return Err(invalid(
            "field",
            format!("expected {h}×{w} displacements, got {}", field.len()),
        ));
    }
    let c = img.c;
    let mut out = vec![0.0f32; h * w * c];
    out.par_chunks_mut(w * c).enumerate().for_each(|(y, row)| {
        for (x, px) in row.chunks_exact_mut(c).enumerate() {
            let d = field[y * w + x];
            crate::mvc::sample_any(img, x as f32 + d[0], y as f32 + d[1], px);
        }
    });
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::super::rpm::tests::{leaf, warp};
    use super::*;

    fn setup(threads: usize) -> Dense {
        let x = leaf(100);
        let y: Vec<Point> = x.iter().map(|&p| warp(p)).collect();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            register(
                &x,
                &y,
                &Params::default(),
                Side {
                    size: (400, 500),
                    mask: None,
                },
                Side {
                    size: (420, 520),
                    mask: None,
                },
                4,
            )
            .unwrap()
        })
    }

    #[test]
    fn forward_then_inverse_is_the_identity_and_fold_free() {
        let d = setup(2);
        assert!(d.min_det > 0.0);
        let (wf, wm) = (500usize, 520usize);
        let mut worst = 0.0f64;
        // Inside the leaf (the fixed outline's bounding box, shrunk).
        for y in (130..270).step_by(3) {
            for x in (120..380).step_by(3) {
                let f = d.forward[y * wf + x];
                let (mx, my) = (x as f64 + f64::from(f[0]), y as f64 + f64::from(f[1]));
                // Bilinear lookup of the inverse field at the moving position.
                let (x0, y0) = (mx.floor() as usize, my.floor() as usize);
                let (ax, ay) = (mx - x0 as f64, my - y0 as f64);
                let at = |xx: usize, yy: usize| {
                    let g = d.inverse[yy * wm + xx];
                    [xx as f64 + f64::from(g[0]), yy as f64 + f64::from(g[1])]
                };
                let (p00, p01, p10, p11) = (
                    at(x0, y0),
                    at(x0 + 1, y0),
                    at(x0, y0 + 1),
                    at(x0 + 1, y0 + 1),
                );
                for (c, base) in [(0, x as f64), (1, y as f64)] {
                    let top = p00[c] + ax * (p01[c] - p00[c]);
                    let bot = p10[c] + ax * (p11[c] - p10[c]);
                    worst = worst.max((top + ay * (bot - top) - base).abs());
                }
            }
        }
        assert!(worst <= 0.1, "forward∘inverse off by {worst:.4} px");
    }

    #[test]
    fn coarse_nodes_agree_with_exact_evaluation() {
        let d = setup(1);
        let w = 500;
        let mut worst = 0.0f64;
        for y in (0..400).step_by(7) {
            for x in (0..500).step_by(5) {
                let e = d.forward_tps.eval([x as f64, y as f64]);
                let f = d.forward[y * w + x];
                worst = worst
                    .max((x as f64 + f64::from(f[0]) - e[0]).abs())
                    .max((y as f64 + f64::from(f[1]) - e[1]).abs());
            }
        }
        assert!(worst < 0.05, "interpolation error {worst} px");
    }

    #[test]
    #[allow(clippy::float_cmp)] // the same arithmetic: equal to the bit
    fn the_inverse_keeps_the_jacobian_at_its_result() {
        // The fold check uses it in place of a new evaluation: it must be the one at `q`.
        let d = setup(1);
        let f = &d.forward_tps;
        let mut kept = 0;
        for p in [
            [300.0, 200.0],
            [150.0, 260.0],
            [420.0, 120.0],
            [10.0, 390.0],
        ] {
            let (q, j) = invert_jacobian(f, p, d.inverse_tps.eval(p));
            assert_eq!(q, invert(f, p, d.inverse_tps.eval(p)));
            if let Some(j) = j {
                assert_eq!(j, f.eval_jacobian(q).1);
                kept += 1;
            }
        }
        assert_eq!(kept, 4);
    }

    #[test]
    fn the_same_for_one_and_two_threads() {
        let (a, b) = (setup(1), setup(2));
        assert_eq!(a.forward, b.forward);
        assert_eq!(a.inverse, b.inverse);
        assert_eq!(a.rpm.matches, b.rpm.matches);
    }

    #[test]
    fn a_fold_is_removed_by_a_stiffer_spline() {
        // Two close points pulled across each other fold an interpolating spline.
        let mut x = leaf(30);
        x.push([250.0, 190.0]);
        x.push([250.0, 210.0]);
        let mut r = rpm(
            &x,
            &x,
            &Params {
                polish: false,
                ..Params::default()
            },
            ("x", "y"),
        )
        .unwrap();
        let fr = r.frame;
        let n = x.len();
        r.targets = x
            .iter()
            .map(|p| [(p[0] - fr.cy[0]) / fr.scale, (p[1] - fr.cy[1]) / fr.scale])
            .collect();
        r.targets[n - 2][1] += 25.0 / fr.scale;
        r.targets[n - 1][1] -= 25.0 / fr.scale;
        r.lambda1 = 0.0;
        let side = Side {
            size: (400, 500),
            mask: None,
        };
        let d = densify(r, side, side, 8).unwrap();
        assert!(
            d.refits > 0 && d.min_det > 0.0,
            "refits {} det {}",
            d.refits,
            d.min_det
        );
        // The unregularised fit does fold there: the check is not vacuous.
        let b = Basis::new("x", &x).unwrap();
        let mut t: Vec<Point> = x.clone();
        t[n - 2][1] += 25.0;
        t[n - 1][1] -= 25.0;
        assert!(b.fit(&t, 0.0, 0.0).eval_jacobian([250.0, 200.0]).1[1][1] < 0.0);
    }
}
