"""Pyramid helpers shared by texture synthesis and completion: area downsampling of images and
coherent upsampling of nearest-neighbour fields."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray


def downsample(img: NDArray[np.float32], shape: tuple[int, int]) -> NDArray[np.float32]:
    h, w = shape
    out = cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(out.reshape(h, w, img.shape[2]), dtype=np.float32)


def upsample_field(
    field: NDArray[np.int32], shape: tuple[int, int], src_shape: tuple[int, int], r: int
) -> NDArray[np.int32]:
    """Coherent upsampling of a field: pixel (y, x) inherits its parent's match, shifted by
    its position inside the parent, clamped to valid centres; ``-1`` stays ``-1``."""
    h, w = shape
    ys, xs = np.arange(h), np.arange(w)
    py = np.minimum(ys // 2, field.shape[0] - 1)
    px = np.minimum(xs // 2, field.shape[1] - 1)
    parent = field[py[:, None], px[None, :]]
    up = np.empty((h, w, 2), dtype=np.int32)
    up[..., 0] = np.clip(2 * parent[..., 0] + (ys - 2 * py)[:, None], r, src_shape[0] - 1 - r)
    up[..., 1] = np.clip(2 * parent[..., 1] + (xs - 2 * px)[None, :], r, src_shape[1] - 1 - r)
    up[parent[..., 0] < 0] = -1
    return up


def upsample_at(
    field: NDArray[np.int32], at: NDArray[np.bool_], src_shape: tuple[int, int], r: int, *, wrap: bool = False
) -> NDArray[np.int32]:
    """:func:`upsample_field` to ``at.shape`` computed only where ``at`` is true, ``-1``
    elsewhere: completion needs the field at its hole's patches only, so this costs the
    hole, not the image. With ``wrap`` the source is a torus whose every pixel is a centre:
    positions wrap around instead of being clamped."""
    ys, xs = np.nonzero(at)
    py = np.minimum(ys // 2, field.shape[0] - 1)
    px = np.minimum(xs // 2, field.shape[1] - 1)
    parent = field[py, px]
    up = np.full((*at.shape, 2), -1, dtype=np.int32)
    keep = parent[:, 0] >= 0
    ys, xs, py, px, parent = ys[keep], xs[keep], py[keep], px[keep], parent[keep]
    cy, cx = 2 * parent[:, 0] + (ys - 2 * py), 2 * parent[:, 1] + (xs - 2 * px)
    if wrap:
        up[ys, xs, 0], up[ys, xs, 1] = cy % src_shape[0], cx % src_shape[1]
    else:
        up[ys, xs, 0] = np.clip(cy, r, src_shape[0] - 1 - r)
        up[ys, xs, 1] = np.clip(cx, r, src_shape[1] - 1 - r)
    return up
