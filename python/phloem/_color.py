"""Colour as the thesis' label maps see it (Laitoch 2018, §3.5): 8-bit RGB, non-local-means
denoising, CIELAB. Shared by :mod:`phloem.bark` (building label maps) and :mod:`phloem.metrics`
(scoring outputs against them), so both see colour exactly alike."""

from __future__ import annotations

import math
import numbers
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray


def check_denoise(denoise: Any) -> None:
    """Reject a denoising strength that is not a finite real number >= 0."""
    if isinstance(denoise, bool) or not isinstance(denoise, numbers.Real) or not math.isfinite(denoise) or denoise < 0:
        raise ValueError(f"denoise: expected a finite strength >= 0, got {denoise!r}")


def rgb8(img: NDArray[np.float32]) -> NDArray[np.uint8]:
    """The first 3 channels (gray repeated) of a checked image as 8-bit RGB."""
    rgb = img[..., :3] if img.shape[2] >= 3 else np.repeat(img[..., :1], 3, axis=2)
    return np.clip(np.rint(rgb * 255), 0, 255).astype(np.uint8)


def denoised_lab(u8: NDArray[np.uint8], denoise: float) -> NDArray[np.float32]:
    """CIELAB of an 8-bit RGB image after non-local-means denoising of strength ``denoise``
    (0: none), as the thesis' label maps see colour (§3.5)."""
    bgr: Any = np.ascontiguousarray(u8[..., ::-1])
    if denoise > 0:
        bgr = cv2.fastNlMeansDenoisingColored(bgr, None, float(denoise), float(denoise), 7, 21)
    return np.asarray(cv2.cvtColor(bgr.astype(np.float32) / 255.0, cv2.COLOR_BGR2Lab), dtype=np.float32)
