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
