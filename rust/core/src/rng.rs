//! Counter-based random numbers: every pixel draws from its own stream, keyed by
//! `(seed, pass, pixel)`, so results never depend on how rayon splits the work.

/// `SplitMix64` finaliser: a strong 64-bit mixing function.
#[inline]
#[must_use]
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A small, fast generator (`SplitMix64` stream) seeded from a key.
#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
}

impl Rng {
    /// A generator for the stream `(seed, a, b)`.
    #[must_use]
    pub fn keyed(seed: u64, a: u64, b: u64) -> Self {
        let s = mix64(seed ^ mix64(a.wrapping_add(0x632B_E59B_D9B4_E019) ^ mix64(b)));
        Self { state: s }
    }

    /// The next 64 random bits.
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// A uniform integer in `0..n` (`n > 0`), by Lemire's multiply-shift.
    #[inline]
    pub fn below(&mut self, n: u64) -> u64 {
        debug_assert!(n > 0);
        ((u128::from(self.next_u64() >> 32) * u128::from(n)) >> 32) as u64
    }

    /// [`Self::below`] for `n` that fits in 32 bits: the same value, without the 128-bit
    /// product.
    #[inline]
    pub fn below_u32(&mut self, n: u32) -> u64 {
        debug_assert!(n > 0);
        ((self.next_u64() >> 32) * u64::from(n)) >> 32
    }

    /// A uniform integer in `lo..=hi`.
    #[inline]
    pub fn range_inclusive(&mut self, lo: i64, hi: i64) -> i64 {
        debug_assert!(lo <= hi);
        lo + self.below((hi - lo + 1) as u64) as i64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_reproducible_and_distinct() {
        let a: Vec<u64> = (0..4).map(|_| Rng::keyed(1, 2, 3).next_u64()).collect();
        assert!(a.windows(2).all(|w| w[0] == w[1]));
        assert_ne!(
            Rng::keyed(1, 2, 3).next_u64(),
            Rng::keyed(1, 2, 4).next_u64()
        );
        assert_ne!(
            Rng::keyed(1, 2, 3).next_u64(),
            Rng::keyed(2, 2, 3).next_u64()
        );
    }

    #[test]
    fn below_u32_is_below() {
        for n in [1u32, 2, 3, 7, 512, 65_535, 65_536, u32::MAX] {
            let (mut a, mut b) = (
                Rng::keyed(5, 6, u64::from(n)),
                Rng::keyed(5, 6, u64::from(n)),
            );
            for _ in 0..1000 {
                assert_eq!(a.below(u64::from(n)), b.below_u32(n));
            }
        }
    }

    #[test]
    fn below_is_in_range_and_roughly_uniform() {
        let mut r = Rng::keyed(7, 0, 0);
        let mut counts = [0u32; 5];
        for _ in 0..50_000 {
            let v = r.below(5);
            counts[v as usize] += 1;
        }
        for c in counts {
            assert!((9_000..11_000).contains(&c), "{counts:?}");
        }
        for _ in 0..1000 {
            let v = r.range_inclusive(-3, 3);
            assert!((-3..=3).contains(&v));
        }
    }
}
