//! The bending model's per-candidate terms that every growth step evaluates over all of its
//! candidates (Sibbing et al. 2010, §4.2): the paper's `dist` between a branch's history and
//! each candidate's, and the heading-change bins of the histogram term.
//!
//! `phloem.branching.bending` keeps the NumPy reference of each (in the tests); both give the
//! same bits, since every step here is one IEEE operation in the order NumPy takes them.

use std::f64::consts::PI;

use crate::error::{invalid, Result};

/// The paper's `dist(X, Y) = 1 / (‖X − Y‖ + 1) + 1` of each of the `c` columns of `cols`
/// (`l` rows, row-major) against `y` (`l` values). The squares are summed row by row.
pub fn dist_columns(cols: &[f64], y: &[f64]) -> Result<Vec<f64>> {
    let l = y.len();
    if l == 0 {
        return Err(invalid("y", "expected at least one history element"));
    }
    if cols.len() % l != 0 {
        return Err(invalid(
            "cols",
            format!(
                "expected {l} rows of equal length, got {} values",
                cols.len()
            ),
        ));
    }
    let c = cols.len() / l;
    let mut s: Vec<f64> = cols[..c]
        .iter()
        .map(|&v| {
            let d = v - y[0];
            d * d
        })
        .collect();
    for (row, &yi) in cols.chunks_exact(c).zip(y).skip(1) {
        for (acc, &v) in s.iter_mut().zip(row) {
            let d = v - yi;
            *acc += d * d;
        }
    }
    for v in &mut s {
        *v = 1.0 / (v.sqrt() + 1.0) + 1.0;
    }
    Ok(s)
}

/// `a mod b` for `b > 0` as NumPy's `%` gives it: `fmod`, moved into `[0, b)`.
#[inline]
fn remainder(a: f64, b: f64) -> f64 {
    // fmod is `a` itself where |a| < b (exactly so in IEEE arithmetic), the common case here,
    // and libm's fmod is the slow part of the loop
    let m = if a.abs() < b { a } else { a % b };
    if m == 0.0 {
        0.0
    } else if m < 0.0 {
        m + b
    } else {
        m
    }
}

/// The absolute heading change of a turn `t` (radians), wrapped to `[0, π]`.
#[inline]
#[must_use]
pub fn abs_turn(t: f64) -> f64 {
    (PI - remainder(PI - t, 2.0 * PI)).abs()
}

/// The bin in `[0, bins)` of each turn's [`abs_turn`] among `bins` equal bins of `[0, π]`
/// (`π` itself in the last, NaN in the first).
pub fn turn_bins(turns: &[f64], bins: usize) -> Result<Vec<i64>> {
    if bins == 0 {
        return Err(invalid("bins", "expected at least one bin, got 0"));
    }
    let nb = bins as f64;
    let top = bins as i64 - 1;
    Ok(turns
        .iter()
        .map(|&t| {
            // x >= 0 (or NaN), so truncation is NumPy's floor, and Rust's saturating cast
            // sends NaN to 0 as NumPy's nan_to_num does; π itself lands in the last bin
            let x = abs_turn(t) / PI * nb;
            (x as i64).min(top)
        })
        .collect())
}

/// §4.2's `Δ` of a histogram for every candidate that adds one count to each of its `p` bins
/// (`bins`, `(C, p)` row-major): `(now − ‖u − h_i / n‖²) / len`, expanded as
/// `now − (uu − 2 Σ_p u[b_ip] / n + Σ_b h_ib² / n²)` over `len`. `u` is the target less the
/// counts over `n`, `uu` its squared norm and `now` the squared distance before the move (the
/// caller's, so that they keep NumPy's summation order).
pub fn histogram_moves(
    u: &[f64],
    uu: f64,
    now: f64,
    n: f64,
    bins: &[i64],
    p: usize,
) -> Result<Vec<f64>> {
    if p == 0 || bins.len() % p != 0 {
        return Err(invalid(
            "bins",
            format!("expected rows of {p} bins, got {} values", bins.len()),
        ));
    }
    if let Some(&b) = bins
        .iter()
        .find(|&&b| usize::try_from(b).map_or(true, |i| i >= u.len()))
    {
        return Err(invalid("bins", format!("bin {b} outside 0..{}", u.len())));
    }
    let len = u.len() as f64;
    // Σ_b h_ib² / n² takes one value per count of pairs that share a bin: divide once each
    let shared: Vec<f64> = (0..=p * (p - 1) / 2)
        .map(|k| (p as f64 + 2.0 * k as f64) / (n * n))
        .collect();
    let mut out = Vec::with_capacity(bins.len() / p);
    for row in bins.chunks_exact(p) {
        // summed from the first value on, as NumPy sums a short row
        let sum = row[1..]
            .iter()
            .fold(u[row[0] as usize], |acc, &b| acc + u[b as usize]);
        // Σ_b h_ib² = p + 2 × the pairs that share a bin
        let mut pairs = 0;
        for a in 0..p {
            for b in a + 1..p {
                pairs += usize::from(row[a] == row[b]);
            }
        }
        let after = uu - 2.0 * sum / n + shared[pairs];
        out.push((now - after) / len);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[allow(clippy::float_cmp)] // equal histories give dist 2 exactly
    fn dist_is_two_for_equal_histories_and_falls_with_the_distance() {
        // two rows, three candidates: equal, 3-4-5 apart, far
        let cols = [1.0, 4.0, 101.0, 2.0, 6.0, 2.0];
        let d = dist_columns(&cols, &[1.0, 2.0]).unwrap();
        assert_eq!(d[0], 2.0);
        assert!((d[1] - (1.0 / 6.0 + 1.0)).abs() < 1e-15);
        assert!(d[2] < d[1] && d[2] > 1.0);
        assert!(dist_columns(&cols, &[]).is_err());
        assert!(dist_columns(&cols[..5], &[1.0, 2.0]).is_err());
    }

    #[test]
    fn histogram_moves_agree_with_the_direct_distance() {
        // target, counts, and two candidates adding p = 3 counts each
        let target = [0.5, 0.3, 0.2, 0.0];
        let counts = [3.0, 1.0, 0.0, 1.0];
        let n0: f64 = counts.iter().sum();
        let n = n0 + 3.0;
        let now: f64 = target
            .iter()
            .zip(&counts)
            .map(|(t, c)| (t - c / n0).powi(2))
            .sum();
        let u: Vec<f64> = target.iter().zip(&counts).map(|(t, c)| t - c / n).collect();
        let uu: f64 = u.iter().map(|v| v * v).sum();
        let rows = [0, 2, 2, 3, 3, 3];
        let got = histogram_moves(&u, uu, now, n, &rows, 3).unwrap();
        for (i, row) in rows.chunks(3).enumerate() {
            let mut h = counts;
            for &b in row {
                h[b as usize] += 1.0;
            }
            let after: f64 = target
                .iter()
                .zip(&h)
                .map(|(t, c)| (t - c / n).powi(2))
                .sum();
            assert!((got[i] - (now - after) / 4.0).abs() < 1e-12);
        }
        assert!(histogram_moves(&u, uu, now, n, &[0, 9, 1], 3).is_err());
        assert!(histogram_moves(&u, uu, now, n, &[0, 1], 3).is_err());
    }

    #[test]
    fn turns_wrap_to_their_absolute_change() {
        for (t, want) in [
            (0.0, 0.0),
            (0.5, 0.5),
            (-0.5, 0.5),
            (2.0 * PI - 0.25, 0.25),
            (-3.0 * PI + 0.5, PI - 0.5),
            (7.0 * PI, PI),
        ] {
            assert!((abs_turn(t) - want).abs() < 1e-12, "{t}: {}", abs_turn(t));
        }
    }

    #[test]
    fn turn_bins_cover_zero_to_pi_and_map_nan_to_the_first() {
        let b = turn_bins(
            &[0.0, PI, 0.26, -0.26, PI / 2.0, f64::NAN, f64::INFINITY],
            4,
        )
        .unwrap();
        assert_eq!(b, vec![0, 3, 0, 0, 2, 0, 0]);
        assert!(turn_bins(&[0.0], 0).is_err());
    }
}
