//! Resampling a polyline to a constant edge length, the first step of branching synthesis
//! (Sibbing et al. 2010, §4.1: every branch becomes a sequence of edges of length `h`).
//!
//! `phloem.branching.Branch.resample` calls this. Its NumPy reference (kept in the tests)
//! takes 2-vector dot products from BLAS, which computes `a·b` as `fma(a₁, b₁, a₀ b₀)`;
//! [`dot`] does the same so that both give the same bits.

use crate::error::{invalid, Result};

/// `a·b` for 2-vectors, rounded as NumPy's `a @ b` rounds it.
#[inline]
fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[1].mul_add(b[1], a[0] * b[0])
}

#[inline]
fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

/// `a + t d`, without fusing (NumPy's element-wise arithmetic does not).
#[inline]
fn along(a: [f64; 2], t: f64, d: [f64; 2]) -> [f64; 2] {
    let (x, y) = (t * d[0], t * d[1]);
    [a[0] + x, a[1] + y]
}

/// Up to `count` vertices along `points` with consecutive distance exactly `h`, starting at
/// the first point.
///
/// From the current vertex `c` the next one is where the polyline first leaves the circle of
/// radius `h` around `c`: on the current segment that is the larger root of
/// `|a + t d − c|² = h²`; if it lies beyond the segment's end, the end is still inside the
/// circle and the search moves on to the next segment. A very curved polyline gives fewer
/// than `count` vertices.
#[must_use]
pub fn chord_walk(points: &[[f64; 2]], count: usize, h: f64) -> Vec<[f64; 2]> {
    let Some(&first) = points.first() else {
        return Vec::new();
    };
    let mut out = vec![first];
    let mut seg = 0;
    while out.len() < count && seg + 1 < points.len() {
        let a = points[seg];
        let d = sub(points[seg + 1], a);
        let f = sub(a, out[out.len() - 1]);
        let qa = dot(d, d);
        if qa == 0.0 {
            seg += 1;
            continue;
        }
        let qb = dot(f, d);
        let disc = qb * qb - qa * (dot(f, f) - h * h);
        let t = (-qb + disc.max(0.0).sqrt()) / qa;
        if t <= 1.0 {
            out.push(along(a, t, d));
        } else {
            seg += 1;
        }
    }
    out
}

/// The arc length along `points` (`cum`, its running length from the first point) of each
/// `query` point's nearest point on the polyline, searched from the previous query's segment
/// on, so that the positions never go back along it.
pub fn arc_positions(points: &[[f64; 2]], cum: &[f64], query: &[[f64; 2]]) -> Result<Vec<f64>> {
    if cum.len() != points.len() {
        return Err(invalid(
            "cum",
            format!(
                "expected one arc length per point ({}), got {}",
                points.len(),
                cum.len()
            ),
        ));
    }
    let mut out = Vec::with_capacity(query.len());
    let mut seg = 0;
    for &q in query {
        let (mut best, mut best_s, mut best_seg) = (f64::INFINITY, 0.0, seg);
        for j in seg..points.len().saturating_sub(1) {
            let a = points[j];
            let d = sub(points[j + 1], a);
            let qa = dot(d, d);
            let t = if qa == 0.0 {
                0.0
            } else {
                (dot(sub(q, a), d) / qa).clamp(0.0, 1.0)
            };
            let e = sub(along(a, t, d), q);
            let dist = dot(e, e);
            if dist < best - 1e-12 {
                (best, best_s, best_seg) = (dist, cum[j] + t * (cum[j + 1] - cum[j]), j);
            }
            if dist < 1e-12 {
                break;
            }
        }
        out.push(best_s);
        seg = best_seg;
    }
    Ok(out)
}

/// `points` resampled by [`chord_walk`] to up to `count` vertices at distance `h` (its two end
/// points where the walk cannot leave the first one's circle), and each new vertex's
/// [`arc_positions`].
pub fn resample(
    points: &[[f64; 2]],
    cum: &[f64],
    count: usize,
    h: f64,
) -> Result<(Vec<[f64; 2]>, Vec<f64>)> {
    let mut walk = chord_walk(points, count, h);
    if walk.len() < 2 {
        walk = match (points.first(), points.last()) {
            (Some(&a), Some(&b)) => vec![a, b],
            _ => return Err(invalid("points", "expected at least one point")),
        };
    }
    let s = arc_positions(points, cum, &walk)?;
    Ok((walk, s))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn running_length(points: &[[f64; 2]]) -> Vec<f64> {
        let mut cum = vec![0.0];
        for w in points.windows(2) {
            let d = sub(w[1], w[0]);
            cum.push(cum[cum.len() - 1] + d[0].hypot(d[1]));
        }
        cum
    }

    #[test]
    #[allow(clippy::float_cmp)] // the walk starts at the very first point
    fn every_edge_of_the_walk_has_length_h() {
        let pts: Vec<[f64; 2]> = (0..200)
            .map(|i| {
                let t = f64::from(i) * 0.05;
                [30.0 * t.cos() + t, 20.0 * t.sin()]
            })
            .collect();
        let walk = chord_walk(&pts, 1000, 2.5);
        assert!(walk.len() > 10);
        assert_eq!(walk[0], pts[0]);
        for w in walk.windows(2) {
            let d = sub(w[1], w[0]);
            assert!((d[0].hypot(d[1]) - 2.5).abs() < 1e-9);
        }
    }

    #[test]
    #[allow(clippy::float_cmp)] // multiples of 3 on a line are exact
    fn a_straight_line_is_cut_at_multiples_of_h_and_count_bounds_the_walk() {
        let pts = [[0.0, 0.0], [4.0, 0.0], [4.0, 0.0], [10.0, 0.0]];
        let walk = chord_walk(&pts, 100, 3.0);
        assert_eq!(walk, vec![[0.0, 0.0], [3.0, 0.0], [6.0, 0.0], [9.0, 0.0]]);
        assert_eq!(chord_walk(&pts, 2, 3.0).len(), 2);
        assert!(chord_walk(&[], 5, 1.0).is_empty());
    }

    #[test]
    fn arc_positions_agree_with_a_brute_force_nearest_point() {
        let pts: Vec<[f64; 2]> = (0..50)
            .map(|i| [f64::from(i) * 2.0, (f64::from(i) * 0.3).sin() * 5.0])
            .collect();
        let cum = running_length(&pts);
        let query = chord_walk(&pts, 1000, 1.7);
        let s = arc_positions(&pts, &cum, &query).unwrap();
        for (q, &si) in query.iter().zip(&s) {
            // brute force over every segment, without the monotone search
            let mut best = (f64::INFINITY, 0.0);
            for j in 0..pts.len() - 1 {
                let d = sub(pts[j + 1], pts[j]);
                let t = (dot(sub(*q, pts[j]), d) / dot(d, d)).clamp(0.0, 1.0);
                let e = sub(along(pts[j], t, d), *q);
                if dot(e, e) < best.0 {
                    best = (dot(e, e), cum[j] + t * (cum[j + 1] - cum[j]));
                }
            }
            assert!((si - best.1).abs() < 1e-9, "{si} against {}", best.1);
        }
        assert!(s.windows(2).all(|w| w[1] >= w[0]));
    }

    #[test]
    #[allow(clippy::float_cmp)] // the ends are copied, their arc lengths are sums of exact steps
    fn a_polyline_that_never_leaves_the_first_circle_keeps_its_ends() {
        let pts = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 0.2]];
        let (walk, s) = resample(&pts, &running_length(&pts), 4, 2.0).unwrap();
        assert_eq!(walk, vec![[0.0, 0.0], [0.0, 0.2]]);
        assert_eq!(s, vec![0.0, 3.8]);
        assert!(resample(&[], &[], 4, 2.0).is_err());
    }

    #[test]
    fn arc_positions_reject_a_running_length_of_the_wrong_size() {
        let err = arc_positions(&[[0.0, 0.0], [1.0, 0.0]], &[0.0], &[[0.5, 0.0]]).unwrap_err();
        assert!(err.to_string().contains("cum"));
    }
}
