"""Premultiplied and straight alpha: leaves are straight-alpha RGBA, and every stage that
resamples or mixes them does it premultiplied, so transparent pixels never bleed into edges."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["premultiplied", "straight"]

F32 = NDArray[np.float32]


def premultiplied(rgba: Any) -> F32:
    """Straight-alpha ``(H, W, 4)`` RGBA with its colours multiplied by alpha (a new array)."""
    x = np.asarray(rgba, dtype=np.float32)
    out = np.empty(x.shape, np.float32)
    out[..., :3] = x[..., :3] * x[..., 3:4]
    out[..., 3] = x[..., 3]
    return out


def straight(pre: F32) -> F32:
    """Premultiplied RGBA back to straight alpha, clipped to [0, 1]; colour 0 where alpha is 0."""
    a = pre[..., 3:4]
    out = np.zeros_like(pre)
    np.divide(pre[..., :3], a, out=out[..., :3], where=a > 1e-6)
    out[..., :3] = np.clip(out[..., :3], 0.0, 1.0)
    out[..., 3] = np.clip(pre[..., 3], 0.0, 1.0)
    return out
