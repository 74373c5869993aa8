"""Leaves in: cut the leaves of a scan or photo from its plain background into RGBA, one per leaf.

The background model comes from the image itself: the median CIELAB colour of a strip along the
image border. Every pixel's distance to it weights lightness by half against chroma, so a shadow
on the backdrop (darker, same hue) stays background while a leaf (other hue, or much darker) does
not. A threshold on that distance is found by Otsu's method and grown by hysteresis (weak pixels
joined to strong ones keep the faint edges of thin petioles without any opening that would cut
them); specks are removed by an area threshold relative to the largest leaf, small holes are
filled and large ones (insect damage, punched holes) kept.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from typing import Any, Literal, overload

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage  # type: ignore[import-untyped]
from skimage.filters import threshold_otsu

from .._validate import as_image, check_float, check_int
from ._fill import interior_holes

__all__ = ["ExtractResult", "extract"]

F32 = NDArray[np.float32]
Box = tuple[int, int, int, int]


@dataclass(frozen=True)
class ExtractResult:
    """What :func:`extract` found (``full_output=True``).

    Attributes
    ----------
    leaves : list of (h, w, 4) ndarray of float32
        The leaves, as :func:`extract` returns them.
    boxes : list of (y0, y1, x0, x1)
        Where each leaf's array lies in the image: rows ``y0:y1`` and columns ``x0:x1``, the
        margin included (it may reach past the image's edge, where the leaf is transparent).
        Drawings made on the whole scan (scribbles) are cut to a leaf with it.
    """

    leaves: list[F32]
    boxes: list[Box]


# Half weight for lightness: shadows differ from the backdrop mostly in lightness, leaves in
# chroma too (docs/pipelines/leaves/extract.md), so shadows stay background and dark leaves stay.
_LIGHTNESS_WEIGHT = 0.5
# Smallest threshold (Lab units): below it two colours are not told apart by eye, so an image
# whose only departures from the background are smaller holds no leaf.
_MIN_THRESHOLD = 8.0
# Otsu splits any distribution; a real leaf/background split has classes whose means lie apart by
# several spreads (>= 2.8 on every shared backdrop), an image that is all leaf (its border is leaf
# too) splits its own texture at <= 1.9.
_MIN_SEPARATION = 2.4
# At most this fraction of the image may be leaf: beyond it there is no background to model.
_MAX_FOREGROUND = 0.95
# Depth (px) of a leaf's interior below its edge: photos' edges (lens blur, JPEG chroma) mix leaf
# and background over up to 3 px, so colour beyond 3 px inside is taken as pure leaf.
_INTERIOR = 3
# A leaf has at least this many pixels whatever min_area says (a blank page with dust holds none).
_MIN_PIXELS = 64


def _lab_distance(lab: F32, background: NDArray[np.float64]) -> F32:
    d_l = _LIGHTNESS_WEIGHT * (lab[..., 0] - background[0])
    d_a = lab[..., 1] - background[1]
    d_b = lab[..., 2] - background[2]
    return np.asarray(np.sqrt(d_l * d_l + d_a * d_a + d_b * d_b), dtype=np.float32)


def _border(a: NDArray[Any], width: int) -> NDArray[Any]:
    """The pixels of a strip ``width`` wide along the image border, as rows of channels."""
    c = a.shape[2]
    return np.concatenate(
        [a[:width].reshape(-1, c), a[-width:].reshape(-1, c), a[:, :width].reshape(-1, c), a[:, -width:].reshape(-1, c)]
    )


def _check_background(background: Any) -> NDArray[np.float64] | None:
    if background is None:
        return None
    try:
        arr = np.asarray(background, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(
            f"background: expected None or an RGB colour of 3 numbers in [0, 1], got {background!r}"
        ) from None
    if arr.shape != (3,) or not np.isfinite(arr).all() or arr.min() < 0 or arr.max() > 1:
        raise ValueError(f"background: expected None or an RGB colour of 3 numbers in [0, 1], got {background!r}")
    return arr


def _reading_order(boxes: list[Box]) -> list[int]:
    """Indices of ``boxes`` (y0, y1, x0, x1) in reading order: rows of boxes whose vertical centre
    lies within the row's span, top to bottom, then left to right within each row."""
    order = sorted(range(len(boxes)), key=lambda i: (boxes[i][0], boxes[i][2]))
    rows: list[list[int]] = []
    row_end = -1
    for i in order:
        y0, y1, _, _ = boxes[i]
        if rows and (y0 + y1) / 2 < row_end:
            rows[-1].append(i)
            row_end = max(row_end, y1)
        else:
            rows.append([i])
            row_end = y1
    return [i for row in rows for i in sorted(row, key=lambda j: (boxes[j][2], boxes[j][0]))]


def _components(mask: NDArray[np.bool_], min_area: float) -> tuple[NDArray[np.int32], list[tuple[int, Box]]]:
    """8-connected components of ``mask`` and the labels and boxes (y0, y1, x0, x1) of those kept
    as leaves (at least ``min_area`` times the largest and ``_MIN_PIXELS``), in reading order."""
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    areas = stats[1:, cv2.CC_STAT_AREA]
    if areas.size == 0:
        return np.asarray(labels, np.int32), []
    h, w = mask.shape
    x, y, bw, bh = (stats[1:, i] for i in range(4))
    # A scanner's lid edge or a frame's border is a thin strip along a side of the image, not a leaf.
    strip = ((bh <= 0.03 * h) & (bw >= 0.2 * w) & ((y == 0) | (y + bh == h))) | (
        (bw <= 0.03 * w) & (bh >= 0.2 * h) & ((x == 0) | (x + bw == w))
    )
    areas = np.where(strip, 0, areas)
    floor = max(_MIN_PIXELS, min_area * float(areas.max()))
    kept = [k + 1 for k in range(n - 1) if areas[k] >= floor]
    boxes = []
    for k in kept:
        bx, by, bw_k, bh_k = (int(v) for v in stats[k, :4])
        boxes.append((by, by + bh_k, bx, bx + bw_k))
    return np.asarray(labels, np.int32), [(kept[i], boxes[i]) for i in _reading_order(boxes)]


def _grow(box: Box, margin: int) -> Box:
    y0, y1, x0, x1 = box
    return y0 - margin, y1 + margin, x0 - margin, x1 + margin


def _crop(a: NDArray[Any], box: tuple[int, int, int, int]) -> NDArray[Any]:
    """``a[y0:y1, x0:x1]``, the parts outside the image repeated from its edge (a margin beyond it)."""
    y0, y1, x0, x1 = box
    h, w = a.shape[:2]
    pad = ((max(0, -y0), max(0, y1 - h)), (max(0, -x0), max(0, x1 - w))) + ((0, 0),) * (a.ndim - 2)
    sub = a[max(0, y0) : min(h, y1), max(0, x0) : min(w, x1)]
    return np.pad(sub, pad, mode="edge") if any(p != (0, 0) for p in pad) else sub.copy()


def _fill_small_holes(leaf: NDArray[np.bool_], holes: float) -> NDArray[np.bool_]:
    """``leaf`` with its holes (4-connected background enclosed by it) under ``holes`` times its
    area filled: pinholes of the threshold and glints are noise, larger holes show real damage."""
    if holes <= 0:
        return leaf
    inside = interior_holes(leaf)
    if not inside.any():
        return leaf
    lab, n = ndimage.label(inside)
    sizes = np.bincount(lab.ravel(), minlength=n + 1)
    small = sizes < holes * float(leaf.sum())
    small[0] = False
    return np.asarray(leaf | small[lab], dtype=bool)


def _from_alpha(img: F32, min_area: float, margin: int) -> list[tuple[F32, Box]]:
    """Leaves of an image with an alpha channel, split by its alpha components, values kept."""
    alpha = img[..., -1]
    rgba = img if img.shape[2] == 4 else np.concatenate([np.repeat(img[..., :1], 3, axis=2), img[..., 1:]], axis=2)
    # Components of alpha > 0 keep each leaf's own soft edge; one must be at least half opaque.
    labels, kept = _components(alpha > 0, 0.0)
    half = np.zeros(int(labels.max()) + 1, bool)
    half[labels[alpha >= 0.5]] = True
    kept = [(k, b) for k, b in kept if half[k]]
    if kept:
        areas = np.bincount(labels.ravel())
        largest = max(int(areas[k]) for k, _ in kept)
        kept = [(k, b) for k, b in kept if areas[k] >= min_area * largest]
    if not kept:
        raise ValueError("image: found no leaf in the alpha channel (nothing at least half opaque)")
    out: list[tuple[F32, Box]] = []
    for k, b in kept:
        box = _grow(b, margin)
        piece = _crop(rgba, box)
        piece[_crop(labels, box) != k, 3] = 0.0  # other leaves in the box, and the margin beyond the image
        out.append((np.ascontiguousarray(piece, dtype=np.float32), box))
    return out


def _result(found: list[tuple[F32, Box]], full_output: bool) -> list[F32] | ExtractResult:
    leaves = [leaf for leaf, _ in found]
    return ExtractResult(leaves, [box for _, box in found]) if full_output else leaves


@overload
def extract(
    image: Any,
    *,
    background: Any = ...,
    threshold: float | None = ...,
    min_area: float = ...,
    holes: float = ...,
    margin: int = ...,
    feather: float = ...,
    full_output: Literal[False] = ...,
) -> list[F32]: ...
@overload
def extract(
    image: Any,
    *,
    background: Any = ...,
    threshold: float | None = ...,
    min_area: float = ...,
    holes: float = ...,
    margin: int = ...,
    feather: float = ...,
    full_output: Literal[True],
) -> ExtractResult: ...
def extract(
    image: Any,
    *,
    background: Any = None,
    threshold: float | None = None,
    min_area: float = 0.05,
    holes: float = 0.001,
    margin: int = 4,
    feather: float = 1.5,
    full_output: bool = False,
) -> list[F32] | ExtractResult:
    """Cut the leaves from a plain background into RGBA, one array per leaf.

    The background colour is the median CIELAB colour of a strip along the image border (2 % of
    the shorter side) unless ``background`` gives it. Each pixel's distance to it (lightness at
    half weight against chroma, so shadows on the backdrop stay background) is thresholded by
    Otsu's method, with hysteresis down to where the background's own spread ends, which keeps thin
    petioles. 8-connected pieces under ``min_area`` times the largest are specks and dropped; holes
    under ``holes`` times their leaf's area are filled, larger ones kept (insect damage shows the
    background through the leaf). Leaves that touch in the image come out as one.

    Parameters
    ----------
    image : (H, W), (H, W, 3) or (H, W, 4) ndarray
        The scan or photo, uint8, uint16 or float in [0, 1]; gray + alpha (2 channels) too. An
        image with an alpha channel that is not fully opaque is taken as it is: it is split by
        its alpha components and its values kept. A fully opaque alpha channel is ignored.
    background : (3,) array_like or None, optional
        The background's RGB colour in [0, 1]; None finds it on the image border.
    threshold : float or None, optional
        Distance (CIELAB units, lightness at half weight) beyond which a pixel is leaf; None
        chooses it by Otsu's method (at least 8).
    min_area : float, optional
        Smallest leaf as a fraction of the largest in [0, 1]; smaller pieces are specks. No leaf
        is smaller than 64 pixels.
    holes : float, optional
        Holes smaller than this fraction of their leaf's area are filled; 0 keeps every hole.
    margin : int, optional
        Pixels of transparent margin around each leaf's bounding box.
    feather : float, optional
        Width in pixels of the soft edge outside each leaf's mask, whose alpha follows the pixel's
        colour from background (0) to the threshold (1); 0 gives a hard edge.
    full_output : bool, optional
        Return an :class:`ExtractResult` with each leaf's box in the image as well.

    Returns
    -------
    list of (h, w, 4) float32 ndarray
        The leaves in reading order: rows of leaves whose vertical extents overlap, top to
        bottom, then left to right within a row. Each is cropped to its bounding box plus
        ``margin``; the colour under zero alpha is that of the nearest leaf pixel (so edges do
        not fringe with the background when composited or resized). With ``full_output``, an
        :class:`ExtractResult` holding them and their boxes.

    Raises
    ------
    ValueError
        If ``image`` holds no leaf (nothing departs from the background, or only specks), is
        all foreground (no background to model), or has the wrong shape; if an option is out
        of range.

    Examples
    --------
    >>> import cv2, numpy as np, phloem
    >>> scan = np.full((120, 200, 3), 0.95, np.float32)           # white paper
    >>> _ = cv2.ellipse(scan, (60, 50), (35, 20), 30, 0, 360, (0.2, 0.45, 0.15), -1)
    >>> _ = cv2.line(scan, (88, 68), (100, 80), (0.35, 0.3, 0.1), 2)   # its petiole
    >>> _ = cv2.ellipse(scan, (150, 60), (20, 40), 0, 0, 360, (0.25, 0.5, 0.2), -1)
    >>> leaves = phloem.leaves.extract(scan)
    >>> [leaf.shape for leaf in leaves]
    [(65, 82, 4), (89, 49, 4)]
    >>> bool(leaves[0][..., 3].max() == 1.0 and leaves[0][0, 0, 3] == 0.0)
    True
    """
    img = as_image(image, "image")
    channels = img.shape[2]
    if channels > 4:
        raise ValueError(f"image: expected 1 (gray), 2 (gray + alpha), 3 (RGB) or 4 (RGBA) channels, got {channels}")
    bg = _check_background(background)
    if threshold is not None:
        threshold = check_float(threshold, "threshold", 0.0, inclusive=False)
    if isinstance(min_area, bool) or not isinstance(min_area, numbers.Real) or not 0 <= float(min_area) <= 1:
        raise ValueError(f"min_area: expected a fraction of the largest leaf in [0, 1], got {min_area!r}")
    min_area = float(min_area)
    if isinstance(holes, bool) or not isinstance(holes, numbers.Real) or not 0 <= float(holes) <= 1:
        raise ValueError(f"holes: expected a fraction of the leaf's area in [0, 1], got {holes!r}")
    holes = float(holes)
    margin = check_int(margin, "margin", 0)
    feather = check_float(feather, "feather", 0.0)

    if channels in (2, 4) and img[..., -1].min() < 1.0:
        return _result(_from_alpha(img, min_area, margin), full_output)
    rgb = img[..., :3] if channels >= 3 else np.repeat(img[..., :1], 3, axis=2)
    rgb = np.ascontiguousarray(np.clip(rgb, 0.0, 1.0))
    h, w = rgb.shape[:2]
    if min(h, w) < 8:
        raise ValueError(f"image: expected at least 8 pixels a side to find a background, got shape {img.shape}")

    lab = np.asarray(cv2.cvtColor(rgb, cv2.COLOR_RGB2Lab), dtype=np.float32)
    if bg is None:
        bg_lab = np.median(_border(lab, max(2, round(0.02 * min(h, w)))), axis=0).astype(np.float64)
    else:
        bg_lab = cv2.cvtColor(bg.astype(np.float32).reshape(1, 1, 3), cv2.COLOR_RGB2Lab).reshape(3).astype(np.float64)
    dist = _lab_distance(lab, bg_lab)

    if (dist > (threshold if threshold is not None else _MIN_THRESHOLD)).mean() > _MAX_FOREGROUND:
        raise ValueError("image: all foreground (no background around the leaves to model); pass background=")
    if dist.max() <= (threshold if threshold is not None else _MIN_THRESHOLD):
        raise ValueError("image: found no leaf (no pixel departs from the background colour)")
    t = threshold if threshold is not None else max(_MIN_THRESHOLD, float(threshold_otsu(dist, nbins=512)))
    strong = dist > t
    fg, bgd = dist[strong], dist[~strong]
    if strong.mean() > _MAX_FOREGROUND or bgd.size == 0:
        raise ValueError("image: all foreground (no background around the leaves to model); pass background=")
    separation = (float(fg.mean()) - float(bgd.mean())) / (float(fg.std()) + float(bgd.std()) + 1e-6)
    if threshold is None and separation < _MIN_SEPARATION:
        raise ValueError(
            f"image: no plain background (leaf and background colours do not separate, {separation:.1f} spreads "
            "apart); is the image all leaf? pass background= or threshold="
        )
    # Hysteresis: weak pixels (beyond the background's own spread) joined to strong ones are leaf.
    weak_t = min(t, max(t / 2, float(bgd.mean()) + 3 * float(bgd.std())))
    # A weak pixel darker than the background with little chroma of its own is shadow, not leaf edge.
    chroma = np.hypot(lab[..., 1] - bg_lab[1], lab[..., 2] - bg_lab[2])
    shadow = (lab[..., 0] < bg_lab[0]) & (chroma < 0.25 * t)
    weak = ((dist > weak_t) & ~shadow) | strong
    n, weak_labels = cv2.connectedComponents(weak.astype(np.uint8), connectivity=8)
    has_strong = np.zeros(n, bool)
    has_strong[weak_labels[strong]] = True
    has_strong[0] = False
    mask = has_strong[weak_labels]

    labels, kept = _components(mask, min_area)
    if not kept:
        raise ValueError(
            f"image: found no leaf of at least {_MIN_PIXELS} pixels (only specks depart from the background)"
        )
    # Soft edge and colour: pixels within `band` of a leaf's interior (the mask eroded by 3 px) are a
    # mix of the leaf's colour F (that of the nearest interior pixel) and the background's B; their
    # alpha is the projection of C - B on F - B, so edges neither fringe with the background nor go
    # hard. Mask pixels beyond the threshold keep alpha >= 0.5; pixels beyond the mask get
    # alpha only within `feather` of it. Thin parts with no interior (a petiole) keep their colour.
    bg_rgb = np.median(_border(rgb, max(2, round(0.02 * min(h, w)))), axis=0) if bg is None else bg
    bg_rgb = np.asarray(bg_rgb, np.float32)
    kernel = np.ones((3, 3), np.uint8)
    band = _INTERIOR + 1.5 + feather
    out: list[tuple[F32, Box]] = []
    for k, b in kept:
        box = _grow(b, margin)
        found = _crop(labels, box) == k
        leaf = _fill_small_holes(found, holes)
        colour = _crop(rgb, box)
        alpha = leaf.astype(np.float32)
        interior = cv2.erode(leaf.astype(np.uint8), kernel, iterations=_INTERIOR) > 0
        if interior.any():
            near, (iy, ix) = ndimage.distance_transform_edt(~interior, return_indices=True)
            fg_c = colour[iy, ix]
            diff = fg_c - bg_rgb
            proj = ((colour - bg_rgb) * diff).sum(-1) / np.maximum((diff * diff).sum(-1), 1e-6)
            proj = np.clip(proj, 0.0, 1.0)
            gap = cv2.distanceTransform((~leaf).astype(np.uint8), cv2.DIST_L2, 3)
            edge = (near > 0) & (near <= band)
            inside = edge & leaf
            alpha[inside] = np.maximum(proj[inside], 0.5)
            outside = edge & ~leaf & (gap <= feather)
            alpha[outside] = np.minimum(proj[outside], 0.49)
            mixed = edge & (leaf | outside)
            colour[mixed] = fg_c[mixed]
        # Pixels that only hysteresis joined (below the threshold) are mixed or noise: their alpha is
        # the same projection, towards the most leaf-like colour within 2 px (the stalk's own centre
        # for a faint petiole, the real edge for a noise pixel beside it) ...
        core = leaf & (_crop(strong, box) | ~found)  # filled holes are leaf
        # ... near the leaf's edge only: a pale fleck deep inside the blade is leaf, not a pinhole.
        depth = cv2.distanceTransform(leaf.astype(np.uint8), cv2.DIST_L2, 3)
        weak_only = leaf & ~core & (depth <= 2.0)
        if weak_only.any():
            ys, xs = np.nonzero(weak_only)
            d_box = np.where(leaf, _crop(dist, box), -1.0)
            source = _crop(rgb, box)
            best = np.full(ys.size, -np.inf, np.float32)
            by, bx = ys.copy(), xs.copy()
            hh, ww = leaf.shape
            for dy in range(-2, 3):
                for dx in range(-2, 3):
                    yy, xx = np.clip(ys + dy, 0, hh - 1), np.clip(xs + dx, 0, ww - 1)
                    better = d_box[yy, xx] > best
                    best[better] = d_box[yy, xx][better]
                    by[better], bx[better] = yy[better], xx[better]
            f_w = source[by, bx]
            diff = f_w - bg_rgb
            proj = ((source[ys, xs] - bg_rgb) * diff).sum(-1) / np.maximum((diff * diff).sum(-1), 1e-6)
            alpha[ys, xs] = np.minimum(alpha[ys, xs], np.clip(proj, 0.0, 1.0))
            colour[ys, xs] = f_w
        # Colour under no leaf: the nearest leaf pixel's, defined and free of background fringes.
        _, idx = ndimage.distance_transform_edt(alpha <= 0, return_indices=True)
        clear = alpha <= 0
        colour[clear] = colour[idx[0][clear], idx[1][clear]]
        out.append((np.ascontiguousarray(np.concatenate([colour, alpha[..., None]], axis=2), dtype=np.float32), box))
    return _result(out, full_output)
