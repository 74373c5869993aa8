//! Boundary patches of label maps, packed into bits (Rosenberger et al. 2009, §3.6.1 of the
//! thesis). A `p × p` patch (`p ≤ 11`, so at most 121 pixels) of a map with `k` labels is
//! stored as `ceil(log2 k)` bit planes of one `u128` each: bit `dy·p + dx` of plane `j` is bit
//! `j` of the label at that offset. Two pixels differ when any plane differs, so the distance
//! of Eq. 3.7 (the number of differing pixels) is one `count_ones` of the OR of the planes'
//! XORs.

/// The largest supported patch side: `11 × 11 = 121` bits fit in a `u128`.
pub const MAX_PATCH: usize = 11;

/// The largest number of bit planes (`2^6 = 64` labels).
pub const MAX_PLANES: usize = 6;

/// A packed patch: `planes` bit planes, unused planes zero.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Patch(pub [u128; MAX_PLANES]);

/// Number of bit planes for `k` labels (`k ≥ 2`).
#[must_use]
pub fn planes_for(k: usize) -> usize {
    (usize::BITS - (k.max(2) - 1).leading_zeros()) as usize
}

/// The patch geometry: side, planes, wrap-around and the rotation permutation.
#[derive(Clone, Debug)]
pub struct Geometry {
    /// Patch side (odd, at most [`MAX_PATCH`]).
    pub p: usize,
    /// Bit planes per patch.
    pub planes: usize,
    /// `rot[i]`: the bit that lands on bit `i` after one 90° rotation.
    rot: Vec<u8>,
}

impl Geometry {
    /// The geometry of `p × p` patches over `k` labels.
    #[must_use]
    pub fn new(p: usize, k: usize) -> Self {
        let mut rot = vec![0u8; p * p];
        for dy in 0..p {
            for dx in 0..p {
                // Rotating by 90° clockwise: new (dy, dx) takes old (p-1-dx, dy).
                rot[dy * p + dx] = ((p - 1 - dx) * p + dy) as u8;
            }
        }
        Self {
            p,
            planes: planes_for(k),
            rot,
        }
    }

    /// All `p²` bits set.
    #[inline]
    #[must_use]
    pub fn full(&self) -> u128 {
        (1u128 << (self.p * self.p)) - 1
    }

    /// Number of differing pixels of two patches (the squared L2 distance of Eq. 3.7 for one
    /// rotation).
    #[inline]
    #[must_use]
    pub fn dist(&self, a: &Patch, b: &Patch) -> u32 {
        let mut m = 0u128;
        for j in 0..self.planes {
            m |= a.0[j] ^ b.0[j];
        }
        m.count_ones()
    }

    /// The label at offset `(dy, dx)` (`0 ≤ dy, dx < p`) of a patch.
    #[inline]
    #[must_use]
    pub fn label_at(&self, a: &Patch, bit: usize) -> u8 {
        let mut l = 0u8;
        for j in 0..self.planes {
            l |= (((a.0[j] >> bit) & 1) as u8) << j;
        }
        l
    }

    /// The set of pixels of a patch that carry `label`.
    #[inline]
    #[must_use]
    pub fn label_mask(&self, a: &Patch, label: u8) -> u128 {
        let mut m = self.full();
        for j in 0..self.planes {
            m &= if (label >> j) & 1 == 1 {
                a.0[j]
            } else {
                !a.0[j]
            };
        }
        m
    }

    /// The patch rotated by 90° clockwise.
    #[must_use]
    pub fn rotate(&self, a: &Patch) -> Patch {
        let mut out = Patch::default();
        for j in 0..self.planes {
            let src = a.0[j];
            if src == 0 {
                continue;
            }
            let mut v = 0u128;
            for (i, &r) in self.rot.iter().enumerate() {
                v |= ((src >> r) & 1) << i;
            }
            out.0[j] = v;
        }
        out
    }

    /// The patch of `map` (`h × w` labels) centred on `(y, x)`; outside pixels wrap around
    /// (`wrap`) or repeat the nearest border pixel.
    #[must_use]
    pub fn extract(&self, map: &[u8], h: usize, w: usize, y: usize, x: usize, wrap: bool) -> Patch {
        let p = self.p;
        let r = p / 2;
        let mut out = Patch::default();
        let interior = y >= r && x >= r && y + r < h && x + r < w;
        let mut cells = [0u8; MAX_PATCH];
        for dy in 0..p {
            let yy = if interior {
                y + dy - r
            } else {
                coord((y + dy) as isize - r as isize, h, wrap)
            };
            let row = &map[yy * w..(yy + 1) * w];
            if interior {
                cells[..p].copy_from_slice(&row[x - r..=x + r]);
            } else {
                for (dx, c) in cells[..p].iter_mut().enumerate() {
                    *c = row[coord((x + dx) as isize - r as isize, w, wrap)];
                }
            }
            // One row's bits of each plane at once (labels are below 2^planes).
            let shift = dy * p;
            for (j, plane) in out.0[..self.planes].iter_mut().enumerate() {
                let mut bits = 0u32;
                for (dx, &l) in cells[..p].iter().enumerate() {
                    bits |= u32::from((l >> j) & 1) << dx;
                }
                *plane |= u128::from(bits) << shift;
            }
            debug_assert!(cells[..p].iter().all(|&l| (l as usize) < 1 << self.planes));
        }
        out
    }
}

/// A coordinate wrapped around (`wrap`) or clamped into `0..n`.
#[inline]
#[must_use]
pub fn coord(v: isize, n: usize, wrap: bool) -> usize {
    if wrap {
        v.rem_euclid(n as isize) as usize
    } else {
        v.clamp(0, n as isize - 1) as usize
    }
}

/// Boundary pixels of a label map, in raster order: pixels with a 4-neighbour of another
/// label (neighbours across the border count only with `wrap`).
#[must_use]
pub fn boundary(map: &[u8], h: usize, w: usize, wrap: bool) -> Vec<u32> {
    let mut out = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let l = map[y * w + x];
            let mut differs = false;
            for (dy, dx) in [(-1isize, 0isize), (1, 0), (0, -1), (0, 1)] {
                let (yy, xx) = (y as isize + dy, x as isize + dx);
                let inside = yy >= 0 && xx >= 0 && (yy as usize) < h && (xx as usize) < w;
                if !inside && !wrap {
                    continue;
                }
                let (yy, xx) = (coord(yy, h, true), coord(xx, w, true));
                if map[yy * w + xx] != l {
                    differs = true;
                    break;
                }
            }
            if differs {
                out.push((y * w + x) as u32);
            }
        }
    }
    out
}

/// The other label of a boundary pixel: the most common differing 4-neighbour label (the
/// smallest on a tie).
#[must_use]
pub fn other_label(map: &[u8], h: usize, w: usize, y: usize, x: usize, wrap: bool) -> u8 {
    let l = map[y * w + x];
    let mut seen = [(0u8, 0u8); 4];
    let mut n = 0;
    for (dy, dx) in [(-1isize, 0isize), (1, 0), (0, -1), (0, 1)] {
        let (yy, xx) = (y as isize + dy, x as isize + dx);
        let inside = yy >= 0 && xx >= 0 && (yy as usize) < h && (xx as usize) < w;
        if !inside && !wrap {
            continue;
        }
        let m = map[coord(yy, h, true) * w + coord(xx, w, true)];
        if m == l {
            continue;
        }
        if let Some(s) = seen[..n].iter_mut().find(|s| s.0 == m) {
            s.1 += 1;
        } else {
            seen[n] = (m, 1);
            n += 1;
        }
    }
    seen[..n]
        .iter()
        .max_by(|a, b| a.1.cmp(&b.1).then(b.0.cmp(&a.0)))
        .map_or(l, |s| s.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn random_map(h: usize, w: usize, k: u64, seed: u64) -> Vec<u8> {
        let mut r = Rng::keyed(seed, 0, 0);
        (0..h * w).map(|_| r.below(k) as u8).collect()
    }

    fn naive_patch(
        map: &[u8],
        h: usize,
        w: usize,
        y: usize,
        x: usize,
        p: usize,
        wrap: bool,
    ) -> Vec<u8> {
        let r = (p / 2) as isize;
        let mut v = Vec::new();
        for dy in -r..=r {
            for dx in -r..=r {
                v.push(map[coord(y as isize + dy, h, wrap) * w + coord(x as isize + dx, w, wrap)]);
            }
        }
        v
    }

    fn naive_rot(a: &[u8], p: usize) -> Vec<u8> {
        let mut out = vec![0; p * p];
        for dy in 0..p {
            for dx in 0..p {
                out[dy * p + dx] = a[(p - 1 - dx) * p + dy];
            }
        }
        out
    }

    #[test]
    fn packed_distance_equals_naive_count_under_rotations() {
        for (k, p) in [(2u64, 11usize), (3, 7), (5, 5), (64, 11), (2, 1)] {
            let (h, w) = (17, 13);
            let a = random_map(h, w, k, 1);
            let b = random_map(h, w, k, 2);
            let g = Geometry::new(p, k as usize);
            for (y, x) in [(0, 0), (5, 7), (16, 12), (8, 0)] {
                for wrap in [false, true] {
                    let pa = g.extract(&a, h, w, y, x, wrap);
                    let pb = g.extract(&b, h, w, 12 - y.min(12), x / 2, wrap);
                    let na = naive_patch(&a, h, w, y, x, p, wrap);
                    let mut nb = naive_patch(&b, h, w, 12 - y.min(12), x / 2, p, wrap);
                    let mut rb = pb;
                    for _ in 0..4 {
                        let naive = na.iter().zip(&nb).filter(|(u, v)| u != v).count() as u32;
                        assert_eq!(g.dist(&pa, &rb), naive);
                        for (bit, &want) in nb.iter().enumerate() {
                            assert_eq!(g.label_at(&rb, bit), want);
                        }
                        rb = g.rotate(&rb);
                        nb = naive_rot(&nb, p);
                    }
                    assert_eq!(rb, pb, "four rotations are the identity");
                }
            }
        }
    }

    #[test]
    fn boundary_and_label_masks() {
        // A 4×4 map: left half 0, right half 1.
        let map = [0, 0, 1, 1, 0, 0, 1, 1, 0, 0, 1, 1, 0, 0, 1, 1];
        assert_eq!(boundary(&map, 4, 4, false), vec![1, 2, 5, 6, 9, 10, 13, 14]);
        assert_eq!(boundary(&map, 4, 4, true).len(), 16);
        assert_eq!(other_label(&map, 4, 4, 0, 1, false), 1);
        let g = Geometry::new(3, 2);
        let p = g.extract(&map, 4, 4, 1, 1, false);
        assert_eq!(g.label_mask(&p, 1).count_ones(), 3);
        assert_eq!(g.label_mask(&p, 0).count_ones(), 6);
        assert_eq!(planes_for(2), 1);
        assert_eq!(planes_for(3), 2);
        assert_eq!(planes_for(64), 6);
    }
}
