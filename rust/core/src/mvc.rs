//! Mean value coordinates and the image warp they define (Hormann & Floater, "Mean value
//! coordinates for arbitrary planar polygons", ACM TOG 25(4), 2006), as the colour transfer
//! of Argudo et al., "Tree variations", CEIG 2017, §5.2 uses them.
//!
//! For a simple polygon `v_0 … v_{N−1}` (any orientation, concave allowed) and a point `x`
//! not on it, let `s_i = v_i − x`, `r_i = |s_i|`, `A_i = s_i × s_{i+1}` and
//! `D_i = s_i · s_{i+1}`. The signed angle `α_i` at `x` in the triangle `x v_i v_{i+1}` has
//! `tan(α_i/2) = A_i / (r_i r_{i+1} + D_i) = (r_i r_{i+1} − D_i) / A_i`; we use the first form
//! when `D_i ≥ 0` and the second otherwise, so the denominator is never smaller than
//! `r_i r_{i+1}` in magnitude except on the polygon itself. The weights
//! `w_i = (tan(α_{i−1}/2) + tan(α_i/2)) / r_i` and coordinates `λ_i = w_i / Σ_j w_j` are
//! defined everywhere in the plane off the polygon (HF06 §3), sum to one and
//! have linear precision (`Σ λ_i v_i = x`). On a vertex `λ` is that vertex's indicator; on an
//! edge it interpolates the edge's two ends linearly — the limits of the formula there.
//!
//! The warp: every pixel centre `x` of a target image (pixel `(row, col)` has centre
//! `(x, y) = (col, row)`, as in `OpenCV` contours) is mapped to `q = Σ λ_i(x) u_i` with `λ`
//! taken w.r.t. the target contour `v` and `u` the source contour, and the source is sampled
//! bilinearly at `q`. Mathematically `q = x + Σ λ_i (u_i − v_i)` (linear precision), and that
//! is how it is computed: rounding then scales with the displacement, not the coordinates,
//! and equal contours map every pixel exactly to itself. The fast path evaluates the
//! coordinates of 16 pixels at a time in `f32` lanes (one `sqrt` and one division per
//! vertex and pixel; compiled for AVX2 too and chosen at run time, with identical results).
//! Pixels on or within about `10⁻³` of an edge, within `0.1` px of a vertex, or with a
//! non-finite result are redone in `f64` with the exact rules above.
//! Rows run in parallel and each pixel's arithmetic is fixed, so the result is the same for
//! any number of threads.

// Lane loops index several arrays in lockstep; the index form is what vectorises.
#![allow(clippy::needless_range_loop)]
// The lane kernel must be inlined into its AVX2 copy to be compiled for AVX2.
#![allow(clippy::inline_always)]

use rayon::prelude::*;

use crate::error::{invalid, Result};
use crate::image::Image;

/// A point `(x, y)`: `x` along columns, `y` along rows.
pub type Point = [f64; 2];

/// Pixels per lane group of the fast path.
const L: usize = 16;

/// Checks that every point of `points` has finite coordinates.
fn check_finite(name: &'static str, points: &[Point]) -> Result<()> {
    match points
        .iter()
        .position(|p| !(p[0].is_finite() && p[1].is_finite()))
    {
        Some(i) => Err(invalid(
            name,
            format!(
                "expected finite coordinates, found ({}, {}) at point {i}",
                points[i][0], points[i][1]
            ),
        )),
        None => Ok(()),
    }
}

/// Checks that `contour` is a usable polygon: at least 3 finite points, no two consecutive
/// ones equal (the last and the first count as consecutive: do not repeat the first point at
/// the end), and a non-zero area.
pub fn check_contour(name: &'static str, contour: &[Point]) -> Result<()> {
    let n = contour.len();
    if n < 3 {
        return Err(invalid(
            name,
            format!("expected at least 3 points, got {n}"),
        ));
    }
    check_finite(name, contour)?;
    for i in 0..n {
        let j = (i + 1) % n;
        // A zero-length edge (the values are finite, so this is exact equality).
        if contour[j][0] - contour[i][0] == 0.0 && contour[j][1] - contour[i][1] == 0.0 {
            return Err(invalid(
                name,
                format!(
                    "points {i} and {j} are equal ({}, {}); consecutive points must differ \
                     (do not repeat the first point at the end)",
                    contour[i][0], contour[i][1]
                ),
            ));
        }
    }
    // Shoelace area relative to the first point, so large offsets do not swamp it.
    let o = contour[0];
    let mut area2 = 0.0;
    let mut scale = 0.0f64;
    for i in 1..n - 1 {
        let (a, b) = (contour[i], contour[i + 1]);
        let (ax, ay, bx, by) = (a[0] - o[0], a[1] - o[1], b[0] - o[0], b[1] - o[1]);
        area2 += ax * by - ay * bx;
        scale = scale.max(ax.abs().max(ay.abs()));
    }
    if area2.abs() <= 1e-12 * scale * scale {
        return Err(invalid(
            name,
            "expected a polygon with non-zero area, got a degenerate one (all points on a line)",
        ));
    }
    Ok(())
}

/// Writes the mean value coordinates of `p` w.r.t. `polygon` into `out` (`polygon.len()`
/// values), in `f64`. `polygon` must have passed [`check_contour`].
///
/// # Panics
/// If `out.len() != polygon.len()`.
pub fn weights(polygon: &[Point], p: Point, out: &mut [f64]) {
    let n = polygon.len();
    assert_eq!(out.len(), n, "one weight per vertex");
    out.fill(0.0);
    // First pass: on a vertex or an edge the coordinates are known exactly.
    for i in 0..n {
        let (a, b) = (polygon[i], polygon[(i + 1) % n]);
        let (sx, sy) = (a[0] - p[0], a[1] - p[1]);
        if sx == 0.0 && sy == 0.0 {
            out[i] = 1.0;
            return;
        }
        let (tx, ty) = (b[0] - p[0], b[1] - p[1]);
        if sx * ty - sy * tx == 0.0 && sx * tx + sy * ty < 0.0 {
            let (ri, rj) = (sx.hypot(sy), tx.hypot(ty));
            out[i] = rj / (ri + rj);
            out[(i + 1) % n] = ri / (ri + rj);
            return;
        }
    }
    let s = |i: usize| {
        let v = polygon[i % n];
        let (x, y) = (v[0] - p[0], v[1] - p[1]);
        (x, y, x.hypot(y))
    };
    // tan(α_i / 2) of the edge from vertex i to i + 1.
    let tan_half = |a: (f64, f64, f64), b: (f64, f64, f64)| {
        let cross = a.0 * b.1 - a.1 * b.0;
        let dot = a.0 * b.0 + a.1 * b.1;
        let rr = a.2 * b.2;
        if dot >= 0.0 {
            cross / (rr + dot)
        } else {
            (rr - dot) / cross
        }
    };
    let first = s(0);
    let mut prev = first;
    let mut t_prev = tan_half(s(n - 1), first);
    let mut sum = 0.0;
    for i in 0..n {
        let next = if i + 1 == n { first } else { s(i + 1) };
        let t = tan_half(prev, next);
        let w = (t_prev + t) / prev.2;
        out[i] = w;
        sum += w;
        t_prev = t;
        prev = next;
    }
    for w in out.iter_mut() {
        *w /= sum;
    }
}

/// Mean value coordinates of many points: a row-major `points.len() × polygon.len()` array.
/// Runs in parallel over points.
pub fn weights_many(
    polygon: &[Point],
    points: &[Point],
    polygon_name: &'static str,
    points_name: &'static str,
) -> Result<Vec<f64>> {
    check_contour(polygon_name, polygon)?;
    check_finite(points_name, points)?;
    let n = polygon.len();
    let mut out = vec![0.0; points.len() * n];
    out.par_chunks_mut(n)
        .zip(points.par_iter())
        .for_each(|(row, &p)| weights(polygon, p, row));
    Ok(out)
}

/// A target contour with, per source, the displacements `u_i − v_i`, laid out for the lanes.
struct Mapping {
    vx: Vec<f32>,
    vy: Vec<f32>,
    /// `k * n + i`: displacement of vertex `i` for source `k`.
    dx: Vec<f32>,
    dy: Vec<f32>,
    target: Vec<Point>,
    disp: Vec<Vec<Point>>,
}

impl Mapping {
    fn new(target: &[Point], sources: &[&[Point]]) -> Self {
        let disp: Vec<Vec<Point>> = sources
            .iter()
            .map(|s| {
                s.iter()
                    .zip(target)
                    .map(|(u, v)| [u[0] - v[0], u[1] - v[1]])
                    .collect()
            })
            .collect();
        Self {
            vx: target.iter().map(|v| v[0] as f32).collect(),
            vy: target.iter().map(|v| v[1] as f32).collect(),
            dx: disp.iter().flatten().map(|d| d[0] as f32).collect(),
            dy: disp.iter().flatten().map(|d| d[1] as f32).collect(),
            target: target.to_vec(),
            disp,
        }
    }

    /// Source positions of pixels `x0 .. x0 + L` of row `y`: `qx[k][l]`, `qy[k][l]`.
    /// Returns a bit mask of the lanes the `f32` arithmetic cannot be trusted with.
    ///
    /// One division per vertex: with `z = 1 / (den_i r_{i+1})` of edge `(i, i + 1)`,
    /// `tan(α_i/2) = num_i r_{i+1} z` and `1 / r_{i+1} = den_i z`.
    #[inline(always)]
    fn lanes(&self, x0: usize, y: f32, qx: &mut [[f32; L]], qy: &mut [[f32; L]]) -> u32 {
        let n = self.vx.len();
        let k_count = qx.len();
        let mut px = [0.0f32; L];
        for l in 0..L {
            px[l] = (x0 + l) as f32;
        }
        let mut suspect = [false; L];
        let vertex = |i: usize, sx: &mut [f32; L], sy: &mut [f32; L], r: &mut [f32; L]| {
            let (vx, vy) = (self.vx[i], self.vy[i]);
            for l in 0..L {
                sx[l] = vx - px[l];
                sy[l] = vy - y;
                r[l] = (sx[l] * sx[l] + sy[l] * sy[l]).sqrt();
            }
        };
        // Edge from vertex a to vertex b: tan(α/2) and 1 / r_b.
        let edge = |a: (&[f32; L], &[f32; L], &[f32; L]),
                    b: (&[f32; L], &[f32; L], &[f32; L]),
                    t: &mut [f32; L],
                    inv: &mut [f32; L],
                    suspect: &mut [bool; L]| {
            for l in 0..L {
                let cross = a.0[l] * b.1[l] - a.1[l] * b.0[l];
                let dot = a.0[l] * b.0[l] + a.1[l] * b.1[l];
                let rr = a.2[l] * b.2[l];
                let pos = dot >= 0.0;
                let num = if pos { cross } else { rr - dot };
                let den = if pos { rr + dot } else { cross };
                suspect[l] |= (!pos && cross.abs() <= 1e-3 * rr) || b.2[l] < 0.1;
                let z = 1.0 / (den * b.2[l]);
                t[l] = num * b.2[l] * z;
                inv[l] = den * z;
            }
        };
        let (mut sx0, mut sy0, mut r0) = ([0.0f32; L], [0.0f32; L], [0.0f32; L]);
        let (mut sxp, mut syp, mut rp) = ([0.0f32; L], [0.0f32; L], [0.0f32; L]);
        vertex(0, &mut sx0, &mut sy0, &mut r0);
        vertex(n - 1, &mut sxp, &mut syp, &mut rp);
        let (mut t_prev, mut inv0) = ([0.0f32; L], [0.0f32; L]);
        edge(
            (&sxp, &syp, &rp),
            (&sx0, &sy0, &r0),
            &mut t_prev,
            &mut inv0,
            &mut suspect,
        );
        let (mut sxc, mut syc, mut rc, mut invc) = (sx0, sy0, r0, inv0);
        let mut wsum = [0.0f32; L];
        for k in 0..k_count {
            qx[k] = [0.0; L];
            qy[k] = [0.0; L];
        }
        let (mut sx, mut sy, mut r) = ([0.0f32; L], [0.0f32; L], [0.0f32; L]);
        let (mut t, mut inv) = ([0.0f32; L], [0.0f32; L]);
        for i in 0..n {
            // Vertex i is (sxc, syc, rc, invc); edge (i, i + 1) gives its second tangent.
            if i + 1 < n {
                vertex(i + 1, &mut sx, &mut sy, &mut r);
            } else {
                (sx, sy, r) = (sx0, sy0, r0);
            }
            edge(
                (&sxc, &syc, &rc),
                (&sx, &sy, &r),
                &mut t,
                &mut inv,
                &mut suspect,
            );
            let mut w = [0.0f32; L];
            for l in 0..L {
                w[l] = (t_prev[l] + t[l]) * invc[l];
                wsum[l] += w[l];
            }
            for k in 0..k_count {
                let (dx, dy) = (self.dx[k * n + i], self.dy[k * n + i]);
                let (ax, ay) = (&mut qx[k], &mut qy[k]);
                for l in 0..L {
                    ax[l] += w[l] * dx;
                    ay[l] += w[l] * dy;
                }
            }
            (sxc, syc, rc, invc, t_prev) = (sx, sy, r, inv, t);
        }
        let mut bad = 0u32;
        for k in 0..k_count {
            for l in 0..L {
                qx[k][l] = px[l] + qx[k][l] / wsum[l];
                qy[k][l] = y + qy[k][l] / wsum[l];
            }
        }
        for l in 0..L {
            let finite = (0..k_count).all(|k| qx[k][l].is_finite() && qy[k][l].is_finite());
            if suspect[l] || !finite {
                bad |= 1 << l;
            }
        }
        bad
    }

    /// Source positions of pixel `(x, y)` in `f64` with the exact rules; `lam` is scratch.
    fn exact(&self, x: f64, y: f64, lam: &mut [f64], q: &mut [(f32, f32)]) {
        weights(&self.target, [x, y], lam);
        for (qk, d) in q.iter_mut().zip(&self.disp) {
            let (mut ax, mut ay) = (0.0, 0.0);
            for (l, di) in lam.iter().zip(d) {
                ax += l * di[0];
                ay += l * di[1];
            }
            *qk = ((x + ax) as f32, (y + ay) as f32);
        }
    }

    /// Source positions of every pixel of row `y` (`width` pixels): `out[k * width + x]`.
    ///
    /// Compiled twice, for the baseline and for AVX2, and chosen at run time. No fused
    /// multiply-adds are used, so both give bit-identical results.
    /// Source positions of pixels `span.0 .. span.1` of row `y` (a row `width` long) into
    /// `out[k * width + x]`; the rest of `out` is left as it is.
    fn row(&self, y: usize, width: usize, span: (usize, usize), out: &mut [(f32, f32)]) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2, checked just above.
            unsafe { self.row_avx2(y, width, span, out) };
            return;
        }
        self.row_any(y, width, span, out);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn row_avx2(
        &self,
        y: usize,
        width: usize,
        span: (usize, usize),
        out: &mut [(f32, f32)],
    ) {
        self.row_any(y, width, span, out);
    }

    #[inline(always)]
    fn row_any(&self, y: usize, width: usize, span: (usize, usize), out: &mut [(f32, f32)]) {
        let k_count = self.disp.len();
        let mut qx = vec![[0.0f32; L]; k_count];
        let mut qy = vec![[0.0f32; L]; k_count];
        let mut lam = vec![0.0; self.vx.len()];
        let mut q = vec![(0.0f32, 0.0f32); k_count];
        for x0 in (span.0..span.1).step_by(L) {
            let bad = self.lanes(x0, y as f32, &mut qx, &mut qy);
            for l in 0..L.min(span.1 - x0) {
                let x = x0 + l;
                if bad & (1 << l) != 0 {
                    self.exact(x as f64, y as f64, &mut lam, &mut q);
                    for k in 0..k_count {
                        out[k * width + x] = q[k];
                    }
                } else {
                    for k in 0..k_count {
                        out[k * width + x] = (qx[k][l], qy[k][l]);
                    }
                }
            }
        }
    }
}

/// Bilinear sample of `img` at `(x, y)` into `out`. The image covers `[−0.5, w − 0.5) ×
/// [−0.5, h − 0.5)`: outside it the result is zero in every channel (transparent), inside it
/// the edge pixels are replicated up to the border.
/// `C` is the channel count when known at compile time, 0 to read it from `img`.
#[inline(always)]
fn sample<const C: usize>(img: &Image<'_>, x: f32, y: f32, out: &mut [f32]) {
    let (w, h) = (img.w as f32, img.h as f32);
    if !(x >= -0.5 && x < w - 0.5 && y >= -0.5 && y < h - 0.5) {
        out.fill(0.0);
        return;
    }
    let xc = x.clamp(0.0, w - 1.0);
    let yc = y.clamp(0.0, h - 1.0);
    // Truncation is the floor here (both are >= 0) and, unlike `floor`, needs no libm call.
    let (x0, y0) = (xc as usize, yc as usize);
    let (fx, fy) = (xc - x0 as f32, yc - y0 as f32);
    let c = if C == 0 { img.c } else { C };
    let step_x = if x0 + 1 < img.w { c } else { 0 };
    let step_y = if y0 + 1 < img.h { img.w * c } else { 0 };
    let o = (y0 * img.w + x0) * c;
    let d = &img.data[o..o + step_y + step_x + c];
    for (ch, v) in out.iter_mut().enumerate().take(c) {
        let (a, b) = (d[ch], d[ch + step_x]);
        let (e, f) = (d[ch + step_y], d[ch + step_y + step_x]);
        let top = a + fx * (b - a);
        let bot = e + fx * (f - e);
        *v = top + fy * (bot - top);
    }
}

/// [`sample`] with the channel loop unrolled for RGBA, the common case.
#[inline(always)]
pub(crate) fn sample_any(img: &Image<'_>, x: f32, y: f32, out: &mut [f32]) {
    if img.c == 4 {
        sample::<4>(img, x, y, out);
    } else {
        sample::<0>(img, x, y, out);
    }
}

/// The columns `first .. last + 1` of the set pixels of row `y` of `region` (all of the row
/// without a region; `(0, 0)` for a row with none set).
fn span(region: Option<&[bool]>, y: usize, width: usize) -> (usize, usize) {
    match region {
        None => (0, width),
        Some(r) => {
            let row = &r[y * width..(y + 1) * width];
            match row.iter().position(|&b| b) {
                None => (0, 0),
                Some(a) => (a, width - row.iter().rev().position(|&b| b).unwrap_or(0)),
            }
        }
    }
}

fn check_region(region: Option<&[bool]>, height: usize, width: usize) -> Result<()> {
    match region {
        Some(r) if r.len() != height * width => Err(invalid(
            "region",
            format!(
                "expected a ({height}, {width}) mask like the result, got {} pixels",
                r.len()
            ),
        )),
        _ => Ok(()),
    }
}

fn check_sources(
    sources: &[Image<'_>],
    source_contours: &[&[Point]],
    target: &[Point],
    height: usize,
    width: usize,
) -> Result<()> {
    if sources.is_empty() {
        return Err(invalid("sources", "expected at least one source image"));
    }
    if source_contours.len() != sources.len() {
        return Err(invalid(
            "source_contours",
            format!(
                "expected one contour per source ({}), got {}",
                sources.len(),
                source_contours.len()
            ),
        ));
    }
    if height == 0 || width == 0 {
        return Err(invalid(
            "size",
            format!("expected a non-empty size, got ({height}, {width})"),
        ));
    }
    check_contour("target_contour", target)?;
    let c = sources[0].c;
    for (s, contour) in sources.iter().zip(source_contours) {
        if s.c != c {
            return Err(invalid(
                "sources",
                format!("expected {c} channels in every source, got {}", s.c),
            ));
        }
        check_contour("source_contours", contour)?;
        if contour.len() != target.len() {
            return Err(invalid(
                "source_contours",
                format!(
                    "expected {} points like target_contour, got {}",
                    target.len(),
                    contour.len()
                ),
            ));
        }
        s.check_finite("sources")?;
    }
    Ok(())
}

/// Warps each source onto a `height × width` target: the pixel at `x` of warped image `k`
/// is source `k` sampled bilinearly at `Σ λ_i(x) u^k_i`, `λ` the mean value coordinates of
/// `x` w.r.t. `target` and `u^k` = `source_contours[k]` (same length as `target`). Returns
/// one `height × width × C` buffer per source. With a `region` (`height × width`, row-major)
/// only its pixels are computed; the others are zero.
pub fn warp(
    sources: &[Image<'_>],
    source_contours: &[&[Point]],
    target: &[Point],
    height: usize,
    width: usize,
    region: Option<&[bool]>,
) -> Result<Vec<Vec<f32>>> {
    check_sources(sources, source_contours, target, height, width)?;
    check_region(region, height, width)?;
    let c = sources[0].c;
    let k_count = sources.len();
    let map = Mapping::new(target, source_contours);
    let mut out = vec![vec![0.0f32; height * width * c]; k_count];
    // Row `y` of every image, written straight into its output (no side-by-side buffer to
    // split afterwards).
    let mut rows: Vec<Vec<&mut [f32]>> = (0..height).map(|_| Vec::with_capacity(k_count)).collect();
    for img in &mut out {
        for (row, part) in rows.iter_mut().zip(img.chunks_exact_mut(width * c)) {
            row.push(part);
        }
    }
    rows.into_par_iter().enumerate().for_each(|(y, mut parts)| {
        if crate::cancel::cancelled() {
            return;
        }
        let sp = span(region, y, width);
        let mut q = vec![(0.0f32, 0.0f32); k_count * width];
        map.row(y, width, sp, &mut q);
        for (k, (src, o)) in sources.iter().zip(&mut parts).enumerate() {
            for (x, px) in o.chunks_exact_mut(c).enumerate().take(sp.1).skip(sp.0) {
                if region.is_some_and(|r| !r[y * width + x]) {
                    continue;
                }
                let (qx, qy) = q[k * width + x];
                sample_any(src, qx, qy, px);
            }
        }
    });
    crate::cancel::check()?;
    Ok(out)
}

/// Checks combination weights: one per source, finite, non-negative, summing to 1 (within
/// `1e-6`).
pub fn check_weights(name: &'static str, weights: &[f64], count: usize) -> Result<()> {
    if weights.len() != count {
        return Err(invalid(
            name,
            format!(
                "expected {count} weights, one per source, got {}",
                weights.len()
            ),
        ));
    }
    if let Some(w) = weights.iter().find(|w| !(w.is_finite() && **w >= 0.0)) {
        return Err(invalid(
            name,
            format!("expected finite non-negative weights, got {w}"),
        ));
    }
    let sum: f64 = weights.iter().sum();
    if (sum - 1.0).abs() > 1e-6 {
        return Err(invalid(
            name,
            format!("expected weights summing to 1, got {sum}"),
        ));
    }
    Ok(())
}

/// Warps every source as [`warp`] does and combines them as Argudo et al. §5.2: the last
/// channel is alpha, the output alpha is the largest source alpha, and the other channels
/// are `Σ ω_k c_k / Σ ω_k` over the sources whose alpha is above zero at that pixel
/// (`ω` = `weights`; if those sources all have weight zero, their plain mean). Where every
/// source is transparent the pixel is zero. Sources need at least 2 channels. With a
/// `region` only its pixels are computed; the others are zero.
pub fn warp_combine(
    sources: &[Image<'_>],
    source_contours: &[&[Point]],
    target: &[Point],
    weights: &[f64],
    height: usize,
    width: usize,
    region: Option<&[bool]>,
) -> Result<Vec<f32>> {
    check_sources(sources, source_contours, target, height, width)?;
    check_region(region, height, width)?;
    check_weights("weights", weights, sources.len())?;
    let c = sources[0].c;
    if c < 2 {
        return Err(invalid(
            "sources",
            format!("expected colour channels and a last alpha channel (C >= 2), got C = {c}"),
        ));
    }
    let k_count = sources.len();
    let map = Mapping::new(target, source_contours);
    let wf: Vec<f32> = weights.iter().map(|&w| w as f32).collect();
    let mut out = vec![0.0f32; height * width * c];
    out.par_chunks_mut(width * c)
        .enumerate()
        .for_each(|(y, o)| {
            if crate::cancel::cancelled() {
                return;
            }
            let sp = span(region, y, width);
            let mut q = vec![(0.0f32, 0.0f32); k_count * width];
            map.row(y, width, sp, &mut q);
            let mut px = vec![0.0f32; c];
            for (x, dst) in o.chunks_exact_mut(c).enumerate().take(sp.1).skip(sp.0) {
                if region.is_some_and(|r| !r[y * width + x]) {
                    continue;
                }
                // Colour accumulates in the output pixel itself.
                dst.fill(0.0);
                let (mut wsum, mut count, mut alpha) = (0.0f32, 0u32, 0.0f32);
                for (k, src) in sources.iter().enumerate() {
                    let (qx, qy) = q[k * width + x];
                    sample_any(src, qx, qy, &mut px);
                    let a = px[c - 1];
                    if a > 0.0 {
                        alpha = alpha.max(a);
                        let wk = wf[k];
                        for ch in 0..c - 1 {
                            dst[ch] += wk * px[ch];
                        }
                        wsum += wk;
                        count += 1;
                    }
                }
                if count == 0 {
                    continue;
                }
                if wsum > 0.0 {
                    let inv = 1.0 / wsum;
                    for v in &mut dst[..c - 1] {
                        *v *= inv;
                    }
                } else {
                    // The visible sources all have weight 0: their plain mean (rare, so the
                    // samples are simply taken again).
                    for (k, src) in sources.iter().enumerate() {
                        let (qx, qy) = q[k * width + x];
                        sample_any(src, qx, qy, &mut px);
                        if px[c - 1] > 0.0 {
                            for ch in 0..c - 1 {
                                dst[ch] += px[ch];
                            }
                        }
                    }
                    let inv = 1.0 / count as f32;
                    for v in &mut dst[..c - 1] {
                        *v *= inv;
                    }
                }
                dst[c - 1] = alpha;
            }
        });
    crate::cancel::check()?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn star(n: usize) -> Vec<Point> {
        (0..2 * n)
            .map(|i| {
                let a = std::f64::consts::PI * i as f64 / n as f64;
                let r = if i % 2 == 0 { 10.0 } else { 4.0 };
                [20.0 + r * a.cos(), 15.0 + r * a.sin()]
            })
            .collect()
    }

    fn l_shape() -> Vec<Point> {
        vec![
            [2.0, 2.0],
            [12.0, 2.0],
            [12.0, 6.0],
            [6.0, 6.0],
            [6.0, 14.0],
            [2.0, 14.0],
        ]
    }

    fn check_linear(poly: &[Point], p: Point) {
        let mut lam = vec![0.0; poly.len()];
        weights(poly, p, &mut lam);
        let s: f64 = lam.iter().sum();
        let x: f64 = lam.iter().zip(poly).map(|(l, v)| l * v[0]).sum();
        let y: f64 = lam.iter().zip(poly).map(|(l, v)| l * v[1]).sum();
        assert!((s - 1.0).abs() < 1e-9, "sum {s} at {p:?}");
        assert!(
            (x - p[0]).abs() < 1e-9 && (y - p[1]).abs() < 1e-9,
            "{x} {y} at {p:?}"
        );
    }

    #[test]
    fn mvc_linear_precision_inside_and_outside() {
        for poly in [star(5), l_shape(), star(7).into_iter().rev().collect()] {
            for i in 0..40 {
                for j in 0..30 {
                    check_linear(&poly, [i as f64 * 0.77 - 3.1, j as f64 * 0.83 - 2.3]);
                }
            }
        }
    }

    #[test]
    fn mvc_vertices_and_edges_are_exact() {
        let poly = l_shape();
        let mut lam = vec![0.0; 6];
        weights(&poly, [6.0, 6.0], &mut lam);
        assert_eq!(lam, [0.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
        weights(&poly, [6.0, 8.0], &mut lam);
        assert_eq!(lam, [0.0, 0.0, 0.0, 0.75, 0.25, 0.0]);
        // On the closing edge (5 → 0).
        weights(&poly, [2.0, 5.0], &mut lam);
        assert_eq!(lam, [0.75, 0.0, 0.0, 0.0, 0.0, 0.25]);
    }

    #[test]
    fn mvc_convex_weights_are_positive_inside() {
        let sq = [[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]];
        let mut lam = vec![0.0; 4];
        weights(&sq, [1.0, 1.0], &mut lam);
        assert!(lam.iter().all(|&l| l > 0.0), "{lam:?}");
    }

    #[test]
    fn mvc_contour_errors_name_the_argument() {
        let e = check_contour("target_contour", &[[0.0, 0.0], [1.0, 0.0]]).unwrap_err();
        assert!(e
            .to_string()
            .starts_with("target_contour: expected at least 3"));
        let e = check_contour("c", &[[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.0, 1.0]]);
        assert!(e.unwrap_err().to_string().contains("consecutive"));
        let e = check_contour("c", &[[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]);
        assert!(e.unwrap_err().to_string().contains("non-zero area"));
        let e = check_contour("c", &[[0.0, 0.0], [f64::NAN, 1.0], [2.0, 0.0]]);
        assert!(e.unwrap_err().to_string().contains("finite"));
        assert!(check_weights("weights", &[0.5, 0.6], 2).is_err());
        assert!(check_weights("weights", &[1.5, -0.5], 2).is_err());
        assert!(check_weights("weights", &[0.25, 0.75], 2).is_ok());
    }

    /// The fast lanes agree with the exact `f64` map to a small fraction of a pixel.
    #[test]
    fn mvc_fast_path_matches_exact() {
        let target = star(6);
        let source: Vec<Point> = target
            .iter()
            .enumerate()
            .map(|(i, v)| [v[0] * 1.3 + (i % 3) as f64, v[1] * 0.8 - 2.0])
            .collect();
        let map = Mapping::new(&target, &[&source]);
        let (w, h) = (45, 35);
        let mut lam = vec![0.0; target.len()];
        let mut q = vec![(0.0, 0.0)];
        let mut worst = 0.0f32;
        for y in 0..h {
            let mut row = vec![(0.0, 0.0); w];
            map.row(y, w, (0, w), &mut row);
            for x in 0..w {
                map.exact(x as f64, y as f64, &mut lam, &mut q);
                worst = worst
                    .max((row[x].0 - q[0].0).abs())
                    .max((row[x].1 - q[0].1).abs());
            }
        }
        assert!(worst < 1e-3, "worst {worst}");
    }

    fn ramp(h: usize, w: usize) -> Vec<f32> {
        (0..h * w)
            .flat_map(|i| [(i % w) as f32, (i / w) as f32, 1.0])
            .collect()
    }

    #[test]
    fn mvc_identity_and_translation() {
        let (h, w) = (30, 40);
        let data = ramp(h, w);
        let img = Image::new("sources", &data, h, w, 3).unwrap();
        let target = l_shape();
        let same = warp(&[img], &[&target], &target, h, w, None).unwrap();
        assert_eq!(same[0], data);
        let shifted: Vec<Point> = target.iter().map(|v| [v[0] + 5.0, v[1] - 2.0]).collect();
        let moved = &warp(&[img], &[&shifted], &target, h, w, None).unwrap()[0];
        for y in 2..h {
            for x in 0..w - 5 {
                let p = &moved[(y * w + x) * 3..(y * w + x) * 3 + 3];
                assert!(
                    (p[0] - (x + 5) as f32).abs() < 1e-3 && (p[1] - (y - 2) as f32).abs() < 1e-3
                );
            }
        }
    }

    #[test]
    fn mvc_combine_alpha_max_and_colour_mix() {
        let (h, w) = (20, 20);
        let a: Vec<f32> = (0..h * w).flat_map(|_| [1.0, 0.0, 0.5]).collect();
        let b: Vec<f32> = (0..h * w).flat_map(|_| [0.0, 1.0, 0.8]).collect();
        let ia = Image::new("sources", &a, h, w, 3).unwrap();
        let ib = Image::new("sources", &b, h, w, 3).unwrap();
        let t = l_shape();
        let out = warp_combine(&[ia, ib], &[&t, &t], &t, &[0.25, 0.75], h, w, None).unwrap();
        for p in out.chunks_exact(3) {
            assert!(
                (p[0] - 0.25).abs() < 1e-6
                    && (p[1] - 0.75).abs() < 1e-6
                    && p[2].to_bits() == 0.8f32.to_bits()
            );
        }
    }

    #[test]
    fn region_limits_work_to_its_pixels_and_matches_the_full_warp() {
        let (h, w) = (30, 40);
        let data = ramp(h, w);
        let img = Image::new("sources", &data, h, w, 3).unwrap();
        let target = l_shape();
        let shifted: Vec<Point> = target.iter().map(|v| [v[0] + 1.5, v[1] + 0.5]).collect();
        let region: Vec<bool> = (0..h * w).map(|i| (i % w + 2 * (i / w)) % 7 < 3).collect();
        let full = &warp(&[img], &[&shifted], &target, h, w, None).unwrap()[0];
        let part = &warp(&[img], &[&shifted], &target, h, w, Some(&region)).unwrap()[0];
        let comb = warp_combine(&[img], &[&shifted], &target, &[1.0], h, w, Some(&region)).unwrap();
        for (i, &inside) in region.iter().enumerate() {
            let (f, p, c) = (
                &full[i * 3..i * 3 + 3],
                &part[i * 3..i * 3 + 3],
                &comb[i * 3..i * 3 + 3],
            );
            if inside {
                assert_eq!(f, p);
                assert_eq!(&f[..2], &c[..2]);
            } else {
                assert!(p.iter().chain(c).all(|&v| v == 0.0));
            }
        }
        let short = vec![true; 5];
        assert!(warp(&[img], &[&shifted], &target, h, w, Some(&short)).is_err());
    }
}
