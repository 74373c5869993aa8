"""Figures for branching structures: the input/output histograms of the paper's Fig. 7."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from .histograms import angle_histogram, histogram_distance, thickness_histogram
from .skeleton import Skeleton

__all__ = ["histogram_figure"]


def _panel(
    a: NDArray[np.float64], b: NDArray[np.float64], edges: NDArray[np.float64], title: str, w: int, h: int
) -> NDArray[np.uint8]:
    # Drawn in 8 bits: OpenCV draws text only on 8-bit images.
    img = np.full((h, w, 3), 255, np.uint8)
    top, bottom, left, right = 28, h - 26, 10, w - 10
    bins = len(a)
    peak = max(float(a.max()), float(b.max()), 1e-9)
    bw = (right - left) / bins
    for i in range(bins):
        x0 = left + i * bw
        for frac, col, off in ((a[i], (90, 90, 90), 0.08), (b[i], (217, 90, 25), 0.5)):
            y = bottom - (bottom - top) * frac / peak
            cv2.rectangle(img, (int(x0 + off * bw), int(y)), (int(x0 + (off + 0.42) * bw), bottom), col, -1)
    cv2.line(img, (left, bottom), (right, bottom), (0, 0, 0), 1)
    font = cv2.FONT_HERSHEY_SIMPLEX
    cv2.putText(img, title, (left, 18), font, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, f"{edges[0]:.2f}", (left, h - 8), font, 0.38, (0, 0, 0), 1, cv2.LINE_AA)
    label = f"{edges[-1]:.2f}"
    cv2.putText(img, label, (right - 8 * len(label), h - 8), font, 0.38, (0, 0, 0), 1, cv2.LINE_AA)
    return img


def histogram_figure(
    source: Skeleton, result: Skeleton, *, h: float, bins: int = 16, width: int = 720, height: int = 220
) -> NDArray[np.float32]:
    """Angle and thickness histograms of an input and a synthesised structure, side by side.

    Grey bars are the input's, orange bars the result's, both binned over the input's range
    (values outside go to the end bins), as in the paper's Fig. 7. The titles give the L1
    distance of the normalised histograms.

    Parameters
    ----------
    source, result : Skeleton
        Input and synthesised structure.
    h : float
        Resampling step before measuring angles (the bending model's ``h``).
    bins : int, optional
        Histogram bins (the paper uses 16).
    width, height : int, optional
        Size of the figure in pixels.

    Returns
    -------
    (height, width, 3) float32 ndarray

    Examples
    --------
    >>> from phloem.branching import synthetic_skeleton
    >>> sk = synthetic_skeleton(0)
    >>> histogram_figure(sk, sk, h=2.0).shape
    (220, 720, 3)
    """
    ha, ea = angle_histogram(source, bins, h=h)
    hb, _ = angle_histogram(result, bins, h=h, range=(float(ea[0]), float(ea[-1])))
    ta, et = thickness_histogram(source, bins, h=h)
    tb, _ = thickness_histogram(result, bins, h=h, range=(float(et[0]), float(et[-1])))
    half = width // 2
    left = _panel(ha, hb, ea, f"angle (rad)  L1 = {histogram_distance(ha, hb):.3f}", half, height)
    right = _panel(ta, tb, et, f"thickness (px)  L1 = {histogram_distance(ta, tb):.3f}", width - half, height)
    return np.concatenate([left, right], axis=1).astype(np.float32) / 255.0
