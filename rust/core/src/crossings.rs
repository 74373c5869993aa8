//! Proper crossings between candidate polylines and existing segments, the test that keeps a
//! growing branching structure planar (Sibbing et al. 2010, §4.4: a candidate extension that
//! crosses the structure is not valid).

use crate::error::{invalid, Result};

/// The orientation of `c` relative to the line `a → b` (twice the signed triangle area).
///
/// Written as `phloem.branching.growth`'s NumPy reference computes it, so that both give the
/// same bits.
#[inline]
fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// Whether segments `pq` and `ab` cross properly: a strict sign change of both orientation
/// pairs. Touching at an end point (a child starting on its parent, consecutive edges) is not
/// a crossing.
#[inline]
#[must_use]
pub fn crosses(p: [f64; 2], q: [f64; 2], a: [f64; 2], b: [f64; 2]) -> bool {
    orient(p, q, a) * orient(p, q, b) < 0.0 && orient(a, b, p) * orient(a, b, q) < 0.0
}

/// For each of `n` polylines of `len` points (`paths`, `(n, len, 2)` row-major), whether any of
/// its edges crosses any of `segments` (`(m, 4)` rows `x0, y0, x1, y1`).
pub fn polylines_crossing(paths: &[f64], len: usize, segments: &[f64]) -> Result<Vec<bool>> {
    if len < 2 {
        return Err(invalid(
            "paths",
            format!("expected polylines of at least 2 points, got {len}"),
        ));
    }
    if paths.len() % (2 * len) != 0 {
        return Err(invalid(
            "paths",
            format!("expected (n, {len}, 2) coordinates, got {}", paths.len()),
        ));
    }
    if segments.len() % 4 != 0 {
        return Err(invalid(
            "segments",
            format!("expected (m, 4) coordinates, got {}", segments.len()),
        ));
    }
    let segs: Vec<([f64; 2], [f64; 2])> = segments
        .chunks_exact(4)
        .map(|s| ([s[0], s[1]], [s[2], s[3]]))
        .collect();
    Ok(paths
        .chunks_exact(2 * len)
        .map(|path| {
            let pt = |i: usize| [path[2 * i], path[2 * i + 1]];
            (0..len - 1).any(|i| {
                let (p, q) = (pt(i), pt(i + 1));
                segs.iter().any(|&(a, b)| crosses(p, q, a, b))
            })
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_x_crosses_and_touching_ends_do_not() {
        assert!(crosses([0.0, 0.0], [2.0, 2.0], [0.0, 2.0], [2.0, 0.0]));
        // a child starting on its parent, consecutive edges, collinear overlap: not proper
        assert!(!crosses([1.0, 1.0], [3.0, 0.0], [0.0, 0.0], [2.0, 2.0]));
        assert!(!crosses([0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [2.0, 1.0]));
        assert!(!crosses([0.0, 0.0], [2.0, 0.0], [1.0, 0.0], [3.0, 0.0]));
        assert!(!crosses([0.0, 0.0], [1.0, 0.0], [2.0, -1.0], [2.0, 1.0]));
    }

    #[test]
    fn polylines_agree_with_every_pair_tested() {
        let mut s = 12345u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s % 1000) as f64 / 100.0
        };
        let (n, len, m) = (40, 5, 30);
        let paths: Vec<f64> = (0..n * len * 2).map(|_| next()).collect();
        // short segments, so that some polylines miss them all
        let segments: Vec<f64> = (0..m)
            .flat_map(|_| {
                let (x, y) = (next(), next());
                [x, y, x + next() / 10.0 - 0.5, y + next() / 10.0 - 0.5]
            })
            .collect();
        let got = polylines_crossing(&paths, len, &segments).unwrap();
        let pt = |c: usize, i: usize| [paths[(c * len + i) * 2], paths[(c * len + i) * 2 + 1]];
        let mut some = 0;
        for (c, &hit) in got.iter().enumerate() {
            let want = (0..len - 1).any(|i| {
                (0..m).any(|j| {
                    let g = &segments[4 * j..4 * j + 4];
                    crosses(pt(c, i), pt(c, i + 1), [g[0], g[1]], [g[2], g[3]])
                })
            });
            assert_eq!(hit, want);
            some += usize::from(hit);
        }
        assert!(some > 0 && some < n);
    }

    #[test]
    fn bad_shapes_are_errors_naming_the_argument() {
        assert!(polylines_crossing(&[0.0; 4], 1, &[]).is_err());
        assert!(polylines_crossing(&[0.0; 5], 2, &[]).is_err());
        let e = polylines_crossing(&[0.0; 4], 2, &[0.0; 3]).unwrap_err();
        assert!(e.to_string().starts_with("segments:"), "{e}");
        assert_eq!(polylines_crossing(&[], 2, &[]).unwrap(), Vec::<bool>::new());
    }
}
