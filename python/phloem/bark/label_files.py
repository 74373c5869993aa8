"""Label maps as images of flat grey levels, for writing and editing by hand (thesis §3.2)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._validate import as_image, as_labels

__all__ = ["decode_labels", "encode_labels"]


def encode_labels(labels: Any) -> NDArray[np.float32]:
    """A label map as an evenly spaced grey image in [0, 1], for writing and hand editing.

    Label ``j`` of the sorted distinct labels ``v_0 < … < v_{n-1}`` becomes ``j / (n - 1)``.
    :func:`decode_labels` reverses it (up to renumbering the labels ``0 … n-1``).
    """
    lab = as_labels(labels, "labels")
    values, inv = np.unique(lab, return_inverse=True)
    n = len(values)
    return (inv.reshape(lab.shape) / max(n - 1, 1)).astype(np.float32)


def decode_labels(image: Any, *, max_labels: int = 16) -> NDArray[np.int32]:
    """A label map from an image of flat colours or grey levels: ``0 … n-1`` by sorted colour.

    Raises ``ValueError`` if the image has more than ``max_labels`` distinct colours (an
    anti-aliased brush or a JPEG, most likely) or values outside [0, 1].
    """
    img = as_image(image, "image")
    lo, hi = float(img.min()), float(img.max())
    if lo < 0 or hi > 1:
        # outside [0, 1] the 8-bit channel keys below overlap: two colours would share a label
        raise ValueError(f"image: expected values in [0, 1] (a label map image), got {lo:g} to {hi:g}")
    q = np.rint(img * 255).astype(np.int64)
    key = np.zeros(img.shape[:2], np.int64)
    for c in range(img.shape[2]):
        key = key * 256 + q[..., c]
    values, inv = np.unique(key, return_inverse=True)
    if len(values) > max_labels:
        raise ValueError(
            f"image: found {len(values)} distinct colours, expected a label map of at most {max_labels} flat colours "
            "(paint with a hard brush and save as PNG)"
        )
    return inv.reshape(img.shape[:2]).astype(np.int32)
