//! Graph-cut seams between two overlapping images.
//!
//! Given two images `a` and `b` in one frame and the region where both exist, every region
//! pixel is labelled "take a" or "take b" so that the colour mismatch along the seam is as
//! small as possible (Kwatra, Schödl, Essa, Turk, Bobick 2003, *Graphcut textures*). Region
//! pixels that border a part of the frame covered by only one image are tied to that image,
//! so the composite has no hole and no jump at the region border. The minimum cut is exact
//! ([`crate::maxflow`]); capacities are computed in parallel.
//!
//! Costs of cutting between neighbours `s` and `t` (`‖·‖` is the Euclidean norm over
//! channels):
//! - [`SeamCost::Kwatra`]: `‖a(s) − b(s)‖ + ‖a(t) − b(t)‖` (Kwatra 2003 Eq. 1; the colour
//!   difference of Sibbing et al. 2010 §5.3);
//! - [`SeamCost::Gradient`]: that cost divided by `‖G_a^d(s)‖ + ‖G_a^d(t)‖ + ‖G_b^d(s)‖ +
//!   ‖G_b^d(t)‖`, the image gradients along the edge direction `d` (Kwatra 2003 Eq. 2), so
//!   seams prefer edges, where they are hard to see;
//! - [`SeamCost::Luo`]: `min(d(s), d(t)) / G(s, t)` with `d(x) = ‖a(x) − b(x)‖⁴` and `G(s, t)
//!   = δ_a(s) + δ_b(s) + δ_a(t) + δ_b(t)`, δ the gradient magnitude (Luo et al., *Stroke-based
//!   editing of object structure*, Eq. 2). Colours are scaled to 0–255 for this cost so that
//!   its border data term of 10000 (their Eq. 1) keeps its published weight.

use rayon::prelude::*;

use crate::error::{invalid, Result};
use crate::image::Image;
use crate::maxflow::{EdgeLayout, GridGraph, DIRS, SYMMETRIC_DIRS};

/// The seam cost functions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SeamCost {
    /// Kwatra et al. 2003 colour difference.
    Kwatra,
    /// Kwatra et al. 2003 gradient-normalised colour difference.
    Gradient,
    /// Luo et al. `min(d(x), d(y)) / G(x, y)`, `d` the fourth power of the colour difference.
    Luo,
}

impl SeamCost {
    /// The border data term of the cost: a hard constraint for Kwatra's costs, 10000 for
    /// Luo's (their Eq. 1).
    #[must_use]
    pub fn default_border_weight(self) -> f32 {
        match self {
            SeamCost::Kwatra | SeamCost::Gradient => f32::INFINITY,
            SeamCost::Luo => 10_000.0,
        }
    }
}

/// Denominator floor of the gradient-normalised costs (in the images' units, and in 0–255
/// units for [`SeamCost::Luo`]), so flat regions get a large but finite cost.
pub const GRADIENT_EPS: f32 = 1e-6;

/// What to cut.
#[derive(Clone, Copy, Debug)]
pub struct SeamInput<'a> {
    /// First image (label "a", the source side of the cut).
    pub a: Image<'a>,
    /// Second image, same shape.
    pub b: Image<'a>,
    /// `h × w`: the overlap, where the labels are chosen.
    pub region: &'a [bool],
    /// `h × w`: where `a` exists (default: the region).
    pub a_mask: Option<&'a [bool]>,
    /// `h × w`: where `b` exists (default: the region).
    pub b_mask: Option<&'a [bool]>,
    /// `h × w`: 0 free, 1 must take `a`, 2 must take `b` (region pixels only).
    pub seeds: Option<&'a [u8]>,
    /// Cost function (ignored when `edges` is given).
    pub cost: SeamCost,
    /// Precomputed symmetric edge costs, `h × w × k/2` in the [`EdgeLayout::Symmetric`]
    /// order; only edges with both ends in the region are used.
    pub edges: Option<&'a [f32]>,
    /// Weight tying a region pixel to the image it borders (`+∞`: hard).
    pub border_weight: f32,
    /// 4 or 8.
    pub connectivity: usize,
}

impl<'a> SeamInput<'a> {
    /// A seam between `a` and `b` over `region` with the Kwatra cost and no border ties.
    #[must_use]
    pub fn new(a: Image<'a>, b: Image<'a>, region: &'a [bool]) -> Self {
        Self {
            a,
            b,
            region,
            a_mask: None,
            b_mask: None,
            seeds: None,
            cost: SeamCost::Kwatra,
            edges: None,
            border_weight: f32::INFINITY,
            connectivity: 4,
        }
    }
}

/// Output of [`seam`].
#[derive(Clone, Debug)]
pub struct Seam {
    /// `h × w`: `true` where the composite takes `b` (outside the region: where only `b`
    /// exists).
    pub take_b: Vec<bool>,
    /// The energy of the cut: seam costs plus violated border terms.
    pub energy: f64,
    /// Number of region pixels tied to `a` and to `b` by the border rule or seeds.
    pub tied: (usize, usize),
}

struct Bbox {
    y0: usize,
    x0: usize,
    h: usize,
    w: usize,
}

fn check_mask(name: &'static str, m: Option<&[bool]>, n: usize) -> Result<()> {
    match m {
        Some(m) if m.len() != n => Err(invalid(
            name,
            format!(
                "expected {n} mask values (the images' height × width), got {}",
                m.len()
            ),
        )),
        _ => Ok(()),
    }
}

fn validate(inp: &SeamInput<'_>) -> Result<Bbox> {
    let (a, b) = (&inp.a, &inp.b);
    if (a.h, a.w, a.c) != (b.h, b.w, b.c) {
        return Err(invalid(
            "b",
            format!(
                "expected the shape of a ({}, {}, {}), got ({}, {}, {})",
                a.h, a.w, a.c, b.h, b.w, b.c
            ),
        ));
    }
    if inp.connectivity != 4 && inp.connectivity != 8 {
        return Err(invalid(
            "connectivity",
            format!("expected 4 or 8, got {}", inp.connectivity),
        ));
    }
    let n = a.h * a.w;
    check_mask("region", Some(inp.region), n)?;
    check_mask("a_mask", inp.a_mask, n)?;
    check_mask("b_mask", inp.b_mask, n)?;
    if inp.border_weight.is_nan() || inp.border_weight < 0.0 {
        return Err(invalid(
            "border_weight",
            format!(
                "expected a non-negative weight or +inf, got {}",
                inp.border_weight
            ),
        ));
    }
    if let Some(s) = inp.seeds {
        if s.len() != n {
            return Err(invalid(
                "seeds",
                format!("expected {n} values, got {}", s.len()),
            ));
        }
        if let Some(i) = s.iter().position(|&v| v > 2) {
            return Err(invalid(
                "seeds",
                format!(
                    "expected 0 (free), 1 (a) or 2 (b), got {} at ({}, {})",
                    s[i],
                    i / a.w,
                    i % a.w
                ),
            ));
        }
        if let Some(i) = (0..n).find(|&i| s[i] != 0 && !inp.region[i]) {
            return Err(invalid(
                "seeds",
                format!("seed at ({}, {}) is outside the region", i / a.w, i % a.w),
            ));
        }
    }
    for (name, m) in [("a_mask", inp.a_mask), ("b_mask", inp.b_mask)] {
        if let Some(m) = m {
            if let Some(i) = (0..n).find(|&i| inp.region[i] && !m[i]) {
                return Err(invalid(
                    name,
                    format!(
                        "must cover the region, but region pixel ({}, {}) is outside it",
                        i / a.w,
                        i % a.w
                    ),
                ));
            }
        }
    }
    if let Some(e) = inp.edges {
        let m = inp.connectivity / 2;
        if e.len() != n * m {
            return Err(invalid(
                "cost",
                format!(
                    "expected {}×{}×{m} edge costs, got {} values",
                    a.h,
                    a.w,
                    e.len()
                ),
            ));
        }
        if let Some(i) = e.iter().position(|v| !v.is_finite() || *v < 0.0) {
            return Err(invalid(
                "cost",
                format!(
                    "edge costs must be finite and non-negative; value {i} is {}",
                    e[i]
                ),
            ));
        }
    } else {
        a.check_finite("a")?;
        b.check_finite("b")?;
    }
    let (mut y0, mut y1, mut x0, mut x1) = (usize::MAX, 0, usize::MAX, 0);
    for y in 0..a.h {
        let row = &inp.region[y * a.w..(y + 1) * a.w];
        if let (Some(first), Some(last)) =
            (row.iter().position(|&v| v), row.iter().rposition(|&v| v))
        {
            y0 = y0.min(y);
            y1 = y;
            x0 = x0.min(first);
            x1 = x1.max(last);
        }
    }
    if y0 == usize::MAX {
        return Err(invalid(
            "region",
            "is empty: expected at least one overlap pixel",
        ));
    }
    Ok(Bbox {
        y0,
        x0,
        h: y1 - y0 + 1,
        w: x1 - x0 + 1,
    })
}

/// Colour distance `‖a(y, x) − b(y, x)‖`.
#[inline]
fn diff(a: &Image<'_>, b: &Image<'_>, y: usize, x: usize) -> f32 {
    a.pixel(y, x)
        .iter()
        .zip(b.pixel(y, x))
        .map(|(p, q)| (p - q) * (p - q))
        .sum::<f32>()
        .sqrt()
}

/// `‖I(y + dy, x + dx) − I(y − dy, x − dx)‖ / 2`, one-sided at the image border.
#[inline]
fn grad_along(img: &Image<'_>, y: usize, x: usize, d: (isize, isize)) -> f32 {
    let clamp = |v: isize, n: usize| v.clamp(0, n as isize - 1) as usize;
    let (yp, xp) = (
        clamp(y as isize + d.0, img.h),
        clamp(x as isize + d.1, img.w),
    );
    let (ym, xm) = (
        clamp(y as isize - d.0, img.h),
        clamp(x as isize - d.1, img.w),
    );
    let span = (yp.abs_diff(ym)).max(xp.abs_diff(xm)).max(1) as f32;
    img.pixel(yp, xp)
        .iter()
        .zip(img.pixel(ym, xm))
        .map(|(p, q)| (p - q) * (p - q))
        .sum::<f32>()
        .sqrt()
        / span
}

/// Gradient magnitude `sqrt(‖∂I/∂x‖² + ‖∂I/∂y‖²)` by central differences.
#[inline]
fn grad_mag(img: &Image<'_>, y: usize, x: usize) -> f32 {
    let gx = grad_along(img, y, x, (0, 1));
    let gy = grad_along(img, y, x, (1, 0));
    (gx * gx + gy * gy).sqrt()
}

/// Symmetric edge costs over the bounding box (`bh × bw × k/2`), zero unless both ends are
/// in the region: the user's costs if given, else the chosen cost function.
fn edge_costs(inp: &SeamInput<'_>, bb: &Bbox) -> Vec<f32> {
    let (a, b) = (&inp.a, &inp.b);
    let w = a.w;
    let m = inp.connectivity / 2;
    let dirs = &SYMMETRIC_DIRS[..m];
    let luo = inp.cost == SeamCost::Luo && inp.edges.is_none();
    // Per-pixel terms over the box plus a one-pixel ring (neighbours of box pixels).
    let (py0, px0) = (bb.y0.saturating_sub(1), bb.x0.saturating_sub(1));
    let (py1, px1) = ((bb.y0 + bb.h + 1).min(a.h), (bb.x0 + bb.w + 1).min(w));
    let pw = px1 - px0;
    let per_pixel = |f: &(dyn Fn(usize, usize) -> f32 + Sync)| -> Vec<f32> {
        let mut out = vec![0f32; (py1 - py0) * pw];
        out.par_chunks_mut(pw).enumerate().for_each(|(r, row)| {
            for (c, v) in row.iter_mut().enumerate() {
                *v = f(py0 + r, px0 + c);
            }
        });
        out
    };
    let dist = if inp.edges.is_some() {
        Vec::new()
    } else {
        per_pixel(&|y, x| {
            let d = diff(a, b, y, x);
            if luo {
                (255.0 * d).powi(4)
            } else {
                d
            }
        })
    };
    let delta = if luo {
        per_pixel(&|y, x| 255.0 * (grad_mag(a, y, x) + grad_mag(b, y, x)))
    } else {
        Vec::new()
    };
    let at = |v: &[f32], y: usize, x: usize| v[(y - py0) * pw + x - px0];

    let mut out = vec![0f32; bb.h * bb.w * m];
    out.par_chunks_mut(bb.w * m)
        .enumerate()
        .for_each(|(r, row)| {
            let y = bb.y0 + r;
            for c in 0..bb.w {
                let x = bb.x0 + c;
                if !inp.region[y * w + x] {
                    continue;
                }
                for (s, &d) in dirs.iter().enumerate() {
                    let (ny, nx) = (y as isize + DIRS[d].0, x as isize + DIRS[d].1);
                    if ny < 0 || nx < 0 || ny as usize >= a.h || nx as usize >= w {
                        continue;
                    }
                    let (ny, nx) = (ny as usize, nx as usize);
                    if !inp.region[ny * w + nx] {
                        continue;
                    }
                    if let Some(e) = inp.edges {
                        row[c * m + s] = e[(y * w + x) * m + s];
                        continue;
                    }
                    let (ds, dt) = (at(&dist, y, x), at(&dist, ny, nx));
                    row[c * m + s] = match inp.cost {
                        SeamCost::Kwatra => ds + dt,
                        SeamCost::Gradient => {
                            let g = grad_along(a, y, x, DIRS[d])
                                + grad_along(a, ny, nx, DIRS[d])
                                + grad_along(b, y, x, DIRS[d])
                                + grad_along(b, ny, nx, DIRS[d]);
                            (ds + dt) / (g + GRADIENT_EPS)
                        }
                        SeamCost::Luo => {
                            ds.min(dt) / (at(&delta, y, x) + at(&delta, ny, nx) + GRADIENT_EPS)
                        }
                    };
                    // An overflow to +inf would make the edge uncuttable; keep it finite.
                    row[c * m + s] = row[c * m + s].min(f32::MAX);
                }
            }
        });
    out
}

/// Finds the minimum-cost seam between `a` and `b` over the region.
pub fn seam(inp: &SeamInput<'_>) -> Result<Seam> {
    let bb = validate(inp)?;
    let (h, w) = (inp.a.h, inp.a.w);
    let edges = edge_costs(inp, &bb);
    let mut g = GridGraph::new(bb.h, bb.w, inp.connectivity)?;
    g.set_edges("cost", &edges, EdgeLayout::Symmetric)?;

    let only = |m: Option<&[bool]>, other: Option<&[bool]>, i: usize| {
        m.is_some_and(|m| m[i]) && !other.is_some_and(|o| o[i]) && !inp.region[i]
    };
    let mut source = vec![0f32; bb.h * bb.w];
    let mut sink = vec![0f32; bb.h * bb.w];
    let mut tied = (0, 0);
    for r in 0..bb.h {
        for c in 0..bb.w {
            let (y, x) = (bb.y0 + r, bb.x0 + c);
            let i = y * w + x;
            if !inp.region[i] {
                continue;
            }
            let (mut by_a, mut by_b) = (false, false);
            for &(dy, dx) in &DIRS[..4] {
                let (ny, nx) = (y as isize + dy, x as isize + dx);
                if ny < 0 || nx < 0 || ny as usize >= h || nx as usize >= w {
                    continue;
                }
                let j = ny as usize * w + nx as usize;
                by_a |= only(inp.a_mask, inp.b_mask, j);
                by_b |= only(inp.b_mask, inp.a_mask, j);
            }
            let seed = inp.seeds.map_or(0, |s| s[i]);
            let o = r * bb.w + c;
            if seed == 1 {
                source[o] = f32::INFINITY;
            } else if seed == 2 {
                sink[o] = f32::INFINITY;
            } else if by_a && !by_b {
                source[o] = inp.border_weight;
            } else if by_b && !by_a {
                sink[o] = inp.border_weight;
            }
            tied.0 += usize::from(source[o] > 0.0);
            tied.1 += usize::from(sink[o] > 0.0);
        }
    }
    g.set_terminals(&source, &sink)?;
    let energy = g.maxflow();
    crate::cancel::check()?;
    let Some(side) = g.sink_side() else {
        return Err(crate::Error::Internal("max-flow left no cut".into()));
    };
    let mut take_b: Vec<bool> = (0..h * w)
        .map(|i| only(inp.b_mask, inp.a_mask, i))
        .collect();
    for r in 0..bb.h {
        for c in 0..bb.w {
            let i = (bb.y0 + r) * w + bb.x0 + c;
            if inp.region[i] {
                take_b[i] = side[r * bb.w + c];
            }
        }
    }
    Ok(Seam {
        take_b,
        energy,
        tied,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn noise(seed: u64, n: usize) -> Vec<f32> {
        let mut r = Rng::keyed(seed, 0, 0);
        (0..n).map(|_| r.below(1000) as f32 / 1000.0).collect()
    }

    /// Energy of a labelling under the cost, by direct summation.
    fn energy(inp: &SeamInput<'_>, take_b: &[bool], border: &[(usize, bool)]) -> f64 {
        let (h, w) = (inp.a.h, inp.a.w);
        let bb = Bbox { y0: 0, x0: 0, h, w };
        let e = edge_costs(inp, &bb);
        let mut v = 0.0;
        for y in 0..h {
            for x in 0..w {
                for (s, &d) in SYMMETRIC_DIRS[..inp.connectivity / 2].iter().enumerate() {
                    let (ny, nx) = (y as isize + DIRS[d].0, x as isize + DIRS[d].1);
                    if ny < 0 || nx < 0 || ny as usize >= h || nx as usize >= w {
                        continue;
                    }
                    if take_b[y * w + x] != take_b[ny as usize * w + nx as usize] {
                        v += f64::from(e[(y * w + x) * (inp.connectivity / 2) + s]);
                    }
                }
            }
        }
        for &(i, want_b) in border {
            if take_b[i] != want_b {
                v += f64::from(inp.border_weight);
            }
        }
        v
    }

    #[test]
    fn seam_is_the_brute_force_minimum_on_small_regions() {
        // A 3×5 frame: column 0 only a, column 4 only b, the 3×3 middle overlapping. Every
        // labelling of the 9 free pixels is tried.
        let (h, w, ch) = (3, 5, 2);
        for (case, cost) in [SeamCost::Kwatra, SeamCost::Gradient, SeamCost::Luo]
            .into_iter()
            .enumerate()
        {
            for conn in [4, 8] {
                let (da, db) = (
                    noise(case as u64, h * w * ch),
                    noise(100 + case as u64, h * w * ch),
                );
                let a = Image::new("a", &da, h, w, ch).unwrap();
                let b = Image::new("b", &db, h, w, ch).unwrap();
                let region: Vec<bool> = (0..h * w).map(|i| (1..4).contains(&(i % w))).collect();
                let am: Vec<bool> = (0..h * w).map(|i| i % w < 4).collect();
                let bm: Vec<bool> = (0..h * w).map(|i| i % w > 0).collect();
                let mut inp = SeamInput::new(a, b, &region);
                inp.a_mask = Some(&am);
                inp.b_mask = Some(&bm);
                inp.cost = cost;
                inp.connectivity = conn;
                inp.border_weight = 0.7; // soft, so the brute force can pay it
                let got = seam(&inp).unwrap();
                let border: Vec<(usize, bool)> = (0..h)
                    .flat_map(|y| [(y * w + 1, false), (y * w + 3, true)])
                    .collect();
                let free: Vec<usize> = (0..h * w).filter(|&i| region[i]).collect();
                let mut best = f64::INFINITY;
                for bits in 0u32..1 << free.len() {
                    let mut lab: Vec<bool> = (0..h * w).map(|i| i % w == 4).collect();
                    for (k, &i) in free.iter().enumerate() {
                        lab[i] = bits >> k & 1 == 1;
                    }
                    best = best.min(energy(&inp, &lab, &border));
                }
                assert!(
                    (got.energy - best).abs() <= 1e-5 * best.max(1e-3),
                    "{cost:?}/{conn}: {} vs {best}",
                    got.energy
                );
                let own = energy(&inp, &got.take_b, &border);
                assert!(
                    (own - best).abs() <= 1e-5 * best.max(1e-3),
                    "{cost:?}/{conn}: labels cost {own}, min {best}"
                );
                assert!(
                    got.take_b[4] && !got.take_b[0],
                    "outside the region the only image is taken"
                );
            }
        }
    }

    #[test]
    fn hard_border_ties_and_seeds_are_respected() {
        let (h, w) = (16, 24);
        let (da, db) = (noise(1, h * w), noise(2, h * w));
        let a = Image::new("a", &da, h, w, 1).unwrap();
        let b = Image::new("b", &db, h, w, 1).unwrap();
        let region: Vec<bool> = (0..h * w).map(|i| (4..20).contains(&(i % w))).collect();
        let am: Vec<bool> = (0..h * w).map(|i| i % w < 20).collect();
        let bm: Vec<bool> = (0..h * w).map(|i| i % w >= 4).collect();
        let mut seeds = vec![0u8; h * w];
        seeds[5 * w + 5] = 2; // next to the a-only side, yet must take b
        seeds[9 * w + 18] = 1;
        let mut inp = SeamInput::new(a, b, &region);
        inp.a_mask = Some(&am);
        inp.b_mask = Some(&bm);
        inp.seeds = Some(&seeds);
        let s = seam(&inp).unwrap();
        for y in 0..h {
            assert!(
                !s.take_b[y * w + 4] || y == 5,
                "row {y}: a-border pixel took b"
            );
            assert!(
                s.take_b[y * w + 19] || y == 9,
                "row {y}: b-border pixel took a"
            );
            assert!(!s.take_b[y * w] && s.take_b[y * w + 23]);
        }
        assert!(s.take_b[5 * w + 5] && !s.take_b[9 * w + 18]);
        assert_eq!(s.tied, (h + 1, h + 1));
    }

    #[test]
    fn identical_images_cost_nothing() {
        let (h, w) = (9, 9);
        let d = noise(3, h * w * 3);
        let a = Image::new("a", &d, h, w, 3).unwrap();
        let region = vec![true; h * w];
        let s = seam(&SeamInput::new(a, a, &region)).unwrap();
        assert!(s.energy.abs() < 1e-12);
    }

    #[test]
    fn bad_inputs_name_their_argument() {
        let d = noise(3, 16);
        let a = Image::new("a", &d, 4, 4, 1).unwrap();
        let b3 = Image::new("b", &d[..12], 4, 3, 1).unwrap();
        let region = vec![true; 16];
        let empty = vec![false; 16];
        let name = |r: Result<Seam>| match r {
            Err(crate::Error::InvalidArgument { name, .. }) => name,
            other => panic!("expected an error, got {other:?}"),
        };
        assert_eq!(name(seam(&SeamInput::new(a, b3, &region))), "b");
        assert_eq!(name(seam(&SeamInput::new(a, a, &empty))), "region");
        let mut inp = SeamInput::new(a, a, &region);
        let seeds = vec![3u8; 16];
        inp.seeds = Some(&seeds);
        assert_eq!(name(seam(&inp)), "seeds");
        let mut inp = SeamInput::new(a, a, &region);
        inp.a_mask = Some(&empty);
        assert_eq!(name(seam(&inp)), "a_mask");
        let nan = vec![f32::NAN; 16];
        let an = Image::new("a", &nan, 4, 4, 1).unwrap();
        assert_eq!(name(seam(&SeamInput::new(an, a, &region))), "a");
    }
}
