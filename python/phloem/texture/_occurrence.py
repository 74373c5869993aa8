"""The occurrence penalty of Kaspar et al. 2015, shared by texture synthesis and completion."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray


def occurrence_cost(
    matches: NDArray[np.int32], src_shape: tuple[int, int], p: int, lam: float, scale: float, usable: int
) -> NDArray[np.float32]:
    """How much more than uniformly each source patch is covered by ``matches`` (source centres,
    shape ``(N, 2)``, row and column), times ``lam`` and ``scale`` (the median patch distance).

    Uniform use spreads the ``N`` matched patches over the ``usable`` source centres.
    """
    sh, sw = src_shape
    matches = matches[matches[:, 0] >= 0]
    if not len(matches):
        return np.zeros(src_shape, np.float32)
    centres = np.bincount((matches[:, 0] * sw + matches[:, 1]).ravel(), minlength=sh * sw).reshape(sh, sw)
    # Pixels covered: each used centre covers its p×p patch; a candidate's occurrence is the
    # mean coverage over its own patch (two box filters).
    cover = cv2.boxFilter(centres.astype(np.float32), -1, (p, p), normalize=False, borderType=cv2.BORDER_CONSTANT)
    mean_cover = cv2.boxFilter(cover, -1, (p, p), normalize=True, borderType=cv2.BORDER_CONSTANT)
    expected = len(matches) * p * p / max(usable, 1)
    over = np.maximum(mean_cover / expected - 1.0, 0.0)
    return np.ascontiguousarray(lam * max(scale, 1e-8) * over, dtype=np.float32)
