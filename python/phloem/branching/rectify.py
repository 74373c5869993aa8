"""Perspective (Sibbing, Pavić, Kobbelt 2010, Fig. 8): :func:`rectify` warps a photo taken at an
angle, with its skeleton, by a user-given homography to a frontal view; synthesise there, then
:func:`unrectify` distorts the result back. Finding the homography is left to the user (four
point pairs and ``cv2.getPerspectiveTransform``).
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .._api import Size, renamed
from .._validate import as_image, check_size
from ._pixels import F32, F64, _by_channels, _check_skeleton
from .skeleton import Branch, Skeleton

__all__ = ["rectify", "unrectify"]


def _homography(homography: Any) -> F64:
    try:
        Hm = np.asarray(homography, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError("homography: expected a 3x3 matrix") from None
    if Hm.shape != (3, 3) or not np.isfinite(Hm).all():
        raise ValueError(f"homography: expected a finite 3x3 matrix, got shape {Hm.shape}")
    if abs(np.linalg.det(Hm)) < 1e-12:
        raise ValueError("homography: the matrix is singular")
    return Hm


def _apply(Hm: F64, pts: F64) -> F64:
    q = np.c_[pts, np.ones(len(pts))] @ Hm.T
    if (q[:, 2] <= 0).any():
        raise ValueError("homography: maps part of the image behind the camera (w <= 0)")
    return np.asarray(q[:, :2] / q[:, 2:], dtype=np.float64)


def rectify(image: Any, skeleton: Skeleton, homography: Any) -> tuple[F32, Skeleton, F64, NDArray[np.bool_]]:
    """Warp an image and its skeleton to a frontal view (Fig. 8 b) for :func:`render`.

    The output frame is the bounding box of the warped image. Skeleton points are mapped by
    the homography; thicknesses are scaled by the local linear scale ``sqrt |det J|`` of the
    map at each point.

    Parameters
    ----------
    image : (H, W[, C]) array_like
        The photo.
    skeleton : Skeleton
        Its structure, in the photo's pixels.
    homography : (3, 3) array_like
        Maps photo pixels ``(x, y, 1)`` to rectified ones.

    Returns
    -------
    rectified : (H', W', C) ndarray of float32
        The warped photo (0 outside the photo).
    skeleton : Skeleton
        The warped skeleton, with ``shape = (H', W')``.
    homography : (3, 3) ndarray
        The homography actually used (the given one followed by the shift into the frame);
        pass it to :func:`unrectify`.
    valid : (H', W') ndarray of bool
        Where the frame shows the photo; pass it as ``valid`` to :func:`render` so that the
        gap completion does not copy the empty corners.

    Examples
    --------
    >>> import numpy as np
    >>> from phloem.branching import Branch, Skeleton, rectify, unrectify
    >>> yy, xx = np.mgrid[:40, :60]
    >>> img = (0.5 + 0.4 * np.sin(xx / 7.0) * np.cos(yy / 5.0)).astype(np.float32)
    >>> sk = Skeleton([Branch([[5, 20], [55, 20]], 2.0)], (40, 60))
    >>> rect, rsk, Hm, valid = rectify(img, sk, [[2, 0, 0], [0, 2, 0], [0, 0, 1]])   # a 2x zoom
    >>> rect.shape, rsk.branches[0].thickness.tolist()
    ((80, 120, 1), [4.0, 4.0])
    >>> back = unrectify(rect, Hm, (40, 60))
    >>> bool(np.abs(back[2:-2, 2:-2, 0] - img[2:-2, 2:-2]).max() < 0.02)
    True
    """
    img = as_image(image, "image")
    sk = _check_skeleton(skeleton, "skeleton", img.shape[:2])
    Hm = _homography(homography)
    h, w = img.shape[:2]
    corners = _apply(Hm, np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]]))
    # Pixel j of the frame is centred at lo + j and the frame covers the warped image exactly.
    lo = corners.min(axis=0) + 0.5
    size = np.maximum(np.round(corners.max(axis=0) - corners.min(axis=0)), 1).astype(int)
    if size.max() > 32768:
        raise ValueError(f"homography: the rectified image would be {size[0]}x{size[1]} pixels")
    Hs = np.array([[1.0, 0.0, -lo[0]], [0.0, 1.0, -lo[1]], [0.0, 0.0, 1.0]]) @ Hm
    out = _by_channels(
        lambda part: cv2.warpPerspective(
            part, Hs, (int(size[0]), int(size[1])), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT
        ),
        img,
    )
    rect: F32 = np.ascontiguousarray(out, dtype=np.float32)
    ones = np.ones(img.shape[:2], np.uint8)
    valid = cv2.warpPerspective(ones, Hs, (int(size[0]), int(size[1])), flags=cv2.INTER_NEAREST) > 0
    branches = []
    for b in sk.branches:
        pts = _apply(Hs, b.points)
        # Local scale: the Jacobian of the projective map at each point, by central differences.
        e = 0.5
        dx = (_apply(Hs, b.points + [e, 0]) - _apply(Hs, b.points - [e, 0])) / (2 * e)
        dy = (_apply(Hs, b.points + [0, e]) - _apply(Hs, b.points - [0, e])) / (2 * e)
        scale = np.sqrt(np.abs(dx[:, 0] * dy[:, 1] - dx[:, 1] * dy[:, 0]))
        pts = np.clip(pts, -0.5, [size[0] - 0.5, size[1] - 0.5])
        branches.append(Branch(pts, b.thickness * scale, b.parent))
    return rect, Skeleton(branches, (int(size[1]), int(size[0]))), Hs, np.asarray(valid)


@renamed(shape="size")
def unrectify(image: Any, homography: Any, size: Size) -> F32:
    """Distort a result synthesised in the rectified frame back to the photo's view (Fig. 8 e).

    Parameters
    ----------
    image : (H', W'[, C]) array_like
        An image in the rectified frame (e.g. the output of :func:`render`).
    homography : (3, 3) array_like
        The homography returned by :func:`rectify`.
    size : int or (int, int)
        ``(H, W)`` of the output, in the photo's view (``shape`` before, deprecated).

    Returns
    -------
    (H, W, C) ndarray of float32
    """
    img = as_image(image, "image")
    Hm = _homography(homography)
    h, w = check_size(size)
    out = _by_channels(
        lambda part: cv2.warpPerspective(
            part, Hm, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_CONSTANT
        ),
        img,
    )
    return np.ascontiguousarray(out, dtype=np.float32)
