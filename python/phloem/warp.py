"""Image warps between contours by mean value coordinates.

Mean value coordinates (Hormann & Floater 2006) express any point of the plane as an affine
combination of the vertices of a simple polygon, concave or not, inside or outside it. Giving
the same coordinates to the vertices of a second polygon maps the first onto the second: the
colour transfer of Argudo et al. (2017, §5.2) that fills a new tree contour with the pixels of
one or more exemplars. Everything runs in phloem's Rust core (parallel over rows, GIL
released, the same result for any number of threads).

Contours are ``(N, 2)`` arrays of ``(x, y)`` points, as OpenCV returns them: ``x`` is the
column and ``y`` the row, and pixel ``(row, col)`` has its centre at ``(x, y) = (col, row)``.
A contour is closed implicitly; do not repeat its first point at the end.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from . import _core
from ._api import Size
from ._validate import as_image, as_mask, check_convex_weights, check_size, check_threads, restore_ndim

__all__ = ["mvc", "mvc_combine", "mvc_weights"]


def _points(points: Any, name: str, *, polygon: bool) -> NDArray[np.float64]:
    arr = np.asarray(points)
    if arr.dtype == np.bool_ or not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise TypeError(f"{name}: expected real (x, y) coordinates, got dtype {arr.dtype}")
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"{name}: expected shape (N, 2) of (x, y) points, got {arr.shape}")
    out = np.ascontiguousarray(arr, dtype=np.float64)
    bad = ~np.isfinite(out).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"{name}: expected finite coordinates, found {tuple(out[i].tolist())} at point {i}")
    if polygon:
        if len(out) < 3:
            raise ValueError(f"{name}: expected at least 3 points, got {len(out)}")
        same = (out == np.roll(out, -1, axis=0)).all(axis=1)
        if same.any():
            i = int(np.argmax(same))
            raise ValueError(
                f"{name}: points {i} and {(i + 1) % len(out)} are equal {tuple(out[i].tolist())}; "
                "consecutive points must differ (do not repeat the first point at the end)"
            )
        rel = out - out[0]
        area2 = np.sum(rel[:-1, 0] * rel[1:, 1] - rel[:-1, 1] * rel[1:, 0])
        if abs(area2) <= 1e-12 * np.abs(rel).max() ** 2:
            raise ValueError(
                f"{name}: expected a polygon with non-zero area, got a degenerate one (all points on a line)"
            )
    return out


def _sources(
    images: Sequence[Any],
    source_contours: Sequence[Any],
    target_contour: Any,
    size: Any,
    *,
    single: bool = False,
) -> tuple[list[NDArray[np.float32]], list[NDArray[np.float64]], NDArray[np.float64], tuple[int, int]]:
    if isinstance(images, np.ndarray) or not isinstance(images, Sequence) or len(images) == 0:
        raise TypeError("images: expected a non-empty list of images")

    def image_name(k: int) -> str:
        return "image" if single else f"images[{k}]"

    def contour_name(k: int) -> str:
        return "source_contour" if single else f"source_contours[{k}]"

    imgs = [as_image(im, image_name(k)) for k, im in enumerate(images)]
    for k, im in enumerate(imgs):
        if im.shape[2] != imgs[0].shape[2]:
            raise ValueError(f"images[{k}]: expected {imgs[0].shape[2]} channels like images[0], got {im.shape[2]}")
    if isinstance(source_contours, np.ndarray) and source_contours.ndim == 3:
        source_contours = list(source_contours)
    if not isinstance(source_contours, Sequence) or len(source_contours) != len(imgs):
        n = len(source_contours) if isinstance(source_contours, Sequence) else type(source_contours).__name__
        raise ValueError(f"source_contours: expected one contour per image ({len(imgs)}), got {n}")
    target = _points(target_contour, "target_contour", polygon=True)
    conts = [_points(c, contour_name(k), polygon=True) for k, c in enumerate(source_contours)]
    for k, c in enumerate(conts):
        if len(c) != len(target):
            raise ValueError(f"{contour_name(k)}: expected {len(target)} points like target_contour, got {len(c)}")
    return imgs, conts, target, check_size(size)


def mvc_weights(polygon: Any, points: Any, *, threads: int | None = None) -> NDArray[np.float64]:
    """Mean value coordinates of ``points`` with respect to ``polygon``.

    For a point ``x`` off the polygon, with ``s_i = v_i − x``, ``r_i = |s_i|`` and ``α_i`` the
    signed angle between ``s_i`` and ``s_{i+1}``, the coordinates are ``λ_i = w_i / Σ_j w_j``
    with ``w_i = (tan(α_{i−1}/2) + tan(α_i/2)) / r_i`` (Hormann & Floater 2006, Eq. 6). They
    are defined everywhere in the plane, for concave polygons too, sum to one and reproduce
    linear functions: ``Σ_i λ_i v_i = x``. Inside a convex polygon they are positive;
    elsewhere some are negative. On a vertex they are 1 there and 0 elsewhere; on an edge
    they interpolate its two ends linearly. Computed in float64.

    Parameters
    ----------
    polygon : (N, 2) array_like
        Vertices ``(x, y)`` of a simple polygon in order (either orientation), N >= 3, no two
        consecutive ones equal, non-zero area. Closed implicitly.
    points : (P, 2) array_like
        Points ``(x, y)``.
    threads : int, optional
        Worker threads (default: ``PHLOEM_NUM_THREADS`` or all cores).

    Returns
    -------
    weights : (P, N) ndarray of float64
        ``weights[p, i]`` is the coordinate of ``points[p]`` for vertex ``i``.

    References
    ----------
    .. [1] K. Hormann, M. S. Floater, "Mean value coordinates for arbitrary planar polygons",
       ACM TOG 25(4), 2006.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> square = [(0, 0), (2, 0), (2, 2), (0, 2)]
    >>> w = phloem.warp.mvc_weights(square, [(1, 1), (1, 0), (5, 3)])
    >>> w[0].round(6).tolist(), w[1].tolist()
    ([0.25, 0.25, 0.25, 0.25], [0.5, 0.5, 0.0, 0.0])
    >>> bool(np.allclose(w @ np.array(square, float), [(1, 1), (1, 0), (5, 3)]))
    True
    """
    poly = _points(polygon, "polygon", polygon=True)
    pts = _points(points, "points", polygon=False)
    return _core.mvc_weights(poly, pts, threads=check_threads(threads))


def mvc(
    image: Any,
    source_contour: Any,
    target_contour: Any,
    size: Size | None = None,
    *,
    region: Any = None,
    threads: int | None = None,
) -> NDArray[np.float32]:
    """Warp ``image`` so that ``source_contour`` lands on ``target_contour``.

    Each pixel ``x`` of the result gets the mean value coordinates ``λ(x)`` of its centre
    with respect to ``target_contour`` and takes the colour of ``image`` at
    ``q = Σ_i λ_i(x) s_i``, ``s`` the source contour, interpolated bilinearly (Argudo et al.
    2017, §5.2). The map sends the target contour onto the source contour piecewise linearly
    and reproduces affine maps exactly. It is defined outside the contour too. Where ``q``
    falls outside ``image`` (beyond half a pixel past its border) the result is 0 in every
    channel, i.e. transparent for RGBA images. Computed per pixel in float32 lanes, with
    pixels on or very near the target contour redone in float64; the positions are
    accurate to about 1e-3 px.

    Parameters
    ----------
    image : (M, N[, C]) array_like
        Source image; RGBA to carry transparency. Integer images are scaled to [0, 1].
    source_contour : (K, 2) array_like
        ``(x, y)`` contour in ``image`` (x = column, y = row; as OpenCV contours).
    target_contour : (K, 2) array_like
        The matching contour in the result, with the same number of points.
    size : int or (int, int), optional
        (height, width) of the result (default: the size of ``image``).
    region : (H, W) bool array_like, optional
        Compute only these pixels of the result; the others are 0 (and cost nothing).
    threads : int, optional
        Worker threads (default: ``PHLOEM_NUM_THREADS`` or all cores).

    Returns
    -------
    warped : (H, W[, C]) ndarray of float32
        The warped image, 2-D when ``image`` is.

    References
    ----------
    .. [1] O. Argudo, C. Andujar, A. Chica, "Tree variations", CEIG 2017, §5.2.
    .. [2] K. Hormann, M. S. Floater, "Mean value coordinates for arbitrary planar polygons",
       ACM TOG 25(4), 2006.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> img = np.arange(48, dtype=np.float32).reshape(6, 8)
    >>> src = [(1, 1), (5, 1), (5, 4), (1, 4)]
    >>> dst = [(2, 1), (6, 1), (6, 4), (2, 4)]        # one column to the right
    >>> out = phloem.warp.mvc(img, src, dst)
    >>> bool(np.array_equal(out[:, 1:], img[:, :-1]))
    True
    """
    hw = np.shape(image)[:2] if size is None else size
    imgs, conts, target, hw = _sources([image], [source_contour], target_contour, hw, single=True)
    reg = None if region is None else as_mask(region, "region", hw)
    out = _core.mvc_warp(imgs, conts, target, hw, region=reg, threads=check_threads(threads))[0]
    return restore_ndim(out, image)


def mvc_combine(
    images: Sequence[Any],
    source_contours: Sequence[Any],
    target_contour: Any,
    weights: Any,
    size: Size,
    *,
    region: Any = None,
    threads: int | None = None,
) -> NDArray[np.float32]:
    """Fill ``target_contour`` from several images at once (Argudo et al. 2017, §5.2).

    Every image is warped as :func:`mvc` does, from its own contour onto ``target_contour``;
    then, per pixel, the alpha (last channel) is the largest alpha of the warped images and
    the colour is ``Σ ω_k c_k / Σ ω_k`` over the images whose warped alpha is above zero there
    (``ω`` = ``weights``; if all of those have weight 0, their plain mean). Where every image
    is transparent the pixel is 0. The paper draws ``weights`` at random; pass them in.

    Parameters
    ----------
    images : sequence of (M_k, N_k, C) array_like
        Source images with the same number of channels ``C >= 2``, alpha last (RGBA).
    source_contours : sequence of (K, 2) array_like
        One ``(x, y)`` contour per image, all with the same number of points.
    target_contour : (K, 2) array_like
        The contour of the result.
    weights : (len(images),) array_like
        Non-negative colour weights summing to 1.
    size : int or (int, int)
        (height, width) of the result.
    region : (H, W) bool array_like, optional
        Compute only these pixels of the result; the others are 0 (and cost nothing).
    threads : int, optional
        Worker threads (default: ``PHLOEM_NUM_THREADS`` or all cores).

    Returns
    -------
    combined : (H, W, C) ndarray of float32

    References
    ----------
    .. [1] O. Argudo, C. Andujar, A. Chica, "Tree variations", CEIG 2017, §5.2.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> red = np.zeros((32, 32, 4), np.float32); red[..., 0] = 1; red[..., 3] = 1.0
    >>> blue = np.zeros((32, 32, 4), np.float32); blue[..., 2] = 1; blue[..., 3] = 0.5
    >>> c = [(4, 4), (27, 4), (27, 27), (4, 27)]
    >>> out = phloem.warp.mvc_combine([red, blue], [c, c], c, [0.25, 0.75], 32)
    >>> out[16, 16].tolist()
    [0.25, 0.0, 0.75, 1.0]
    """
    imgs, conts, target, hw = _sources(images, source_contours, target_contour, size)
    if imgs[0].shape[2] < 2:
        raise ValueError(
            f"images: expected colour channels and a last alpha channel (C >= 2), got C = {imgs[0].shape[2]}"
        )
    w = check_convex_weights(weights, len(imgs))
    reg = None if region is None else as_mask(region, "region", hw)
    return _core.mvc_combine(imgs, conts, target, w, hw, region=reg, threads=check_threads(threads))
