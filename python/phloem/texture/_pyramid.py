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
    up, orphan = _upsample_dense(field, shape, src_shape, r, wrap=False)
    up[orphan] = -1
    return up


def _upsample_dense(
    field: NDArray[np.int32], shape: tuple[int, int], src_shape: tuple[int, int], r: int, *, wrap: bool
) -> tuple[NDArray[np.int32], NDArray[np.bool_]]:
    """:func:`upsample_field` at every pixel, and where the parent had no match (``-1``, left
    for the caller to set). Parents are repeated, not gathered, and the arithmetic stays in
    int32 (positions fit it), which is several times faster on a large level."""
    h, w = shape
    fh, fw = field.shape[:2]
    parent = np.repeat(np.repeat(field, 2, axis=0), 2, axis=1)
    # a level one pixel larger than twice its parent repeats the parent's last row or column
    parent = np.pad(parent, ((0, max(h - 2 * fh, 0)), (0, max(w - 2 * fw, 0)), (0, 0)), mode="edge")[:h, :w]
    ys, xs = np.arange(h), np.arange(w)
    oy = (ys - 2 * np.minimum(ys // 2, fh - 1)).astype(np.int32)
    ox = (xs - 2 * np.minimum(xs // 2, fw - 1)).astype(np.int32)
    up = np.empty((h, w, 2), dtype=np.int32)
    np.multiply(parent[..., 0], 2, out=up[..., 0])
    np.multiply(parent[..., 1], 2, out=up[..., 1])
    up[..., 0] += oy[:, None]
    up[..., 1] += ox[None, :]
    if wrap:
        up[..., 0] %= src_shape[0]
        up[..., 1] %= src_shape[1]
    else:
        np.clip(up[..., 0], r, src_shape[0] - 1 - r, out=up[..., 0])
        np.clip(up[..., 1], r, src_shape[1] - 1 - r, out=up[..., 1])
    return up, parent[..., 0] < 0


# Above this share of the image, computing ``upsample_at`` everywhere and masking is cheaper
# than gathering the ``at`` pixels one by one (docs/engines/completion.md, "Large holes").
DENSE_SHARE = 0.1


def upsample_at(
    field: NDArray[np.int32], at: NDArray[np.bool_], src_shape: tuple[int, int], r: int, *, wrap: bool = False
) -> NDArray[np.int32]:
    """:func:`upsample_field` to ``at.shape`` computed only where ``at`` is true, ``-1``
    elsewhere: completion needs the field at its hole's patches only, so this costs the
    hole, not the image. With ``wrap`` the source is a torus whose every pixel is a centre:
    positions wrap around instead of being clamped."""
    if at.mean() >= DENSE_SHARE:
        up, orphan = _upsample_dense(field, at.shape, src_shape, r, wrap=wrap)
        up[~at | orphan] = -1
        return up
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
