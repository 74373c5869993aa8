//! Fetching source texture: rigid, rotated copies of the source object around stroke samples.

use rayon::prelude::*;

use crate::error::invalid;
use crate::image::Image;
use crate::mvc::sample_any;
use crate::{cancel, Result};

/// Px added on each side to the object's width across the stroke, so a piece's support
/// ends on the object's own (soft) edge rather than on the rectangle.
pub const WIDTH_MARGIN: f64 = 2.0;
/// Step in px of the march across the stroke that measures the object's width.
const MARCH_STEP: f64 = 0.5;
/// Alpha above which a sampled pixel belongs to a piece.
const SUPPORT_ALPHA: f32 = 1.0 / 512.0;
/// Bounds of the scale a target width may ask of a piece: beyond them a piece is mostly
/// interpolated (enlarged) or aliased (shrunk) texture.
pub const SCALE_RANGE: (f64, f64) = (0.125, 8.0);

/// Where one piece goes and where it comes from. Points are `(x, y)` pixel positions, the
/// tangents unit vectors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PieceSpec {
    /// The target sample `p`.
    pub target: [f64; 2],
    /// The target stroke's direction at `p`.
    pub target_tangent: [f64; 2],
    /// The source sample `p'`.
    pub source: [f64; 2],
    /// The source stroke's direction at `p'`.
    pub source_tangent: [f64; 2],
    /// Half the piece's length along the stroke.
    pub half_length: f64,
    /// The most the piece reaches across the stroke on either side.
    pub max_half_width: f64,
    /// The object's half width wanted at `p`, in target px: the piece is scaled (texture and
    /// all) by its ratio to the object's half width across the source stroke at `p'`, within
    /// [`SCALE_RANGE`]. 0 keeps the source's scale (the paper).
    pub target_half_width: f64,
    /// How the wanted half width changes per target px along the stroke at `p`: the piece's
    /// sides follow it (a tapering branch gets a smooth outline, not steps). Read only with a
    /// target half width.
    pub target_half_width_slope: f64,
}

/// A fetched piece: an axis-aligned box of the target frame holding the piece's RGBA values.
#[derive(Clone, Debug, PartialEq)]
pub struct Piece {
    /// Row of the box's top-left pixel in the target frame (may be negative).
    pub y0: i64,
    /// Column of the box's top-left pixel.
    pub x0: i64,
    /// Box height.
    pub h: usize,
    /// Box width.
    pub w: usize,
    /// `h × w × 4`: the source's colour and alpha, zero outside the support.
    pub rgba: Vec<f32>,
    /// `h × w`: pixels of the piece (inside its rectangle, alpha above zero).
    pub support: Vec<bool>,
    /// How far the piece reaches across the stroke at `p'`, to the left (`−n`) and to the
    /// right (`+n`) of the source direction: the object's run across the stroke nearest `p'`,
    /// margin included (negative when the run lies wholly on the other side).
    pub widths: [f64; 2],
}

fn normal(t: [f64; 2]) -> [f64; 2] {
    [-t[1], t[0]]
}

fn alpha_at(img: &Image<'_>, x: f64, y: f64, px: &mut [f32; 4]) -> f32 {
    sample_any(img, x as f32, y as f32, px);
    px[3]
}

/// The run of the object (alpha ≥ ½) on the line through `p` along `dir`, within `± cap`,
/// that lies nearest `p` (the one holding `p` when `p` is on the object): its ends as signed
/// distances along `dir`, in [`MARCH_STEP`]s. `None` when the line misses the object. A
/// stroke drawn a little off the object's middle, or off a thin part, still finds it.
fn span(img: &Image<'_>, p: [f64; 2], dir: [f64; 2], cap: f64) -> Option<(f64, f64)> {
    let mut px = [0f32; 4];
    let k = (cap / MARCH_STEP).floor() as i64;
    let inside = |i: i64, px: &mut [f32; 4]| {
        let d = i as f64 * MARCH_STEP;
        alpha_at(img, p[0] + d * dir[0], p[1] + d * dir[1], px) >= 0.5
    };
    // The nearest inside step, the nearer side first at equal distance.
    let start = (0..=k).find_map(|i| [i, -i].into_iter().find(|&j| inside(j, &mut px)))?;
    let (mut lo, mut hi) = (start, start);
    while lo > -k && inside(lo - 1, &mut px) {
        lo -= 1;
    }
    while hi < k && inside(hi + 1, &mut px) {
        hi += 1;
    }
    Some((lo as f64 * MARCH_STEP, hi as f64 * MARCH_STEP))
}

fn check_spec(i: usize, s: &PieceSpec) -> Result<()> {
    let finite = s
        .target
        .iter()
        .chain(&s.target_tangent)
        .chain(&s.source)
        .chain(&s.source_tangent)
        .chain([
            &s.half_length,
            &s.max_half_width,
            &s.target_half_width,
            &s.target_half_width_slope,
        ])
        .all(|v| v.is_finite());
    let unit = |t: [f64; 2]| ((t[0] * t[0] + t[1] * t[1]).sqrt() - 1.0).abs() < 1e-6;
    if !finite || !unit(s.target_tangent) || !unit(s.source_tangent) {
        return Err(invalid(
            "pieces",
            format!("piece {i}: expected finite points and unit tangents"),
        ));
    }
    if s.half_length <= 0.0 || s.max_half_width < 0.0 || s.target_half_width < 0.0 {
        return Err(invalid(
            "pieces",
            format!(
                "piece {i}: expected a positive half length and non-negative widths, got {}, {} and {}",
                s.half_length, s.max_half_width, s.target_half_width
            ),
        ));
    }
    Ok(())
}

fn fetch_one(src: &Image<'_>, s: &PieceSpec) -> Piece {
    let (ts, ns) = (s.source_tangent, normal(s.source_tangent));
    let (lo, hi) = span(src, s.source, ns, s.max_half_width).unwrap_or((0.0, 0.0));
    let scale = if s.target_half_width > 0.0 && hi > lo {
        (2.0 * s.target_half_width / (hi - lo)).clamp(SCALE_RANGE.0, SCALE_RANGE.1)
    } else {
        1.0
    };
    let widths = [WIDTH_MARGIN - lo * scale, hi * scale + WIDTH_MARGIN];
    let (tt, nt) = (s.target_tangent, normal(s.target_tangent));
    let l = s.half_length;
    // The rectangle's corners in the target frame give the box.
    let corners = [
        (-l, -widths[0]),
        (-l, widths[1]),
        (l, -widths[0]),
        (l, widths[1]),
    ];
    let (mut xmin, mut xmax, mut ymin, mut ymax) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for (a, b) in corners {
        let x = s.target[0] + a * tt[0] + b * nt[0];
        let y = s.target[1] + a * tt[1] + b * nt[1];
        (xmin, xmax, ymin, ymax) = (xmin.min(x), xmax.max(x), ymin.min(y), ymax.max(y));
    }
    let (x0, y0) = (xmin.floor() as i64, ymin.floor() as i64);
    let w = (xmax.ceil() as i64 - x0 + 1) as usize;
    let h = (ymax.ceil() as i64 - y0 + 1) as usize;
    let mut rgba = vec![0f32; h * w * 4];
    let mut support = vec![false; h * w];
    for r in 0..h {
        for c in 0..w {
            let dx = (x0 + c as i64) as f64 - s.target[0];
            let dy = (y0 + r as i64) as f64 - s.target[1];
            let (a, b) = (dx * tt[0] + dy * tt[1], dx * nt[0] + dy * nt[1]);
            // With a wanted width the sides follow its change along the stroke.
            let side = if s.target_half_width > 0.0 {
                ((s.target_half_width + s.target_half_width_slope * a) / s.target_half_width)
                    .max(0.0)
            } else {
                1.0
            };
            if a.abs() > l || b < -widths[0] * side || b > widths[1] * side {
                continue;
            }
            let (a, b) = (a / scale, b / scale);
            let x = s.source[0] + a * ts[0] + b * ns[0];
            let y = s.source[1] + a * ts[1] + b * ns[1];
            let i = r * w + c;
            let px = &mut rgba[i * 4..i * 4 + 4];
            sample_any(src, x as f32, y as f32, px);
            if px[3] > SUPPORT_ALPHA {
                support[i] = true;
            } else {
                px.fill(0.0);
            }
        }
    }
    Piece {
        y0,
        x0,
        h,
        w,
        rgba,
        support,
        widths,
    }
}

/// Fetches one piece per spec from the RGBA `source` (alpha: where the object is, already
/// restricted to the part of it that belongs to the stroke). Each target pixel of the piece's
/// rectangle (`|a| ≤ half_length` along the target direction, `−w_l ≤ b ≤ w_r` across it,
/// `w` the ends of the object's run across the source stroke nearest `p'`, measured on the
/// alpha, times the scale, plus [`WIDTH_MARGIN`]) takes the source bilinearly at
/// `p' + (a·t' + b·n') / scale`, the scale 1 unless the spec asks for a target half width.
pub fn fetch(source: &Image<'_>, specs: &[PieceSpec]) -> Result<Vec<Piece>> {
    if source.c != 4 {
        return Err(invalid(
            "source",
            format!("expected an RGBA image (4 channels), got {}", source.c),
        ));
    }
    for (i, s) in specs.iter().enumerate() {
        check_spec(i, s)?;
    }
    let pieces = specs
        .par_iter()
        .map(|s| {
            if cancel::cancelled() {
                None
            } else {
                Some(fetch_one(source, s))
            }
        })
        .collect::<Vec<_>>();
    cancel::check()?;
    Ok(pieces.into_iter().flatten().collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 40 × 60 RGBA image: a horizontal band of rows 15..25 (alpha 1), colour = (x, y, 0).
    fn band() -> Vec<f32> {
        let (h, w) = (40, 60);
        let mut d = vec![0f32; h * w * 4];
        for y in 0..h {
            for x in 0..w {
                let o = (y * w + x) * 4;
                d[o] = x as f32;
                d[o + 1] = y as f32;
                d[o + 3] = if (15..25).contains(&y) { 1.0 } else { 0.0 };
            }
        }
        d
    }

    fn spec(target: [f64; 2], tt: [f64; 2]) -> PieceSpec {
        PieceSpec {
            target,
            target_tangent: tt,
            source: [30.0, 20.0],
            source_tangent: [1.0, 0.0],
            half_length: 6.0,
            max_half_width: 15.0,
            target_half_width: 0.0,
            target_half_width_slope: 0.0,
        }
    }

    #[test]
    #[allow(clippy::float_cmp)] // the march moves in exact half-pixel steps
    fn identity_piece_copies_the_band() {
        let d = band();
        let img = Image::new("s", &d, 40, 60, 4).unwrap();
        let p = &fetch(&img, &[spec([30.0, 20.0], [1.0, 0.0])]).unwrap()[0];
        // The band's edge rows 15 and 24 lie 5 and 4 px from the centre row; bilinear alpha
        // is still ½ halfway to the next row.
        assert_eq!(p.widths, [5.5 + WIDTH_MARGIN, 4.5 + WIDTH_MARGIN]);
        for r in 0..p.h {
            for c in 0..p.w {
                let (y, x) = (p.y0 + r as i64, p.x0 + c as i64);
                let i = r * p.w + c;
                let inside = (15..25).contains(&y) && (x - 30).abs() <= 6;
                assert_eq!(p.support[i], inside, "({y}, {x})");
                if inside {
                    assert_eq!(&p.rgba[i * 4..i * 4 + 2], &[x as f32, y as f32]);
                }
            }
        }
    }

    #[test]
    fn a_quarter_turn_maps_source_along_to_target_along() {
        let d = band();
        let img = Image::new("s", &d, 40, 60, 4).unwrap();
        // Target runs down (+y): a step of 1 down the target is a step of 1 right in the source;
        // target +x (its normal's opposite) is source −y.
        let p = &fetch(&img, &[spec([100.0, 100.0], [0.0, 1.0])]).unwrap()[0];
        let at = |y: i64, x: i64| {
            let i = ((y - p.y0) as usize) * p.w + (x - p.x0) as usize;
            (p.support[i], p.rgba[i * 4], p.rgba[i * 4 + 1])
        };
        assert_eq!(at(103, 100), (true, 33.0, 20.0));
        assert_eq!(at(100, 102), (true, 30.0, 18.0));
        assert!(!at(100, 106).0, "source row 14, off the band");
    }

    #[test]
    #[allow(clippy::float_cmp)] // the march moves in exact half-pixel steps
    fn a_source_sample_off_the_object_finds_the_nearest_run() {
        let d = band();
        let img = Image::new("s", &d, 40, 60, 4).unwrap();
        // 8 px above the band (rows 15..25): the run spans 7.5 to 17.5 px along +n (down).
        let mut s = spec([30.0, 20.0], [1.0, 0.0]);
        s.source = [30.0, 7.0];
        s.max_half_width = 20.0;
        let p = &fetch(&img, &[s]).unwrap()[0];
        assert_eq!(p.widths, [WIDTH_MARGIN - 7.5, 17.5 + WIDTH_MARGIN]);
        // Placed at target row 20, the band's rows 15..24 land on target rows 28..37.
        let rows: Vec<i64> = (0..p.h)
            .filter(|&r| p.support[r * p.w + p.w / 2])
            .map(|r| p.y0 + r as i64)
            .collect();
        assert_eq!(rows, (28..38).collect::<Vec<_>>());
        s.max_half_width = 5.0;
        assert_eq!(
            fetch(&img, &[s]).unwrap()[0].widths,
            [WIDTH_MARGIN, WIDTH_MARGIN]
        );
    }

    #[test]
    #[allow(clippy::float_cmp)] // scale 2 maps target pixels to exact half-pixel source steps
    fn a_target_half_width_scales_the_piece() {
        let d = band();
        let img = Image::new("s", &d, 40, 60, 4).unwrap();
        // The band's run across the stroke at row 20 is 10 px (−5.5 to 4.5): half width 10
        // asks for scale 2.
        let mut s = spec([30.0, 20.0], [1.0, 0.0]);
        s.target_half_width = 10.0;
        let p = &fetch(&img, &[s]).unwrap()[0];
        assert_eq!(p.widths, [11.0 + WIDTH_MARGIN, 9.0 + WIDTH_MARGIN]);
        let at = |y: i64, x: i64| {
            let i = ((y - p.y0) as usize) * p.w + (x - p.x0) as usize;
            (p.support[i], p.rgba[i * 4], p.rgba[i * 4 + 1])
        };
        // Target (x, y) takes source (30 + (x − 30) / 2, 20 + (y − 20) / 2).
        assert_eq!(at(24, 34), (true, 32.0, 22.0));
        assert_eq!(at(12, 30), (true, 30.0, 16.0));
        assert!(!at(8, 30).0, "source row 14, off the band");
        // A width shrinking by 1 px per px along +x: the lower side (11 px at the sample)
        // closes in with it, 11 × (10 − a) / 10 px at a, until the band's own edge (row 29).
        s.target_half_width_slope = -1.0;
        let t = &fetch(&img, &[s]).unwrap()[0];
        let edge = |x: i64| {
            (0..t.h)
                .filter(|&r| t.support[r * t.w + (x - t.x0) as usize])
                .map(|r| t.y0 + r as i64)
                .max()
        };
        assert_eq!(
            [edge(24), edge(30), edge(33), edge(36)],
            [Some(29), Some(29), Some(27), Some(24)]
        );
        s.target_half_width_slope = 0.0;
        // An absurd width is bounded by the scale range.
        s.target_half_width = 1e6;
        let q = &fetch(&img, &[s]).unwrap()[0];
        assert_eq!(q.widths[1], 4.5 * SCALE_RANGE.1 + WIDTH_MARGIN);
    }

    #[test]
    fn bad_specs_are_errors() {
        let d = band();
        let img = Image::new("s", &d, 40, 60, 4).unwrap();
        let mut s = spec([0.0, 0.0], [1.0, 0.0]);
        s.target_tangent = [2.0, 0.0];
        assert!(fetch(&img, &[s]).is_err());
        let mut s = spec([0.0, 0.0], [1.0, 0.0]);
        s.half_length = 0.0;
        assert!(fetch(&img, &[s]).is_err());
        let mut s = spec([0.0, 0.0], [1.0, 0.0]);
        s.target_half_width = -1.0;
        assert!(fetch(&img, &[s]).is_err());
    }
}
