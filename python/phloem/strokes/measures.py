"""Measures of an edit against its strokes (Luo et al.'s aims, as numbers): does the result
cover each target stroke, and is it as wide across the target stroke as the object is across
the corresponding source stroke. Re-exported by :mod:`phloem.metrics`."""

from __future__ import annotations

from typing import Any, Final

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage  # type: ignore[import-untyped]

from .._validate import as_image, check_int
from .stroke_set import Stroke, StrokeSet

__all__ = ["stroke_coverage", "stroke_widths", "width_agreement"]

F64 = NDArray[np.float64]
#: Step of the march across a stroke that measures the object's width, px.
_STEP: Final = 0.5


def _alpha(image: Any, name: str) -> NDArray[np.float32]:
    img = as_image(image, name)
    if img.shape[2] not in (1, 2, 4):
        raise ValueError(
            f"{name}: expected an alpha channel (RGBA, gray + alpha) or a mask, got {img.shape[2]} channels"
        )
    return np.ascontiguousarray(img[..., -1])


def _check_set(strokes: Any) -> StrokeSet:
    if not isinstance(strokes, StrokeSet):
        raise TypeError(f"strokes: expected a phloem.strokes.StrokeSet, got {type(strokes).__name__}")
    return strokes


def stroke_coverage(image: Any, strokes: Any) -> float:
    """Fraction of the target strokes' points (one per px of arc, the ends included) where ``image`` is
    opaque (alpha ≥ ½). 1 when the result covers every target stroke.

    Parameters
    ----------
    image : (H, W, 4), (H, W, 2) or (H, W) array_like
        The result (its alpha, the last channel) or a mask.
    strokes : StrokeSet

    Examples
    --------
    >>> import numpy as np, phloem
    >>> from phloem.strokes import StrokeSet
    >>> out = np.zeros((20, 40)); out[5:15, :20] = 1
    >>> phloem.metrics.stroke_coverage(out, StrokeSet.from_lists([[[0, 0], [9, 0]]], [[[0, 10], [39, 10]]]))
    0.5
    """
    alpha = _alpha(image, "image")
    h, w = alpha.shape
    hit = total = 0
    for p in _check_set(strokes).pairs:
        n = int(np.ceil(p.target.length())) + 1
        pts = p.target.at(np.linspace(0.0, 1.0, n))
        xi = np.clip(np.floor(pts[:, 0] + 0.5).astype(int), 0, w - 1)
        yi = np.clip(np.floor(pts[:, 1] + 0.5).astype(int), 0, h - 1)
        hit += int((alpha[yi, xi] >= 0.5).sum())
        total += n
    return hit / total


def stroke_widths(alpha: Any, stroke: Stroke, u: Any, *, max_width: float | None = None) -> F64:
    """Width of the opaque region (alpha ≥ ½, bilinear) across ``stroke`` at arc-length
    fractions ``u``: the reach along the normal to either side, summed; 0 where the stroke's
    point itself is not opaque.

    Parameters
    ----------
    alpha : (H, W) array_like
        Alpha or mask.
    stroke : Stroke
    u : (n,) array_like
        Arc-length fractions.
    max_width : float, optional
        Most measured to either side (default: the image's diagonal).
    """
    a = _alpha(alpha, "alpha")
    uu = np.asarray(u, np.float64).reshape(-1)
    cap = float(np.hypot(*a.shape)) if max_width is None else float(max_width)
    pts = stroke.at(uu)
    t = stroke.directions(uu)
    nrm = np.stack([-t[:, 1], t[:, 0]], axis=1)
    steps = np.arange(1, int(cap / _STEP) + 1) * _STEP
    out = np.zeros(len(uu))
    centre = ndimage.map_coordinates(a, [pts[:, 1], pts[:, 0]], order=1, mode="constant") >= 0.5
    for sign in (-1.0, 1.0):
        xs = pts[:, None, 0] + sign * steps[None, :] * nrm[:, None, 0]
        ys = pts[:, None, 1] + sign * steps[None, :] * nrm[:, None, 1]
        inside = ndimage.map_coordinates(a, [ys.ravel(), xs.ravel()], order=1, mode="constant").reshape(xs.shape) >= 0.5
        # The reach is the last step before the first one outside.
        first_out = np.where(inside.all(axis=1), len(steps), np.argmin(inside, axis=1))
        out += first_out * _STEP
    return np.where(centre, out, 0.0)


def width_agreement(image: Any, strokes: Any, source: Any, *, samples: int = 32) -> float:
    """Median relative difference between the result's width across each target stroke and
    the width it should have: the source object's width across the corresponding source
    stroke, at ``samples`` arc fractions per pair (spread evenly along the target, mapped to
    the source through the pair's controls, piecewise linearly), or the pair's wanted
    ``width`` where it has one. 0 when the widths agree; lower is better. Samples where the
    source is not opaque are skipped. The median, because where target strokes
    meet or cross, the line across one runs along the other and its width means nothing.

    Parameters
    ----------
    image : (H, W, 4), (H, W, 2) or (H, W) array_like
        The result or its alpha.
    strokes : StrokeSet
    source : (h, w, 4), (h, w, 2) or (h, w) array_like
        The source object: its alpha or mask.
    samples : int, optional
        Samples per stroke pair (default 32).

    Examples
    --------
    >>> import numpy as np, phloem
    >>> from phloem.strokes import StrokeSet
    >>> src = np.zeros((40, 60)); src[15:25, 5:55] = 1    # 10 px wide
    >>> out = np.zeros((60, 40)); out[5:55, 15:20] = 1    # 5 px wide, upright
    >>> s = StrokeSet.from_lists([[[5, 20], [54, 20]]], [[[17, 5], [17, 54]]])
    >>> round(phloem.metrics.width_agreement(out, s, src), 3)
    0.5
    """
    n = check_int(samples, "samples", 2)
    out_a = _alpha(image, "image")
    src_a = _alpha(source, "source")
    errors = []
    for p in _check_set(strokes).pairs:
        ut = (np.arange(n) + 0.5) / n
        us = np.interp(ut, p.controls[:, 1], p.controls[:, 0])
        ws = stroke_widths(src_a, p.source, us)
        wanted = p.width_at(ut)
        if wanted is not None:
            ws = np.where(ws > 0, wanted, 0.0)
        wt = stroke_widths(out_a, p.target, ut)
        ok = ws > 0
        errors.extend((np.abs(wt[ok] - ws[ok]) / ws[ok]).tolist())
    if not errors:
        raise ValueError("source: no source stroke runs over the opaque object")
    return float(np.median(errors))
