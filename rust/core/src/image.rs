//! A borrowed, C-contiguous `H×W×C` `f32` image: the one layout every kernel works on.

use crate::error::{invalid, Result};
use ndarray::ArrayView3;

/// A read-only image view: `data[(y * w + x) * c + k]`.
#[derive(Clone, Copy, Debug)]
pub struct Image<'a> {
    /// Pixel values, row-major, channels interleaved.
    pub data: &'a [f32],
    /// Height in pixels.
    pub h: usize,
    /// Width in pixels.
    pub w: usize,
    /// Channels per pixel.
    pub c: usize,
}

impl<'a> Image<'a> {
    /// Wraps a slice; checks that its length is `h * w * c` and that no dimension is zero.
    pub fn new(name: &'static str, data: &'a [f32], h: usize, w: usize, c: usize) -> Result<Self> {
        if h == 0 || w == 0 || c == 0 {
            return Err(invalid(
                name,
                format!("expected a non-empty image, got shape ({h}, {w}, {c})"),
            ));
        }
        if data.len() != h * w * c {
            return Err(invalid(
                name,
                format!(
                    "buffer of {} values does not hold ({h}, {w}, {c})",
                    data.len()
                ),
            ));
        }
        Ok(Self { data, h, w, c })
    }

    /// Borrows a standard-layout ndarray view (call `as_standard_layout` first if unsure).
    pub fn from_view(name: &'static str, view: &ArrayView3<'a, f32>) -> Result<Self> {
        let (h, w, c) = view.dim();
        let data = view
            .to_slice()
            .ok_or_else(|| invalid(name, "expected a C-contiguous array"))?;
        Self::new(name, data, h, w, c)
    }

    /// The `c` values of pixel `(y, x)`.
    #[inline]
    #[must_use]
    pub fn pixel(&self, y: usize, x: usize) -> &'a [f32] {
        let o = (y * self.w + x) * self.c;
        &self.data[o..o + self.c]
    }

    /// Fails with a message naming `name` if any value is NaN or infinite.
    pub fn check_finite(&self, name: &'static str) -> Result<()> {
        if let Some(i) = self.data.iter().position(|v| !v.is_finite()) {
            let p = i / self.c;
            return Err(invalid(
                name,
                format!(
                    "expected finite values, found {} at pixel (row {}, col {})",
                    self.data[i],
                    p / self.w,
                    p % self.w
                ),
            ));
        }
        Ok(())
    }
}

/// Multiplies every channel by `sqrt(weight)`, so a plain sum of squared differences of the
/// result equals the weighted one of the original. Returns an owned buffer.
pub fn prescale(img: &Image<'_>, weights: Option<&[f32]>) -> Result<Vec<f32>> {
    let Some(wts) = weights else {
        return Ok(img.data.to_vec());
    };
    if wts.len() != img.c {
        return Err(invalid(
            "weights",
            format!("expected {} per-channel weights, got {}", img.c, wts.len()),
        ));
    }
    if let Some(bad) = wts.iter().find(|v| !v.is_finite() || **v < 0.0) {
        return Err(invalid(
            "weights",
            format!("expected finite non-negative weights, got {bad}"),
        ));
    }
    let s: Vec<f32> = wts.iter().map(|v| v.sqrt()).collect();
    Ok(img
        .data
        .chunks_exact(img.c)
        .flat_map(|px| px.iter().zip(&s).map(|(v, k)| v * k))
        .collect())
}

/// The `h × w × c` buffer `data` mirrored by `r` pixels on every side, without repeating the
/// edge (`abcd` → `cb|abcd|cb` for r = 2).
pub(crate) fn mirror_pad(data: &[f32], h: usize, w: usize, c: usize, r: usize) -> Vec<f32> {
    pad_with(data, h, w, c, r, |i, n| {
        if n == 1 {
            return 0;
        }
        let n = n as i64;
        let mut i = i;
        // Mirror without repeating the edge pixel; loop covers r >= n.
        while i < 0 || i >= n {
            i = if i < 0 { -i } else { 2 * (n - 1) - i };
        }
        i as usize
    })
}

/// The `h × w × c` buffer `data` grown by `r` pixels on every side, the pixel at padded
/// `(y, x)` copied from `(at(y − r, h), at(x − r, w))`.
pub(crate) fn pad_with(
    data: &[f32],
    h: usize,
    w: usize,
    c: usize,
    r: usize,
    at: impl Fn(i64, usize) -> usize,
) -> Vec<f32> {
    let (ph, pw) = (h + 2 * r, w + 2 * r);
    let mut out = Vec::with_capacity(ph * pw * c);
    for y in 0..ph {
        let sy = at(y as i64 - r as i64, h);
        for x in 0..pw {
            let sx = at(x as i64 - r as i64, w);
            out.extend_from_slice(&data[(sy * w + sx) * c..][..c]);
        }
    }
    out
}

/// The `r`-pixel border of a `h × w × c` buffer made by wrapping around.
pub(crate) fn wrap_pad(data: &[f32], h: usize, w: usize, c: usize, r: usize) -> Vec<f32> {
    pad_with(data, h, w, c, r, |i, n| i.rem_euclid(n as i64) as usize)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mirror_pad_reflects_without_repeating_the_edge() {
        let d = [1f32, 2., 3., 4.];
        let p = mirror_pad(&d, 1, 4, 1, 2);
        // Rows also mirror: a 1-row image mirrors onto itself.
        assert_eq!(&p[2 * 8..3 * 8], &[3., 2., 1., 2., 3., 4., 3., 2.]);
    }
}
