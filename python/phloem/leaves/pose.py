"""Posing exemplar leaves on the training leaf, and the canvas they all share.

Scans lie at any angle, either side up and at any scale, which TPS-RPM's annealing does not
undo; a similarity from the leaves' principal axes and areas brings each exemplar close to the
training leaf first, and registration does the rest.
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .._validate import as_image
from ._rgba import premultiplied, straight

__all__ = ["CANVAS_MARGIN", "canvas", "pose", "warp_rgba"]

F32 = NDArray[np.float32]

#: Transparent border (px) kept around the union of the posed leaves on the canvas.
CANVAS_MARGIN = 16
#: Side (px) at which the four half-turn/mirror candidates of a pose are compared.
_POSE_SIDE = 256


def _moments(alpha: NDArray[np.bool_]) -> tuple[NDArray[np.float64], float, float]:
    """Centroid ``(x, y)``, major-axis angle and area of a mask."""
    ys, xs = np.nonzero(alpha)
    c = np.array([xs.mean(), ys.mean()])
    dx, dy = xs - c[0], ys - c[1]
    theta = 0.5 * math.atan2(2.0 * float(np.mean(dx * dy)), float(np.mean(dx * dx) - np.mean(dy * dy)))
    return c, theta, float(len(xs))


def _similarity(c_from: NDArray[np.float64], c_to: NDArray[np.float64], angle: float, scale: float, mirror: bool,
                axis: float) -> NDArray[np.float64]:  # fmt: skip
    """2×3 matrix: mirror across the axis at ``axis`` through ``c_from``, rotate by ``angle``,
    scale, and move ``c_from`` onto ``c_to``."""
    ca, sa = math.cos(axis), math.sin(axis)
    to_axis = np.array([[ca, sa], [-sa, ca]])
    flip = np.diag([1.0, -1.0 if mirror else 1.0])
    cr, sr = math.cos(angle), math.sin(angle)
    rot = np.array([[cr, -sr], [sr, cr]])
    lin = scale * rot @ to_axis.T @ flip @ to_axis
    return np.hstack([lin, (c_to - lin @ c_from)[:, None]])


def warp_rgba(img: F32, m: NDArray[np.float64], size: tuple[int, int]) -> F32:
    """Straight-alpha RGBA resampled by an affine map onto a ``size`` canvas (premultiplied
    colours are interpolated, so transparent pixels do not bleed into the edge)."""
    out = cv2.warpAffine(
        premultiplied(img), m, (size[1], size[0]), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT
    )
    return np.ascontiguousarray(straight(np.asarray(out, np.float32)))


def pose(leaf: Any, training: Any) -> tuple[NDArray[np.float64], float]:
    """The similarity that puts ``leaf`` on ``training`` before non-rigid registration.

    The leaf's centroid goes onto the training leaf's, its area is scaled to the training
    leaf's, and its major axis is turned onto the training leaf's major axis; of the four ways
    to do that (a half turn, a mirror image) the one whose alpha overlaps the training leaf's
    most (IoU at 256 px) wins. Scans lie at any angle and either side up, which TPS-RPM's
    annealing does not undo.

    Parameters
    ----------
    leaf, training : (H, W, 4) array_like
        RGBA leaves (straight alpha).

    Returns
    -------
    matrix : (2, 3) ndarray of float64
        From ``leaf`` pixel ``(x, y, 1)`` to ``training`` pixel coordinates.
    scale : float
        The linear scale factor in it (the training leaf's size over the leaf's).
    """
    a_l = as_image(leaf, "leaf")[..., -1] > 0.5
    a_t = as_image(training, "training")[..., -1] > 0.5
    if not a_l.any() or not a_t.any():
        raise ValueError("leaf: the alpha channel is empty; expected a leaf")
    c_l, th_l, area_l = _moments(a_l)
    c_t, th_t, area_t = _moments(a_t)
    scale = math.sqrt(area_t / area_l)
    k = min(1.0, _POSE_SIDE / max(a_t.shape))
    small_t = cv2.resize(a_t.astype(np.float32), None, fx=k, fy=k, interpolation=cv2.INTER_AREA) > 0.5
    down = np.array([[k, 0, 0], [0, k, 0], [0, 0, 1.0]])
    best: tuple[float, NDArray[np.float64]] | None = None
    for mirror in (False, True):
        for half in (0.0, math.pi):
            m = _similarity(c_l, c_t, th_t - th_l + half, scale, mirror, th_l)
            ms = (down @ np.vstack([m, [0, 0, 1]]))[:2]
            w = cv2.warpAffine(a_l.astype(np.float32), ms, (small_t.shape[1], small_t.shape[0])) > 0.5
            iou = float((w & small_t).sum()) / max(1.0, float((w | small_t).sum()))
            if best is None or iou > best[0] + 1e-9:
                best = (iou, m)
    assert best is not None
    return best[1], scale


def canvas(leaves: list[F32], t: int) -> tuple[list[NDArray[np.float64]], list[float], tuple[int, int]]:
    """Each leaf's pose on one canvas and the canvas size ``(H, W)``: the 2×3 matrices from each
    leaf's pixels to the canvas (the training leaf ``t`` only moved by whole pixels), their
    scale factors, and a canvas that holds every posed leaf with :data:`CANVAS_MARGIN` to spare."""
    mats, scales = [], []
    for i, leaf in enumerate(leaves):
        if i == t:
            mats.append(np.array([[1.0, 0, 0], [0, 1.0, 0]]))
            scales.append(1.0)
        else:
            m, s = pose(leaf, leaves[t])
            mats.append(m)
            scales.append(s)
    lo = np.array([np.inf, np.inf])
    hi = -lo
    for i, (leaf, m) in enumerate(zip(leaves, mats)):
        if i == t:  # all of it: the scribbles drawn on it are placed whole
            ys, xs = np.array([0, leaf.shape[0] - 1]), np.array([0, leaf.shape[1] - 1])
        else:
            ys, xs = np.nonzero(leaf[..., 3] > 0)
        pts = np.array([[xs.min(), ys.min()], [xs.max(), ys.min()], [xs.min(), ys.max()], [xs.max(), ys.max()]], float)
        q = pts @ m[:, :2].T + m[:, 2]
        lo, hi = np.minimum(lo, q.min(axis=0)), np.maximum(hi, q.max(axis=0))
    shift = CANVAS_MARGIN - np.floor(lo)
    size = (int(np.ceil(hi[1] + shift[1])) + CANVAS_MARGIN + 1, int(np.ceil(hi[0] + shift[0])) + CANVAS_MARGIN + 1)
    for m in mats:
        m[:, 2] += shift
    return mats, scales, size
