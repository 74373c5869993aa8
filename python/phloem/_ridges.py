"""Ridge filtering shared by the pipelines that look for thin lines: the branching trace
(vessels, rivers, cracks) and the leaves' scribble expansion (veins)."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]

# Weight of the gradient subtracted from the ridge curvature. Beside a step edge of height A,
# at distance u*sigma, the scale-normalised curvature is u*phi(u)*A and the gradient phi(u)*A
# (phi: the standard normal density): with weight 2 a step leaves at most 0.009*A, while at a
# ridge centre the gradient is zero and nothing is lost.
EDGE = 2.0


def hessian_eigs(gray: F32, sigma: float) -> tuple[F32, F32, F32]:
    """Scale-normalised Hessian eigenvalues ``l1 <= l2`` and gradient magnitude at ``sigma``."""
    g = cv2.GaussianBlur(gray, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    gy, gx = np.gradient(g)
    gyy, gyx = np.gradient(gy)
    gxx = np.gradient(gx, axis=1)
    s2 = np.float32(sigma * sigma)
    hxx, hyy, hxy = gxx * s2, gyy * s2, 0.5 * (gyx + np.gradient(gy, axis=1)) * s2
    half = 0.5 * (hxx + hyy)
    root = np.sqrt(0.25 * (hxx - hyy) ** 2 + hxy**2)
    grad = np.sqrt(gx * gx + gy * gy) * np.float32(sigma)
    return (half - root).astype(np.float32), (half + root).astype(np.float32), grad.astype(np.float32)


def ridge_response(gray: F32, sigmas: tuple[float, ...], polarity: str, *, subpixel: bool = False) -> F32:
    """Multi-scale ridge strength: the cross-ridge curvature minus the gradient, max over scales.

    For a bright ridge the curvature across it is the most negative Hessian eigenvalue ``l1``;
    for a dark one the most positive ``l2``. Subtracting twice the scale-normalised gradient
    magnitude (``EDGE``) suppresses the side lobes that a Hessian filter finds beside step edges
    (the rim of a retina photo, the border of a lit region): at a ridge centre the gradient
    vanishes, beside an edge it outweighs the curvature.

    The gradient vanishes at the ridge's centre, not at the nearest pixel centre: a line 1 px
    wide whose centre falls half a pixel off loses all its response at ``sigma = 1``.
    ``subpixel`` evaluates the filter on the image upsampled 2x (cubic; the scale-normalised
    response is the same function at doubled scales) and keeps each pixel's best of its four
    sub-positions, a quarter of a pixel from its centre.
    """
    if subpixel:
        h, w = gray.shape
        up = np.asarray(cv2.resize(gray, (2 * w, 2 * h), interpolation=cv2.INTER_CUBIC), np.float32)
        fine = ridge_response(up, tuple(2.0 * s for s in sigmas), polarity)
        return np.asarray(fine.reshape(h, 2, w, 2).max(axis=(1, 3)), np.float32)
    out = np.zeros_like(gray)
    for s in sigmas:
        l1, l2, grad = hessian_eigs(gray, s)
        curv = -l1 if polarity == "bright" else l2
        np.maximum(out, curv - EDGE * grad, out=out)
    return out


def ridge_polarity(gray: F32, sigmas: tuple[float, ...]) -> str:
    """``"bright"`` or ``"dark"``: which kind of ridge is stronger in the image."""
    s = sigmas[len(sigmas) // 2]
    l1, l2, grad = hessian_eigs(gray, s)
    bright = np.maximum(-l1 - EDGE * grad, 0)
    dark = np.maximum(l2 - EDGE * grad, 0)
    return "bright" if float(np.percentile(bright, 99)) > float(np.percentile(dark, 99)) else "dark"
