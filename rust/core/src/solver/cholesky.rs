//! Dense Cholesky factorisation `A = L Lᵀ` that skips what lies outside the matrix's row
//! profile: the direct solver of the coarsest multigrid level and of small systems.
//!
//! For a grid operator in row-major order, whose nonzeros lie within a few grid rows of the
//! diagonal, the profile is a band and the factor costs `O(n b²)` instead of `O(n³)`. The terms
//! skipped are exact zeros, so the factor is the one of the textbook loop, bit for bit.

// Triangular loops index the factor and the lanes in lockstep.
#![allow(clippy::needless_range_loop)]

/// A factor `L Lᵀ` of a symmetric positive (semi)definite matrix, kept dense with its profile.
pub(crate) struct Cholesky {
    n: usize,
    /// Lower-triangular factor, row-major `n × n`.
    l: Vec<f64>,
    /// First column of each row of `l` that is not zero.
    first: Vec<usize>,
}

impl Cholesky {
    /// Factors the row-major `n × n` matrix `m` with `shift` added to its diagonal and pivots
    /// floored at `floor` (see [`cholesky_in_place`]).
    pub fn new(mut m: Vec<f64>, n: usize, shift: f64, floor: f64) -> Self {
        debug_assert_eq!(m.len(), n * n);
        let first = cholesky_in_place(&mut m, n, shift, floor);
        Self { n, l: m, first }
    }

    /// Solves `L Lᵀ x = b` for `L` right-hand sides at once, in place (`x` holds `b` on entry).
    pub fn solve<const L: usize>(&self, x: &mut [[f64; L]]) {
        let n = self.n;
        debug_assert_eq!(x.len(), n);
        for i in 0..n {
            let mut s = x[i];
            for k in self.first[i]..i {
                let l = self.l[i * n + k];
                for c in 0..L {
                    s[c] -= l * x[k][c];
                }
            }
            x[i] = s.map(|v| v / self.l[i * n + i]);
        }
        for i in (0..n).rev() {
            let mut s = x[i];
            for k in i + 1..n {
                if self.first[k] > i {
                    continue; // outside the profile: a zero
                }
                let l = self.l[k * n + i];
                for c in 0..L {
                    s[c] -= l * x[k][c];
                }
            }
            x[i] = s.map(|v| v / self.l[i * n + i]);
        }
    }
}

/// Dense Cholesky factorisation of the row-major `n × n` matrix `m`, in place (the lower
/// triangle becomes `L`). `shift` is added to the diagonal first and pivots are floored at
/// `floor`, so singular but consistent coarse systems still factor.
///
/// Returns the profile: `first[i]`, the first column of row `i` that is not zero. `L` has
/// the profile of the matrix (fill-in stays inside it), so only entries inside it are
/// computed and read: for a grid operator in row-major order, whose band is a few grid rows
/// wide, that is `O(n b²)` instead of `O(n³)`. The terms skipped are exact zeros, so the
/// factor is the same as the full loop's.
pub(crate) fn cholesky_in_place(m: &mut [f64], n: usize, shift: f64, floor: f64) -> Vec<usize> {
    let first: Vec<usize> = (0..n)
        .map(|i| (0..i).find(|&j| m[i * n + j] != 0.0).unwrap_or(i))
        .collect();
    for i in 0..n {
        m[i * n + i] += shift;
    }
    for j in 0..n {
        let fj = first[j];
        let mut d = m[j * n + j];
        for k in fj..j {
            d -= m[j * n + k] * m[j * n + k];
        }
        let d = d.max(floor).sqrt();
        m[j * n + j] = d;
        for i in j + 1..n {
            if first[i] > j {
                continue; // outside the profile: stays 0
            }
            let mut s = m[i * n + j];
            for k in first[i].max(fj)..j {
                s -= m[i * n + k] * m[j * n + k];
            }
            m[i * n + j] = s / d;
        }
    }
    first
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The profile-aware factor equals the textbook full-loop factor, bit for bit, on banded
    /// matrices with ragged profiles (a grid operator with some unknowns removed).
    #[test]
    fn profile_cholesky_equals_the_full_loop() {
        fn full(m: &mut [f64], n: usize, shift: f64, floor: f64) {
            for i in 0..n {
                m[i * n + i] += shift;
            }
            for j in 0..n {
                let mut d = m[j * n + j];
                for k in 0..j {
                    d -= m[j * n + k] * m[j * n + k];
                }
                let d = d.max(floor).sqrt();
                m[j * n + j] = d;
                for i in j + 1..n {
                    let mut s = m[i * n + j];
                    for k in 0..j {
                        s -= m[i * n + k] * m[j * n + k];
                    }
                    m[i * n + j] = s / d;
                }
            }
        }
        let mut rng = crate::rng::Rng::keyed(5, 0, 0);
        for &(h, w) in &[(6usize, 7usize), (9, 4), (12, 12)] {
            // A 5-point Laplacian plus a diagonal, with random cells dropped.
            let keep: Vec<usize> = (0..h * w).filter(|_| rng.below(5) != 0).collect();
            let n = keep.len();
            let mut m = vec![0f64; n * n];
            for (i, &p) in keep.iter().enumerate() {
                m[i * n + i] = 4.5 + rng.below(100) as f64 / 100.0;
                for (j, &q) in keep.iter().enumerate() {
                    let (dy, dx) = ((p / w).abs_diff(q / w), (p % w).abs_diff(q % w));
                    if dy + dx == 1 {
                        m[i * n + j] = -1.0;
                    }
                }
            }
            let mut a = m.clone();
            let first = cholesky_in_place(&mut a, n, 1e-9, 1e-12);
            full(&mut m, n, 1e-9, 1e-12);
            for i in 0..n {
                assert!(first[i] <= i);
                for j in 0..=i {
                    assert_eq!(
                        a[i * n + j].to_bits(),
                        m[i * n + j].to_bits(),
                        "L[{i}][{j}]"
                    );
                }
            }
            assert!(
                first.iter().enumerate().any(|(i, &f)| f > 0 && f < i),
                "a ragged profile"
            );
        }
    }

    #[test]
    fn solves_a_small_system() {
        // A 1-D Dirichlet Laplacian: a tridiagonal profile.
        let n = 9;
        let mut m = vec![0f64; n * n];
        for i in 0..n {
            m[i * n + i] = 2.0;
            if i > 0 {
                m[i * n + i - 1] = -1.0;
                m[(i - 1) * n + i] = -1.0;
            }
        }
        let x_true: Vec<[f64; 2]> = (0..n).map(|i| [i as f64, (i * i) as f64 * 0.1]).collect();
        let mut b: Vec<[f64; 2]> = (0..n)
            .map(|i| std::array::from_fn(|c| (0..n).map(|j| m[i * n + j] * x_true[j][c]).sum()))
            .collect();
        let f = Cholesky::new(m, n, 0.0, 0.0);
        f.solve(&mut b);
        for (x, t) in b.iter().zip(&x_true) {
            for c in 0..2 {
                assert!((x[c] - t[c]).abs() < 1e-12, "{x:?} vs {t:?}");
            }
        }
    }
}
