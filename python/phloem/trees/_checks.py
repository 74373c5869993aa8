"""Argument checks and array aliases shared by the :mod:`phloem.trees` modules."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._validate import as_image, as_mask, check_float

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]
Mask = NDArray[np.bool_]


def as_rgba(rgba: Any, name: str = "rgba") -> F32:
    """``rgba`` as a float32 image that must have four channels."""
    img = as_image(rgba, name)
    if img.shape[2] != 4:
        raise ValueError(f"{name}: expected an RGBA image with 4 channels, got {img.shape[2]}")
    return img


def check_alpha_threshold(alpha_threshold: Any) -> float:
    """An alpha threshold in (0, 1]."""
    t = check_float(alpha_threshold, "alpha_threshold", 0.0, inclusive=False)
    if t > 1.0:
        raise ValueError(f"alpha_threshold: expected a value in (0, 1], got {alpha_threshold}")
    return t


def as_points(points: Any, name: str) -> F64:
    """A C-contiguous (N, 2) float64 array of finite ``(x, y)`` points, N >= 1."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 1:
        raise ValueError(f"{name}: expected an (N, 2) array of (x, y) points, got shape {p.shape}")
    if not np.isfinite(p).all():
        raise ValueError(f"{name}: expected finite coordinates")
    return np.ascontiguousarray(p)


def as_alpha_mask(alpha: Any, alpha_threshold: float) -> Mask:
    """The opaque pixels of a bool mask, an (H, W) alpha channel or an RGBA image."""
    arr = np.asarray(alpha)
    if arr.dtype == np.bool_:
        return as_mask(arr, "alpha", arr.shape[:2])
    img = as_image(arr, "alpha")
    if img.shape[2] == 4:
        img = img[..., 3:]
    if img.shape[2] != 1:
        raise ValueError(f"alpha: expected an (H, W) alpha channel or an RGBA image, got {img.shape[2]} channels")
    return np.ascontiguousarray(img[..., 0] >= alpha_threshold)
