//! The patch-distance kernels shared by PatchMatch ([`crate::patch`]), the k-nearest-patch
//! search ([`crate::knn`]) and texture-by-numbers ([`crate::tbn`]): sums of squared
//! differences over rows of `f32` values, portable or with AVX2, bit-identical either way.
//!
//! Callers pick the kernel once per work unit (`avx2_enabled`) and monomorphise their hot
//! loop over `Kernel`; only code inlined into a `#[target_feature(enable = "avx2")]`
//! function is compiled with AVX2, hence the `#[inline(always)]` throughout.

#![allow(clippy::inline_always)]

use std::sync::atomic::{AtomicBool, Ordering};

/// Forces the portable (non-AVX2) code path; for tests and for timing the difference.
pub static FORCE_PORTABLE: AtomicBool = AtomicBool::new(false);

/// Whether the AVX2 kernel may be used (the CPU has it and [`FORCE_PORTABLE`] is off).
pub(crate) fn avx2_enabled() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        !FORCE_PORTABLE.load(Ordering::Relaxed) && std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// A patch-distance kernel. Each row is split into chunks of eight values (the last one
/// zero-padded); chunk `j` of every row adds its squared differences lane by lane into
/// accumulator `j mod 3`. Rows are never reduced on their own, so a patch's additions form
/// three short independent chains instead of one long serial one; the three are combined and
/// reduced only when a total is needed. Implementations must give bit-identical results.
pub(crate) trait Kernel {
    type Acc: Copy;
    fn zero() -> Self::Acc;
    fn add_row(acc: &mut Self::Acc, a: &[f32], b: &[f32]);
    fn total(acc: &Self::Acc) -> f32;

    /// `base` plus the distance between the `rows × len` values at `t[t0 + k·ts..]` and
    /// `s[s0 + k·ss..]` (`k < rows`), abandoned if it has reached `cutoff` after two rows.
    /// (One check only: on unrelated images most candidates survive the first rows, and each
    /// check is a horizontal sum and a badly predicted branch. Abandoning never changes a
    /// result, only the time: partial sums of squares never exceed the full one.) `NC` is `len.div_ceil(8)`; both slices must hold at
    /// least [`PAD`] values past the end of their last row, which implementations may read
    /// (and ignore). Same result, bit for bit, as [`Self::add_row`] row by row.
    #[inline(always)]
    fn patch<const NC: usize>(
        t: &[f32],
        (t0, ts): (usize, usize),
        s: &[f32],
        (s0, ss): (usize, usize),
        (rows, len): (usize, usize),
        base: f32,
        cutoff: f32,
    ) -> f32 {
        let mut acc = Self::zero();
        for k in 0..rows {
            let (a, b) = (t0 + k * ts, s0 + k * ss);
            Self::add_row(&mut acc, &t[a..a + len], &s[b..b + len]);
            if k == 1 && rows > 2 {
                let partial = base + Self::total(&acc);
                if partial >= cutoff {
                    return partial;
                }
            }
        }
        base + Self::total(&acc)
    }
}

/// Zero floats appended to a level's source and target buffers, so that a fixed-width kernel
/// ([`Kernel::patch`]) may load whole 8-lane chunks past the end of a patch row.
pub(crate) const PAD: usize = 8;

/// The portable kernel.
pub(crate) struct Portable;

impl Kernel for Portable {
    type Acc = [[f32; 8]; 3];

    #[inline(always)]
    fn zero() -> Self::Acc {
        [[0.0; 8]; 3]
    }

    #[inline(always)]
    fn add_row(acc: &mut Self::Acc, a: &[f32], b: &[f32]) {
        let n = a.len().min(b.len());
        for (chunk, start) in (0..n).step_by(8).enumerate() {
            let lanes = &mut acc[chunk % 3];
            for (i, lane) in lanes.iter_mut().enumerate().take((n - start).min(8)) {
                let d = a[start + i] - b[start + i];
                *lane += d * d;
            }
        }
    }

    #[inline(always)]
    fn total(acc: &Self::Acc) -> f32 {
        let mut v = [0f32; 8];
        for (i, lane) in v.iter_mut().enumerate() {
            *lane = (acc[0][i] + acc[1][i]) + acc[2][i];
        }
        ((v[0] + v[4]) + (v[1] + v[5])) + ((v[2] + v[6]) + (v[3] + v[7]))
    }
}

/// AVX2 intrinsics doing exactly what [`Portable`] does lane by lane: subtract, multiply, add
/// (no fused multiply-add, whose single rounding would change results); the tail chunk is a
/// masked load whose empty lanes add `+0.0`, which changes nothing.
#[cfg(target_arch = "x86_64")]
pub(crate) struct Avx2;

#[cfg(target_arch = "x86_64")]
impl Kernel for Avx2 {
    type Acc = [std::arch::x86_64::__m256; 3];

    #[inline(always)]
    fn zero() -> Self::Acc {
        // SAFETY: only reached from callers compiled with AVX2 (see the module docs).
        unsafe { [std::arch::x86_64::_mm256_setzero_ps(); 3] }
    }

    #[inline(always)]
    fn add_row(acc: &mut Self::Acc, a: &[f32], b: &[f32]) {
        use std::arch::x86_64::{
            __m256, _mm256_add_ps, _mm256_cmpgt_epi32, _mm256_loadu_ps, _mm256_maskload_ps,
            _mm256_mul_ps, _mm256_set1_epi32, _mm256_setr_epi32, _mm256_sub_ps,
        };
        let n = a.len().min(b.len());
        let full = n / 8 * 8;
        // SAFETY: AVX2 is enabled (see `zero`); full loads read below `full <= n`, and the
        // masked load touches only the `n - full` lanes inside both slices.
        unsafe {
            let sq = |i: usize| -> __m256 {
                let d = _mm256_sub_ps(
                    _mm256_loadu_ps(a.as_ptr().add(i)),
                    _mm256_loadu_ps(b.as_ptr().add(i)),
                );
                _mm256_mul_ps(d, d)
            };
            // Chunk j goes to accumulator j mod 3, as in `Portable`; the indices are static
            // so the three accumulators stay in registers.
            let [mut a0, mut a1, mut a2] = *acc;
            let mut i = 0;
            while i + 24 <= full {
                a0 = _mm256_add_ps(a0, sq(i));
                a1 = _mm256_add_ps(a1, sq(i + 8));
                a2 = _mm256_add_ps(a2, sq(i + 16));
                i += 24;
            }
            // 0, 1 or 2 full chunks left, then maybe a partial one: the next slots in order.
            let left = (full - i) / 8;
            let rest = (n - full) as i32;
            let tail = if rest > 0 {
                let mask = _mm256_cmpgt_epi32(
                    _mm256_set1_epi32(rest),
                    _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
                );
                let d = _mm256_sub_ps(
                    _mm256_maskload_ps(a.as_ptr().add(full), mask),
                    _mm256_maskload_ps(b.as_ptr().add(full), mask),
                );
                Some(_mm256_mul_ps(d, d))
            } else {
                None
            };
            match (left, tail) {
                (0, Some(t)) => a0 = _mm256_add_ps(a0, t),
                (1, None) => a0 = _mm256_add_ps(a0, sq(i)),
                (1, Some(t)) => {
                    a0 = _mm256_add_ps(a0, sq(i));
                    a1 = _mm256_add_ps(a1, t);
                }
                (2, None) => {
                    a0 = _mm256_add_ps(a0, sq(i));
                    a1 = _mm256_add_ps(a1, sq(i + 8));
                }
                (2, Some(t)) => {
                    a0 = _mm256_add_ps(a0, sq(i));
                    a1 = _mm256_add_ps(a1, sq(i + 8));
                    a2 = _mm256_add_ps(a2, t);
                }
                _ => {}
            }
            *acc = [a0, a1, a2];
        }
    }

    #[inline(always)]
    fn patch<const NC: usize>(
        t: &[f32],
        (t0, ts): (usize, usize),
        s: &[f32],
        (s0, ss): (usize, usize),
        (rows, len): (usize, usize),
        base: f32,
        cutoff: f32,
    ) -> f32 {
        use std::arch::x86_64::{
            _mm256_add_ps, _mm256_and_ps, _mm256_castsi256_ps, _mm256_cmpgt_epi32, _mm256_loadu_ps,
            _mm256_mul_ps, _mm256_set1_epi32, _mm256_setr_epi32, _mm256_setzero_ps, _mm256_sub_ps,
        };
        assert!(NC >= 1 && len.div_ceil(8) == NC && rows >= 1);
        assert!(t0 + (rows - 1) * ts + 8 * NC <= t.len());
        assert!(s0 + (rows - 1) * ss + 8 * NC <= s.len());
        // SAFETY: AVX2 is enabled (see `zero`); the asserts above keep every load of `8 * NC`
        // values per row inside the slices.
        unsafe {
            // The last chunk's lanes past `len` hold the next pixels' values: zeroing their
            // differences adds +0.0, as the masked loads of `add_row` do.
            let mask = _mm256_castsi256_ps(_mm256_cmpgt_epi32(
                _mm256_set1_epi32((len - 8 * (NC - 1)) as i32),
                _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
            ));
            let (tr, sr) = (t.as_ptr().add(t0), s.as_ptr().add(s0));
            let [mut a0, mut a1, mut a2] = [_mm256_setzero_ps(); 3];
            // Patch row k: chunk j into accumulator j mod 3.
            macro_rules! row {
                ($k:expr) => {
                    for j in 0..NC {
                        let mut d = _mm256_sub_ps(
                            _mm256_loadu_ps(tr.add($k * ts + 8 * j)),
                            _mm256_loadu_ps(sr.add($k * ss + 8 * j)),
                        );
                        if j + 1 == NC {
                            d = _mm256_and_ps(d, mask);
                        }
                        let sq = _mm256_mul_ps(d, d);
                        match j % 3 {
                            0 => a0 = _mm256_add_ps(a0, sq),
                            1 => a1 = _mm256_add_ps(a1, sq),
                            _ => a2 = _mm256_add_ps(a2, sq),
                        }
                    }
                };
            }
            row!(0);
            if rows > 1 {
                row!(1);
                if rows > 2 {
                    let partial = base + Self::total(&[a0, a1, a2]);
                    if partial >= cutoff {
                        return partial;
                    }
                    for k in 2..rows {
                        row!(k);
                    }
                }
            }
            base + Self::total(&[a0, a1, a2])
        }
    }

    #[inline(always)]
    fn total(acc: &Self::Acc) -> f32 {
        use std::arch::x86_64::{
            _mm256_add_ps, _mm256_castps256_ps128, _mm256_extractf128_ps, _mm_add_ps,
            _mm_cvtss_f32, _mm_shuffle_ps,
        };
        // SAFETY: AVX2 is enabled (see `zero`).
        unsafe {
            let v = _mm256_add_ps(_mm256_add_ps(acc[0], acc[1]), acc[2]);
            // (v0+v4, v1+v5, v2+v6, v3+v7), then (s0+s1) + (s2+s3) as in `Portable::total`.
            let s = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps::<1>(v));
            let s01 = _mm_cvtss_f32(_mm_add_ps(s, _mm_shuffle_ps::<0b01>(s, s)));
            let s23 = _mm_cvtss_f32(_mm_add_ps(
                _mm_shuffle_ps::<0b10>(s, s),
                _mm_shuffle_ps::<0b11>(s, s),
            ));
            s01 + s23
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    #[test]
    fn kernel_total_matches_naive_sum() {
        for n in [1usize, 5, 8, 13, 21, 24, 29, 50] {
            let a: Vec<f32> = (0..n).map(|i| i as f32 * 0.1).collect();
            let b: Vec<f32> = (0..n).map(|i| (i * i) as f32 * 0.01).collect();
            let naive: f32 = a.iter().zip(&b).map(|(x, y)| (x - y) * (x - y)).sum();
            let mut acc = Portable::zero();
            Portable::add_row(&mut acc, &a, &b);
            Portable::add_row(&mut acc, &b, &a);
            assert!(
                (Portable::total(&acc) - 2.0 * naive).abs() <= 1e-4 * naive.max(1.0),
                "n = {n}"
            );
        }
    }
    /// `Kernel::patch` with `NC` fixed, for every kernel, on the same data.
    fn patch_all<const NC: usize>(
        t: &[f32],
        s: &[f32],
        (rows, len): (usize, usize),
        (ts, ss): (usize, usize),
        (base, cutoff): (f32, f32),
    ) -> Vec<f32> {
        let args = ((1, ts), (2, ss), (rows, len));
        let mut out = vec![Portable::patch::<NC>(
            t, args.0, s, args.1, args.2, base, cutoff,
        )];
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            #[target_feature(enable = "avx2")]
            unsafe fn avx2<const NC: usize>(
                t: &[f32],
                s: &[f32],
                args: ((usize, usize), (usize, usize), (usize, usize)),
                base: f32,
                cutoff: f32,
            ) -> f32 {
                Avx2::patch::<NC>(t, args.0, s, args.1, args.2, base, cutoff)
            }
            // SAFETY: the CPU has AVX2 (checked above).
            out.push(unsafe { avx2::<NC>(t, s, args, base, cutoff) });
        }
        out
    }

    #[test]
    fn fixed_width_kernel_matches_row_by_row_sums() {
        // Rows of every length a fixed-width kernel takes, rows packed tightly (so the lanes
        // past a row's end hold the next row's values) and with slack, every cutoff regime.
        let mut rng = Rng::keyed(77, 0, 0);
        let mut val = || rng.below(1 << 20) as f32 / (1 << 16) as f32 - 8.0;
        for len in 1..=32 {
            for rows in [1, 2, 3, 7, 9] {
                for slack in [0, 5] {
                    let (ts, ss) = (len + slack, len + 2 * slack);
                    let t: Vec<f32> = (0..1 + rows * ts + PAD).map(|_| val()).collect();
                    let s: Vec<f32> = (0..2 + rows * ss + PAD).map(|_| val()).collect();
                    let mut acc = Portable::zero();
                    for k in 0..rows {
                        let (a, b) = (1 + k * ts, 2 + k * ss);
                        Portable::add_row(&mut acc, &t[a..a + len], &s[b..b + len]);
                    }
                    let full = 0.5 + Portable::total(&acc);
                    for cutoff in [f32::INFINITY, full, full * 0.5, 0.25] {
                        let ctx = (rows, len);
                        let got = match len.div_ceil(8) {
                            1 => patch_all::<1>(&t, &s, ctx, (ts, ss), (0.5, cutoff)),
                            2 => patch_all::<2>(&t, &s, ctx, (ts, ss), (0.5, cutoff)),
                            3 => patch_all::<3>(&t, &s, ctx, (ts, ss), (0.5, cutoff)),
                            _ => patch_all::<4>(&t, &s, ctx, (ts, ss), (0.5, cutoff)),
                        };
                        for d in &got {
                            if cutoff > full {
                                assert_eq!(d.to_bits(), full.to_bits(), "len {len} rows {rows}");
                            } else {
                                assert!(*d >= cutoff && *d <= full, "len {len} rows {rows}");
                            }
                        }
                        assert!(got.windows(2).all(|w| w[0].to_bits() == w[1].to_bits()));
                    }
                }
            }
        }
    }
}
