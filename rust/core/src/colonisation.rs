//! Space colonisation in branching growth (Sibbing et al. 2010, §4.4): the density map
//! `D(p) = exp(−d(p, B)² / ρ²)` of the structure grown so far, updated locally as segments
//! become final, and the largest density (or guidance) along candidate rays.
//!
//! The growth itself is a Markov chain, one extension at a time, so these are small calls
//! made once per step; only a stamp's window is split between threads (by rows, so the
//! result does not depend on their number).

use rayon::prelude::*;

use crate::error::{invalid, Result};

/// Segments stamped per window: a window is the segments' bounding box grown by `3ρ` plus
/// the thickness, so stamping a long branch in pieces keeps the work near linear in its length.
const CHUNK: usize = 8;
/// Pixels of a row handled together by [`Window::row`].
const BLOCK: usize = 64;
/// Windows of at least this many pixels are stamped in parallel, rows split between threads.
const PARALLEL_PIXELS: usize = 4096;

/// The density map and, per pixel, which branch vertex its density comes from (`-1`: none).
pub struct DensityMap<'a> {
    pub density: &'a mut [f32],
    pub owner_branch: &'a mut [i32],
    pub owner_vertex: &'a mut [i32],
    pub height: usize,
    pub width: usize,
}

/// A read-only [`DensityMap`], for the ray look-ups.
#[derive(Clone, Copy)]
pub struct DensityView<'a> {
    pub density: &'a [f32],
    pub owner_branch: &'a [i32],
    pub owner_vertex: &'a [i32],
    pub height: usize,
    pub width: usize,
}

/// Pixels whose density comes from branch `branch` within `near` vertices of `vertex` read only
/// their excess over `floor`, `max(D − floor, 0)`: a child starts on its parent, where every
/// direction would see `D = 1`, and `floor`, the parent's density at the child's tip, lets the
/// child still see a turn back towards the parent.
#[derive(Clone, Copy, Debug)]
pub struct Skip {
    pub branch: i32,
    pub vertex: i32,
    pub near: i32,
    pub floor: f64,
}

/// `samples` points at `length · k / samples`, `k = 1 ..= samples`, along each unit direction
/// from `tip`.
#[derive(Clone, Copy)]
pub struct Rays<'a> {
    pub tip: [f64; 2],
    pub directions: &'a [[f64; 2]],
    pub length: f64,
    pub samples: usize,
}

impl DensityMap<'_> {
    fn view(&self) -> DensityView<'_> {
        DensityView {
            density: self.density,
            owner_branch: self.owner_branch,
            owner_vertex: self.owner_vertex,
            height: self.height,
            width: self.width,
        }
    }
}

impl DensityView<'_> {
    /// The map and its owners hold `height × width` pixels each.
    fn check(&self) -> Result<()> {
        let (h, w) = (self.height, self.width);
        let lens = [
            self.density.len(),
            self.owner_branch.len(),
            self.owner_vertex.len(),
        ];
        if lens.iter().any(|&n| n != h * w) {
            return Err(invalid(
                "density",
                format!(
                    "expected the map and its owners to hold {h}×{w} pixels each, got {lens:?}"
                ),
            ));
        }
        Ok(())
    }
}

/// Writes the polyline `points` (vertices `first, first + 1, …` of branch `branch`, with their
/// `thickness`) into the map where `d(p, B) ≤ 3ρ`, and returns how much the map's sum grew.
///
/// `d(p, B)` is the distance from the pixel centre to the branch's surface: the least, over
/// the segments, of the distance to the segment's nearest point minus the thickness
/// interpolated there (zero inside the branch; ties: the earlier segment). A pixel keeps the
/// larger of its density and the new one, and where the new one is larger it takes the branch
/// vertex nearest to that segment point as its owner.
pub fn stamp(
    map: &mut DensityMap<'_>,
    points: &[[f64; 2]],
    thickness: &[f64],
    branch: i32,
    first: i32,
    rho: f64,
) -> Result<f64> {
    map.view().check()?;
    if thickness.len() != points.len() {
        return Err(invalid(
            "thickness",
            format!(
                "expected one value per point ({}), got {}",
                points.len(),
                thickness.len()
            ),
        ));
    }
    if !(rho.is_finite() && rho > 0.0) {
        return Err(invalid(
            "rho",
            format!("expected a positive radius, got {rho}"),
        ));
    }
    if points
        .iter()
        .flatten()
        .chain(thickness)
        .any(|v| !v.is_finite())
    {
        return Err(invalid("points", "expected finite points and thicknesses"));
    }
    let mut added = 0.0;
    let segments = points.len().saturating_sub(1);
    let mut start = 0;
    while start < segments {
        let end = (start + CHUNK).min(segments);
        let offset = i32::try_from(start).unwrap_or(i32::MAX);
        added += stamp_window(
            map,
            &points[start..=end],
            &thickness[start..=end],
            branch,
            first.saturating_add(offset),
            rho,
        );
        start = end;
    }
    Ok(added)
}

fn stamp_window(
    map: &mut DensityMap<'_>,
    points: &[[f64; 2]],
    thickness: &[f64],
    branch: i32,
    first: i32,
    rho: f64,
) -> f64 {
    let reach = 3.0 * rho + thickness.iter().copied().fold(0.0, f64::max);
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in points {
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let clamp = |v: f64, n: usize| v.clamp(0.0, n as f64) as usize;
    let (x0, x1) = (
        clamp((lo[0] - reach).floor(), map.width),
        clamp((hi[0] + reach).ceil() + 1.0, map.width),
    );
    let (y0, y1) = (
        clamp((lo[1] - reach).floor(), map.height),
        clamp((hi[1] + reach).ceil() + 1.0, map.height),
    );
    let segs: Vec<([f64; 2], [f64; 2], f64)> = points
        .windows(2)
        .map(|s| {
            let d = [s[1][0] - s[0][0], s[1][1] - s[0][1]];
            (s[0], d, 1.0 / (d[0] * d[0] + d[1] * d[1]).max(1e-12))
        })
        .collect();
    let w = map.width;
    let window = Window {
        points,
        thickness,
        segs: &segs,
        reach,
        rho,
        branch,
        first,
        x0,
        x1,
    };
    let rows = |(k, ((d, b), v)): RowOf<'_>| window.row(y0 + k, d, b, v);
    let dens = &mut map.density[y0 * w..y1 * w];
    let owners = (
        &mut map.owner_branch[y0 * w..y1 * w],
        &mut map.owner_vertex[y0 * w..y1 * w],
    );
    // rows are independent; their sums are added in row order, whatever the thread count
    let sums: Vec<f64> = if (y1 - y0) * (x1 - x0) >= PARALLEL_PIXELS {
        dens.par_chunks_mut(w)
            .zip(owners.0.par_chunks_mut(w))
            .zip(owners.1.par_chunks_mut(w))
            .enumerate()
            .map(rows)
            .collect()
    } else {
        dens.chunks_mut(w)
            .zip(owners.0.chunks_mut(w))
            .zip(owners.1.chunks_mut(w))
            .enumerate()
            .map(rows)
            .collect()
    };
    sums.iter().sum()
}

/// Row `k` of a window: its density, owner-branch and owner-vertex pixels.
type RowOf<'r> = (usize, ((&'r mut [f32], &'r mut [i32]), &'r mut [i32]));

/// What one stamp writes: its polyline, reach and owner.
struct Window<'a> {
    points: &'a [[f64; 2]],
    thickness: &'a [f64],
    /// per segment: start, direction, 1 / squared length
    segs: &'a [([f64; 2], [f64; 2], f64)],
    reach: f64,
    rho: f64,
    branch: i32,
    first: i32,
    x0: usize,
    x1: usize,
}

impl Window<'_> {
    /// Stamps row `y` (`dens`, `branch` and `vertex` are that row of the maps); returns how
    /// much its sum grew.
    fn row(&self, y: usize, dens: &mut [f32], branch: &mut [i32], vertex: &mut [i32]) -> f64 {
        let yf = y as f64;
        let reach = self.reach;
        // the row's pixels within `reach` of a segment's bounding box, the only ones that can
        // be within 3ρ of the segment's surface
        let (mut rx0, mut rx1) = (f64::INFINITY, f64::NEG_INFINITY);
        for w in self.points.windows(2) {
            let dy = (w[0][1].min(w[1][1]) - yf)
                .max(yf - w[0][1].max(w[1][1]))
                .max(0.0);
            if dy <= reach {
                let dx = (reach * reach - dy * dy).sqrt();
                rx0 = rx0.min(w[0][0].min(w[1][0]) - dx);
                rx1 = rx1.max(w[0][0].max(w[1][0]) + dx);
            }
        }
        if rx0 > rx1 {
            return 0.0;
        }
        let n = dens.len() as f64;
        let xa = (rx0.floor().clamp(0.0, n) as usize).max(self.x0);
        let xb = ((rx1.ceil() + 1.0).clamp(0.0, n) as usize).min(self.x1);
        let (inv, cutoff) = (1.0 / (self.rho * self.rho), 3.0 * self.rho);
        let th = self.thickness;
        let mut added = 0.0;
        // blocks of pixels: first the nearest segment point of each pixel, segment by segment
        // in a branch-free loop the compiler vectorises, then the density where it is nearer
        // single precision: window coordinates are exact in it, and distances within a few
        // ρ of a segment need no more than its 24 bits; four lanes per SSE2 instruction
        let (mut best, mut bj, mut bt) = ([0.0f32; BLOCK], [0i32; BLOCK], [0.0f32; BLOCK]);
        let mut xs = [0.0f32; BLOCK];
        let segs32: Vec<Seg32> = self
            .segs
            .iter()
            .zip(th.windows(2))
            .map(|(&(a, d, inv_dd), r)| {
                (
                    [a[0] as f32, a[1] as f32],
                    [d[0] as f32, d[1] as f32],
                    inv_dd as f32,
                    r[0] as f32,
                    (r[1] - r[0]) as f32,
                )
            })
            .collect();
        let (inv32, cutoff32) = (inv as f32, cutoff as f32);
        let mut x = xa;
        while x < xb {
            let n = (xb - x).min(BLOCK);
            for (k, v) in xs[..n].iter_mut().enumerate() {
                *v = (x + k) as f32;
            }
            nearest(
                &segs32,
                yf as f32,
                &xs[..n],
                &mut best[..n],
                &mut bj[..n],
                &mut bt[..n],
            );
            for k in 0..n {
                let gap = best[k].max(0.0);
                // beyond 3ρ the density is below e⁻⁹: the local update leaves it
                if gap > cutoff32 {
                    continue;
                }
                let new = (-(gap * gap) * inv32).exp();
                let i = x + k;
                if new > dens[i] {
                    added += f64::from(new - dens[i]);
                    dens[i] = new;
                    branch[i] = self.branch;
                    // bj < CHUNK and bt in [0, 1]
                    vertex[i] = self
                        .first
                        .saturating_add(bj[k] + bt[k].round_ties_even() as i32);
                }
            }
            x += n;
        }
        added
    }
}

/// A segment for [`nearest`]: start, direction, 1 / squared length, thickness at the start
/// and its change along the segment.
type Seg32 = ([f32; 2], [f32; 2], f32, f32, f32);

/// For each pixel `(xs[k], y)`: the least gap to the segments' surface, which segment gives
/// it and where on it. With AVX2 where the CPU has it: the same operations (no fused
/// multiply-add), so the same bits either way.
fn nearest(segs: &[Seg32], y: f32, xs: &[f32], best: &mut [f32], bj: &mut [i32], bt: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx2")]
        unsafe fn avx2(
            segs: &[Seg32],
            y: f32,
            xs: &[f32],
            best: &mut [f32],
            bj: &mut [i32],
            bt: &mut [f32],
        ) {
            nearest_portable(segs, y, xs, best, bj, bt);
        }
        if crate::distance::avx2_enabled() {
            // SAFETY: the CPU supports AVX2 (checked at run time just above)
            unsafe { avx2(segs, y, xs, best, bj, bt) };
            return;
        }
    }
    nearest_portable(segs, y, xs, best, bj, bt);
}

// inlined into the AVX2 wrapper, where it is compiled with AVX2
#[allow(clippy::inline_always)]
#[inline(always)]
fn nearest_portable(
    segs: &[Seg32],
    y: f32,
    xs: &[f32],
    best: &mut [f32],
    bj: &mut [i32],
    bt: &mut [f32],
) {
    let n = xs.len();
    let (best, bj, bt) = (&mut best[..n], &mut bj[..n], &mut bt[..n]);
    best.fill(f32::INFINITY);
    for (j, &(a, d, inv_dd, r0, dr)) in segs.iter().enumerate() {
        let py = y - a[1];
        let j = j as i32;
        for k in 0..n {
            let px = xs[k] - a[0];
            let t = ((px * d[0] + py * d[1]) * inv_dd).clamp(0.0, 1.0);
            let (ex, ey) = (px - t * d[0], py - t * d[1]);
            let gap = (ex * ex + ey * ey).sqrt() - (r0 + t * dr);
            let nearer = gap < best[k];
            best[k] = if nearer { gap } else { best[k] };
            bj[k] = if nearer { j } else { bj[k] };
            bt[k] = if nearer { t } else { bt[k] };
        }
    }
}

/// The pixel of a point (rounded half to even, as NumPy's `rint`), or None outside.
#[inline]
fn pixel(x: f64, y: f64, h: usize, w: usize) -> Option<usize> {
    let (ix, iy) = (x.round_ties_even(), y.round_ties_even());
    (ix >= 0.0 && iy >= 0.0 && ix < w as f64 && iy < h as f64)
        .then(|| iy as usize * w + ix as usize)
}

fn ray_max(rays: &Rays<'_>, value: impl Fn(f64, f64) -> f64) -> Vec<f64> {
    let n = rays.samples as f64;
    rays.directions
        .iter()
        .map(|d| {
            (1..=rays.samples).fold(f64::NEG_INFINITY, |m, k| {
                let s = rays.length * k as f64 / n;
                m.max(value(rays.tip[0] + d[0] * s, rays.tip[1] + d[1] * s))
            })
        })
        .collect()
}

/// Rays need a positive length, a sample, and finite points.
pub(crate) fn check_rays(rays: &Rays<'_>) -> Result<()> {
    if rays.samples == 0 || !(rays.length.is_finite() && rays.length > 0.0) {
        return Err(invalid(
            "rays",
            format!(
                "expected a positive length and at least one sample, got {} and {}",
                rays.length, rays.samples
            ),
        ));
    }
    if rays
        .tip
        .iter()
        .chain(rays.directions.iter().flatten())
        .any(|v| !v.is_finite())
    {
        return Err(invalid("rays", "expected a finite tip and directions"));
    }
    Ok(())
}

/// The largest density along each ray (outside the image: 0). With `border_rho`, the image
/// border counts as structure: a sample at pixel distance `d` from the first pixel outside
/// reads at least `exp(−d² / ρ²)`, and 1 outside.
pub fn density_ray_max(
    view: DensityView<'_>,
    rays: &Rays<'_>,
    skip: Option<Skip>,
    border_rho: Option<f64>,
) -> Result<Vec<f64>> {
    view.check()?;
    check_rays(rays)?;
    if skip.is_some_and(|s| !s.floor.is_finite()) {
        return Err(invalid("skip", "expected a finite floor"));
    }
    let (h, w) = (view.height, view.width);
    Ok(ray_max(rays, |x, y| {
        let inside = pixel(x, y, h, w).map_or(0.0, |i| match skip {
            Some(s)
                if view.owner_branch[i] == s.branch
                    && (i64::from(view.owner_vertex[i]) - i64::from(s.vertex)).abs()
                        <= i64::from(s.near) =>
            {
                (f64::from(view.density[i]) - s.floor).max(0.0)
            }
            _ => f64::from(view.density[i]),
        });
        match border_rho {
            None => inside,
            Some(rho) => {
                let (ix, iy) = (x.round_ties_even(), y.round_ties_even());
                let d = (ix + 1.0)
                    .min(w as f64 - ix)
                    .min((iy + 1.0).min(h as f64 - iy));
                let d = d.max(0.0);
                inside.max((-(d * d) / (rho * rho)).exp())
            }
        }
    }))
}

/// The largest value of `field` (`h × w`) along each ray (outside the image: 0).
pub fn field_ray_max(field: &[f64], h: usize, w: usize, rays: &Rays<'_>) -> Result<Vec<f64>> {
    if field.len() != h * w {
        return Err(invalid(
            "field",
            format!("expected {h}×{w} values, got {}", field.len()),
        ));
    }
    check_rays(rays)?;
    Ok(ray_max(rays, |x, y| {
        pixel(x, y, h, w).map_or(0.0, |i| field[i])
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Owned {
        density: Vec<f32>,
        branch: Vec<i32>,
        vertex: Vec<i32>,
        h: usize,
        w: usize,
    }

    impl Owned {
        fn new(h: usize, w: usize) -> Self {
            Self {
                density: vec![0.0; h * w],
                branch: vec![-1; h * w],
                vertex: vec![-1; h * w],
                h,
                w,
            }
        }
        fn map(&mut self) -> DensityMap<'_> {
            DensityMap {
                density: &mut self.density,
                owner_branch: &mut self.branch,
                owner_vertex: &mut self.vertex,
                height: self.h,
                width: self.w,
            }
        }
        fn view(&self) -> DensityView<'_> {
            DensityView {
                density: &self.density,
                owner_branch: &self.branch,
                owner_vertex: &self.vertex,
                height: self.h,
                width: self.w,
            }
        }
    }

    /// The distance from `p` to the polyline's surface, by brute force over fine samples.
    fn brute_gap(p: [f64; 2], pts: &[[f64; 2]], th: &[f64]) -> f64 {
        let mut best = f64::INFINITY;
        for j in 0..pts.len() - 1 {
            for k in 0..=2000 {
                let t = f64::from(k) / 2000.0;
                let q = [
                    pts[j][0] + t * (pts[j + 1][0] - pts[j][0]),
                    pts[j][1] + t * (pts[j + 1][1] - pts[j][1]),
                ];
                let r = th[j] + t * (th[j + 1] - th[j]);
                let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt();
                best = best.min((d - r).max(0.0));
            }
        }
        best
    }

    #[test]
    #[allow(clippy::float_cmp)] // a pixel on the branch has density exactly 1
    fn stamp_matches_the_distance_to_the_polyline() {
        let mut o = Owned::new(40, 50);
        // 20 vertices: three windows, constant thickness (the projection is then exact)
        let pts: Vec<[f64; 2]> = (0..20)
            .map(|i| {
                [
                    5.0 + 2.0 * f64::from(i),
                    20.0 + 6.0 * (f64::from(i) / 3.0).sin(),
                ]
            })
            .collect();
        let th = vec![1.5; 20];
        let rho = 3.0;
        let added = stamp(&mut o.map(), &pts, &th, 4, 10, rho).unwrap();
        let mut sum = 0.0;
        for y in 0..40 {
            for x in 0..50 {
                let g = brute_gap([x as f64, y as f64], &pts, &th);
                let want = (-(g * g) / (rho * rho)).exp();
                let got = f64::from(o.density[y * 50 + x]);
                sum += got;
                if g < 3.0 * rho - 1e-3 {
                    assert!((got - want).abs() < 2e-3, "({x}, {y}): {got} vs {want}");
                    assert_eq!(o.branch[y * 50 + x], 4);
                    assert!((10..30).contains(&o.vertex[y * 50 + x]));
                } else if g > 3.0 * rho + 1e-3 {
                    assert_eq!(o.branch[y * 50 + x], -1, "({x}, {y}) is beyond 3ρ");
                }
            }
        }
        assert!((added - sum).abs() < 1e-3 * sum);
        // the pixel on vertex 7 belongs to it
        let p = pts[7];
        let i = p[1].round() as usize * 50 + p[0].round() as usize;
        assert!((15..=18).contains(&o.vertex[i]), "{}", o.vertex[i]);
        assert_eq!(o.density[i], 1.0);
    }

    #[test]
    fn avx2_and_portable_stamps_agree_to_the_bit() {
        use std::sync::atomic::Ordering;
        let pts: Vec<[f64; 2]> = (0..30)
            .map(|i| {
                [
                    3.0 + 2.3 * f64::from(i),
                    40.0 + 15.0 * (f64::from(i) / 4.0).cos(),
                ]
            })
            .collect();
        let th: Vec<f64> = (0..30).map(|i| 1.0 + f64::from(i % 7) / 3.0).collect();
        let run = |portable: bool| {
            crate::distance::FORCE_PORTABLE.store(portable, Ordering::Relaxed);
            let mut o = Owned::new(80, 90);
            let added = stamp(&mut o.map(), &pts, &th, 2, 0, 4.5).unwrap();
            crate::distance::FORCE_PORTABLE.store(false, Ordering::Relaxed);
            (
                added.to_bits(),
                o.density.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                o.vertex,
            )
        };
        assert_eq!(run(true), run(false));
    }

    #[test]
    #[allow(clippy::float_cmp)] // an identical stamp raises nothing, exactly
    fn stamp_keeps_the_larger_density_and_its_owner() {
        let mut o = Owned::new(30, 30);
        stamp(
            &mut o.map(),
            &[[5.0, 15.0], [25.0, 15.0]],
            &[0.0, 0.0],
            0,
            0,
            2.0,
        )
        .unwrap();
        let before = o.density.clone();
        let added = stamp(
            &mut o.map(),
            &[[5.0, 18.0], [25.0, 18.0]],
            &[0.0, 0.0],
            1,
            0,
            2.0,
        )
        .unwrap();
        assert!(added > 0.0);
        assert!(o.density.iter().zip(&before).all(|(a, b)| a >= b));
        assert_eq!(o.branch[15 * 30 + 15], 0);
        assert_eq!(o.branch[18 * 30 + 15], 1);
        assert_eq!(o.branch[16 * 30 + 15], 0, "nearer the first line");
        // a second identical stamp changes nothing
        assert_eq!(
            stamp(
                &mut o.map(),
                &[[5.0, 18.0], [25.0, 18.0]],
                &[0.0, 0.0],
                2,
                0,
                2.0
            )
            .unwrap(),
            0.0
        );
    }

    #[test]
    #[allow(clippy::float_cmp)] // nothing to write adds exactly zero
    fn stamp_rejects_bad_input() {
        let mut o = Owned::new(10, 10);
        let line = [[0.0, 0.0], [1.0, 1.0]];
        let mut run =
            |pts: &[[f64; 2]], th: &[f64], rho: f64| stamp(&mut o.map(), pts, th, 0, 0, rho);
        assert!(run(&line, &[0.0], 1.0).is_err());
        assert!(run(&line, &[0.0; 2], 0.0).is_err());
        assert!(run(&[[0.0, f64::NAN], [1.0, 1.0]], &[0.0; 2], 1.0).is_err());
        // one point or points far outside: nothing to write
        assert_eq!(run(&[[3.0, 3.0]], &[0.0], 1.0).unwrap(), 0.0);
        assert_eq!(
            run(&[[-90.0, 3.0], [-80.0, 3.0]], &[0.0; 2], 1.0).unwrap(),
            0.0
        );
        let mut short = Owned::new(10, 10);
        short.branch.pop();
        assert!(stamp(&mut short.map(), &line, &[0.0; 2], 0, 0, 1.0).is_err());
    }

    #[test]
    fn rays_read_the_largest_value_and_skip_the_parent() {
        let mut o = Owned::new(20, 20);
        o.density[10 * 20 + 15] = 0.75; // (x 15, y 10)
        o.branch[10 * 20 + 15] = 3;
        o.vertex[10 * 20 + 15] = 8;
        o.density[5 * 20 + 10] = 0.5; // (x 10, y 5)
        let dirs = [[1.0, 0.0], [0.0, -1.0], [-1.0, 0.0]];
        let rays = Rays {
            tip: [10.0, 10.0],
            directions: &dirs,
            length: 6.0,
            samples: 6,
        };
        let read = |skip: Option<(i32, i32, f64)>| {
            let skip = skip.map(|(branch, vertex, floor)| Skip {
                branch,
                vertex,
                near: 2,
                floor,
            });
            density_ray_max(o.view(), &rays, skip, None).unwrap()
        };
        assert_eq!(read(None), vec![0.75, 0.5, 0.0]);
        // the parent's pixel at vertex 8 is within 2 of vertex 6, not of vertex 5
        assert_eq!(read(Some((3, 6, 1.0))), vec![0.0, 0.5, 0.0]);
        assert_eq!(read(Some((3, 5, 1.0))), vec![0.75, 0.5, 0.0]);
        assert_eq!(read(Some((2, 8, 1.0))), vec![0.75, 0.5, 0.0]);
        // below the floor (the parent's density at the tip) nothing; above it, the excess
        assert_eq!(read(Some((3, 6, 0.5))), vec![0.25, 0.5, 0.0]);
        assert_eq!(read(Some((3, 6, 0.8))), vec![0.0, 0.5, 0.0]);
        assert!(density_ray_max(
            o.view(),
            &rays,
            Some(Skip {
                branch: 3,
                vertex: 6,
                near: 2,
                floor: f64::NAN
            }),
            None
        )
        .is_err());
        // the border: the left ray ends at x = 4, five pixels from x = -1
        let b = density_ray_max(o.view(), &rays, None, Some(2.0)).unwrap();
        assert!((b[2] - (-25.0f64 / 4.0).exp()).abs() < 1e-15);
        let out = Rays {
            tip: [1.0, 1.0],
            directions: &dirs[2..],
            length: 3.0,
            samples: 3,
        };
        assert_eq!(
            density_ray_max(o.view(), &out, None, Some(2.0)).unwrap(),
            vec![1.0]
        );
        let field: Vec<f64> = (0..400).map(f64::from).collect();
        assert_eq!(
            field_ray_max(&field, 20, 20, &rays).unwrap(),
            vec![216.0, 190.0, 209.0]
        );
        let bad = Rays {
            tip: [1.0, 1.0],
            directions: &dirs,
            length: 0.0,
            samples: 3,
        };
        assert!(density_ray_max(o.view(), &bad, None, None).is_err());
        assert!(field_ray_max(&field[1..], 20, 20, &rays).is_err());
    }
}
