"""Source skeletons from images: thickness by maximum gradient (Sibbing et al. 2010, §3) and automatic tracing.

In the paper the user clicks the skeleton of the source structure and "a simple maximum gradient
detection operator in the direction perpendicular to the branch orientation provides some initial
estimate for the local branch thickness" (§3). :func:`estimate_thickness` is that operator.

:func:`trace` goes beyond the paper (its stated future work): it finds the whole skeleton
automatically. A binary mask is used as it is; a photo is first filtered for ridges (bright or
dark curvilinear structures) with a multi-scale Hessian filter and thresholded. The mask is then
cleaned, skeletonised, turned into a pixel graph, cut into a forest (braided rivers have
cycles), and every tree is decomposed into branches by longest paths: the longest path from the
root is the main branch, and each other subtree hanging off it becomes a child branch, its own
longest path first, recursively. Thickness comes from the distance transform of a mask, and
from :func:`estimate_thickness` on a photo.
"""

from __future__ import annotations

import math
import numbers
from collections import deque
from collections.abc import Sequence
from typing import Any, Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from .._distance import euclidean_distance
from .._ridges import ridge_polarity, ridge_response
from .._validate import as_image, as_mask, check_float, check_int
from ._elements import _smooth_path, _tree_roots
from .skeleton import Branch, Skeleton

__all__ = ["estimate_thickness", "threshold_climb", "trace"]

#: How far from its junction, in the junction's radii, a traced child's own radius begins: the
#: child's centre line leaves its parent's channel at ``1 / sin θ`` of that radius, 1.5 for a
#: child leaving at about 40° (docs/pipelines/branching/quality.md, fifty-fifth session).
JUNCTION_REACH = 1.5

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]
Kind = Literal["auto", "bright", "dark", "mask"]
Thickness = Literal["auto", "mask", "gradient"]
_KINDS = ("auto", "bright", "dark", "mask")


# -- input helpers ----------------------------------------------------------------------------


def _gray(image: Any, channel: int | None) -> F32:
    """``image`` as a 2-D float32 array: one channel, or luminance of the first three."""
    img = as_image(image, "image")
    c = img.shape[2]
    if channel is not None:
        channel = check_int(channel, "channel", 0)
        if channel >= c:
            raise ValueError(f"channel: expected a channel index below {c}, got {channel}")
        return np.ascontiguousarray(img[:, :, channel])
    if c >= 3:
        return np.ascontiguousarray(img[:, :, :3] @ np.array([0.299, 0.587, 0.114], np.float32))
    return np.ascontiguousarray(img[:, :, 0])


def _traced_gray(image: Any, kind: str, channel: int | None) -> F32:
    """:func:`_gray` of what :func:`trace` reads: a bool image with ``kind="mask"`` is True = structure."""
    if kind == "mask" and np.asarray(image).dtype == np.bool_:
        image = np.asarray(image, np.float32)
    return _gray(image, channel)


#: Scales (px) of the ridge filter when none are given.
DEFAULT_SIGMAS = (1.0, 2.0, 3.0)

#: A tree's root is one of its far ends: a leaf at least this share of the tree's diameter from
#: its farthest pixel (step 5), the end of a long path rather than a side twig ...
ROOT_ECCENTRICITY = 0.75

#: ... or a leaf at least this share away that is :data:`ROOT_THICKER` times as thick as every
#: far end: a trunk's foot, where the arms above it span the tree's diameter. A leaf this far
#: out that ends at the frame (:func:`_at_frame`) counts as a far end: the structure enters the
#: picture there.
TRUNK_ECCENTRICITY = 0.5

#: See :data:`TRUNK_ECCENTRICITY`.
ROOT_THICKER = 1.5

#: The factor by which ``trace``'s default ridge threshold climbs above Otsu's on a grainy
#: surface (:func:`_stable_threshold`) ...
GRAIN_STEP = 1.25

#: ... where a first step keeps less than this share of the mask (between grain's and a
#: structure's shares: docs/pipelines/branching/quality.md) ...
GRAIN_KEEP = 0.65

#: ... until a step keeps at least this share ...
STABLE_KEEP = 0.75

#: ... and keeps more than this share (a step that keeps less cuts into the structure) ...
GRAIN_FLOOR = 0.25

#: ... for at most this many steps (about 2.4 times Otsu's threshold).
GRAIN_STEPS = 4


def _range_to_trace(gray: F32) -> tuple[float, float]:
    """The gray image's minimum and maximum, or a ValueError where there is nothing to trace."""
    lo, hi = float(gray.min()), float(gray.max())
    if hi - lo <= 1e-12:
        raise ValueError(f"image: nothing to trace, the image is constant ({lo})")
    if min(gray.shape) < 3:
        # The ridge filter's derivatives need 3 pixels a side (numpy's gradient would say "Shape of array too small").
        raise ValueError(
            f"image: nothing to trace in a {gray.shape[1]}x{gray.shape[0]} image; it needs at least 3x3 pixels"
        )
    return lo, hi


def _filter_reach(sig: tuple[float, ...]) -> int:
    """How far (px) the ridge filter at scales ``sig`` reads: a border within it reads as a ridge."""
    return 2 * math.ceil(3 * max(sig)) + 3


def _sigmas(sigmas: Any) -> tuple[float, ...]:
    if isinstance(sigmas, numbers.Real):
        sigmas = (sigmas,)
    try:
        vals = tuple(check_float(s, "sigmas", 0.0, inclusive=False) for s in sigmas)
    except TypeError:
        raise TypeError(f"sigmas: expected a positive number or a sequence of them, got {sigmas!r}") from None
    if not vals:
        raise ValueError("sigmas: expected at least one scale")
    return vals


# -- thickness by maximum gradient (§3) ---------------------------------------------------------


def _tangents(points: F64) -> F64:
    """Unit tangents by central differences (one-sided at the ends)."""
    d = np.gradient(points, axis=0) if len(points) > 2 else np.repeat(points[1:] - points[:1], len(points), axis=0)
    norm = np.linalg.norm(d, axis=1, keepdims=True)
    norm[norm == 0] = 1.0
    return np.asarray(d / norm, dtype=np.float64)


def estimate_thickness(
    image: Any,
    skeleton: Skeleton,
    *,
    max_radius: float | None = None,
    sigma: float = 1.0,
    step: float = 0.25,
    channel: int | None = None,
) -> Skeleton:
    """Branch radius at every vertex by the maximum gradient across the branch (§3 of [1]_).

    For each vertex ``x_i`` with unit tangent ``t_i`` (central differences of its neighbours)
    and normal ``n_i = (-t_y, t_x)``, the image (gray: luminance, or ``channel``), smoothed by a
    Gaussian of ``sigma`` px, is sampled bilinearly along ``x_i + s n_i`` for
    ``s = -max_radius .. max_radius`` in steps of ``step`` px. The profile's derivative along
    ``s`` is the gradient component perpendicular to the branch. On each side separately the
    position of its largest magnitude is found (``s+ > 0`` and ``s- < 0``, refined to sub-sample
    precision by a parabola through the maximum and its two neighbours), and the radius is
    ``(s+ - s-) / 2``: half the distance between the two edges. The vertex need not sit exactly
    on the centre line for this to hold. Where one side has no gradient at all (a flat profile)
    the other side's distance is used; where neither has, the old thickness is kept.

    Parameters
    ----------
    image : array, shape (H, W) or (H, W, C)
        The image the skeleton was drawn on.
    skeleton : Skeleton
        Its branches give positions; their thicknesses are replaced.
    max_radius : float, optional
        Largest radius searched, in px. Default: 2 x the largest thickness already in the
        skeleton + 3, or 16 when all thicknesses are zero. Keep it below the distance to the
        next structure, whose edges would otherwise win.
    sigma : float
        Gaussian smoothing (px) before differentiating; 0 for none.
    step : float
        Sampling step along the normal, in px.
    channel : int, optional
        Use this channel instead of the luminance.

    Returns
    -------
    Skeleton
        The same branches, parents and shape with new thicknesses.

    Examples
    --------
    >>> img = np.zeros((40, 60), np.float32)
    >>> img[16:25, 5:56] = 1.0   # a bar 9 px wide (rows 16 .. 24): radius 4.5
    >>> sk = Skeleton([Branch([[10, 20], [30, 20], [50, 20]], 0.0)])
    >>> r = estimate_thickness(img, sk).branches[0].thickness
    >>> bool(np.all(np.abs(r - 4.5) < 0.2))
    True
    """
    gray = _gray(image, channel)
    if not isinstance(skeleton, Skeleton):
        raise TypeError(f"skeleton: expected a phloem.branching.Skeleton, got {type(skeleton).__name__}")
    sigma = check_float(sigma, "sigma", 0.0)
    step = check_float(step, "step", 0.0, inclusive=False)
    if max_radius is None:
        biggest = max((float(b.thickness.max()) for b in skeleton.branches), default=0.0)
        max_radius = 2.0 * biggest + 3.0 if biggest > 0 else 16.0
    max_radius = check_float(max_radius, "max_radius", 0.0, inclusive=False)
    if sigma > 0:
        gray = np.asarray(cv2.GaussianBlur(gray, (0, 0), sigma, borderType=cv2.BORDER_REFLECT), np.float32)
    n_side = max(2, math.ceil(max_radius / step))
    s = np.arange(-n_side, n_side + 1, dtype=np.float64) * step
    out = []
    for b in skeleton.branches:
        t = _tangents(b.points)
        normal = np.stack([-t[:, 1], t[:, 0]], axis=1)
        xy = b.points[:, None, :] + s[None, :, None] * normal[:, None, :]
        prof = cv2.remap(
            gray,
            xy[..., 0].astype(np.float32),
            xy[..., 1].astype(np.float32),
            cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_REPLICATE,
        ).astype(np.float64)
        grad = np.abs(np.gradient(prof, step, axis=1))
        plus = _peak(grad[:, n_side + 1 :], step) + step  # s of the strongest edge on the + side
        minus = _peak(grad[:, :n_side][:, ::-1], step) + step  # distance of the strongest on the - side
        thick = b.thickness.copy()
        ok_p, ok_m = np.isfinite(plus), np.isfinite(minus)
        both = ok_p & ok_m
        thick[both] = 0.5 * (plus[both] + minus[both])
        thick[ok_p & ~ok_m] = plus[ok_p & ~ok_m]
        thick[ok_m & ~ok_p] = minus[ok_m & ~ok_p]
        out.append(Branch(b.points.copy(), thick, b.parent))
    return Skeleton(out, skeleton.shape)


def _peak(g: F64, step: float) -> F64:
    """Per row, the sub-sample position (in units of ``step`` times index) of the maximum; NaN if flat."""
    idx = np.argmax(g, axis=1)
    rows = np.arange(len(g))
    best = g[rows, idx]
    pos = idx.astype(np.float64)
    inner = (idx > 0) & (idx < g.shape[1] - 1)
    a, c = g[rows[inner], idx[inner] - 1], g[rows[inner], idx[inner] + 1]
    den = a - 2 * best[inner] + c
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.where(den < 0, 0.5 * (a - c) / den, 0.0)
    pos[inner] += np.clip(off, -0.5, 0.5)
    pos[best <= 1e-9] = np.nan
    return np.asarray(pos * step, np.float64)


def _otsu(values: F32) -> float:
    v = values[values > 0]
    if v.size == 0:
        return math.inf
    scaled = np.clip(v / float(v.max()) * 255.0, 0, 255).astype(np.uint8)
    t, _ = cv2.threshold(scaled.reshape(-1, 1), 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    return float(t) / 255.0 * float(v.max())


def _hysteresis(resp: F32, low: float, high: float) -> NDArray[np.bool_]:
    """Pixels above ``low`` that are 8-connected to a pixel above ``high``."""
    _, lab = cv2.connectedComponents((resp > low).astype(np.uint8), connectivity=8)
    strong = np.zeros(int(lab.max()) + 1, bool)
    strong[lab[resp > high]] = True
    strong[0] = False
    return np.asarray(strong[lab], dtype=np.bool_)


def _photo_response(
    gray: F32, sig: tuple[float, ...], kind: str, valid: NDArray[np.bool_] | None, *, subpixel: bool = False
) -> F32:
    """The ridge response ``trace`` thresholds on a photo: 0 within the filter's reach of ``valid``'s border."""
    resp = ridge_response(gray, sig, kind, subpixel=subpixel)
    if valid is not None:
        reach = _filter_reach(sig)
        kernel = np.ones((reach, reach), np.uint8)
        inner = cv2.erode(valid.astype(np.uint8), kernel, borderType=cv2.BORDER_REPLICATE).astype(bool)
        resp = np.where(inner, resp, 0.0).astype(np.float32)
    return resp


def _ridge_mask(resp: F32, t: float) -> NDArray[np.bool_]:
    """The hysteresis mask of a ridge response at ``threshold = t`` (``trace``'s step 1)."""
    mask = _hysteresis(resp, 0.5 * t, t)
    # A ridge mask is ragged: close tiny gaps and round it so the skeleton has fewer spurs.
    return cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8)).astype(bool)


def _stable_threshold(resp: F32, min_area: int) -> tuple[float, float, NDArray[np.bool_]]:
    """The ridge threshold ``trace`` uses by default, the factor by which it climbed above
    Otsu's, and its :func:`_ridge_mask`.

    A structure's ridges stand clear of their surroundings, so a :data:`GRAIN_STEP` times higher
    threshold keeps most of its mask. A textured surface (asphalt, stone) answers the ridge
    filter everywhere with a response that falls off smoothly around Otsu's threshold, and the
    same step sheds its grain by the half. Where the first step keeps less than
    :data:`GRAIN_KEEP` of the mask, the threshold climbs by that step until one keeps at least
    :data:`STABLE_KEEP` (at most :data:`GRAIN_STEPS` steps): the level at which what is left
    no longer melts away, the structure. A step that would keep less than :data:`GRAIN_FLOOR`
    is not taken: grain sheds about half its mask a step, so one that sheds three quarters
    cuts into a faint structure itself.
    """
    t = _otsu(resp)
    mask = _ridge_mask(resp, t)
    if not math.isfinite(t):
        return t, 1.0, mask
    area = int(_drop_small(mask, min_area).sum())
    climb = 1.0
    for i in range(GRAIN_STEPS):
        if area == 0:
            break
        up = _ridge_mask(resp, t * climb * GRAIN_STEP)
        kept = int(_drop_small(up, min_area).sum())
        if kept >= (GRAIN_KEEP if i == 0 else STABLE_KEEP) * area or kept < GRAIN_FLOOR * area:
            break
        climb, area, mask = climb * GRAIN_STEP, kept, up
    return t * climb, climb, mask


# -- mask cleaning ---------------------------------------------------------------------------


def _drop_small(mask: NDArray[np.bool_], min_area: int) -> NDArray[np.bool_]:
    """``mask`` without components smaller than ``min_area`` and with holes smaller than it filled."""
    if min_area <= 1:
        return mask
    _, lab, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    keep = stats[:, cv2.CC_STAT_AREA] >= min_area
    keep[0] = False
    mask = keep[lab]
    _, lab, stats, _ = cv2.connectedComponentsWithStats((~mask).astype(np.uint8), connectivity=4)
    fill = stats[:, cv2.CC_STAT_AREA] < min_area
    fill[0] = False
    return np.asarray(mask | fill[lab], dtype=bool)


def _bridge(skel: NDArray[np.bool_], gap: float) -> NDArray[np.bool_]:
    """Join skeleton ends to another skeleton piece ahead of them, at most ``gap`` px away.

    A ridge filter loses the response where vessels cross or fork, so one vessel falls apart
    into pieces whose ends point at each other. For every end pixel (one 8-neighbour) its
    heading is the direction from the centroid of its own piece's pixels within 4 px; the
    nearest pixel of a different piece within ``gap`` px and 60 degrees of that heading is
    joined to it by a straight 8-connected line.
    """
    from scipy.spatial import cKDTree  # type: ignore[import-untyped]

    sk = skel.astype(np.uint8)
    nb = cv2.filter2D(sk, -1, np.ones((3, 3), np.float32), borderType=cv2.BORDER_CONSTANT) - sk
    ends = np.argwhere((sk > 0) & (nb == 1))
    if len(ends) == 0:
        return skel
    _, lab = cv2.connectedComponents(sk, connectivity=8)
    pix = np.argwhere(sk > 0)
    kd = cKDTree(pix)
    out = sk.copy()
    for y, x in ends.tolist():
        own = lab[y, x]
        y0, y1, x0, x1 = max(0, y - 4), y + 5, max(0, x - 4), x + 5
        wy, wx = np.nonzero(lab[y0:y1, x0:x1] == own)
        head = np.array([x - (wx.mean() + x0), y - (wy.mean() + y0)])
        norm = float(np.hypot(*head))
        if norm < 0.5:
            continue
        head /= norm
        cand = pix[kd.query_ball_point([y, x], gap)]
        cand = cand[lab[cand[:, 0], cand[:, 1]] != own]
        if len(cand) == 0:
            continue
        vec = np.stack([cand[:, 1] - x, cand[:, 0] - y], axis=1).astype(np.float64)
        dist = np.hypot(vec[:, 0], vec[:, 1])
        ok = (vec @ head) >= 0.5 * dist
        if not ok.any():
            continue
        k = int(np.flatnonzero(ok)[np.argmin(dist[ok])])
        cv2.line(out, (x, y), (int(cand[k, 1]), int(cand[k, 0])), 1, 1, cv2.LINE_8)
    return np.asarray(out > 0, dtype=np.bool_)


# -- graph -----------------------------------------------------------------------------------

_OFFSETS = ((0, 1, 1.0), (1, -1, math.sqrt(2)), (1, 0, 1.0), (1, 1, math.sqrt(2)))


def _pixel_forest(skel: NDArray[np.bool_], radius: F32) -> tuple[NDArray[np.intp], NDArray[np.intp], F64, Any]:
    """Skeleton pixels, and a spanning forest of their 8-neighbour graph as a symmetric CSR of lengths.

    Cycles are broken where the structure is thinnest: the forest is the minimum spanning forest
    for edge weights ``length / (r_a + r_b)``, so every cycle loses its edge of smallest radius
    (and the redundant diagonals of the pixel graph go first).
    """
    from scipy import sparse  # type: ignore[import-untyped]  # (scipy comes with scikit-image; imported
    from scipy.sparse import csgraph  # type: ignore[import-untyped]  # here, not at phloem import time)

    ys, xs = np.nonzero(skel)
    n = len(ys)
    index = np.full(skel.shape, -1, np.int64)
    index[ys, xs] = np.arange(n)
    h, w = skel.shape
    src, dst, length = [], [], []
    for dy, dx, ln in _OFFSETS:
        y2, x2 = ys + dy, xs + dx
        ok = (y2 >= 0) & (y2 < h) & (x2 >= 0) & (x2 < w)
        j = np.full(n, -1, np.int64)
        j[ok] = index[y2[ok], x2[ok]]
        has = j >= 0
        src.append(np.nonzero(has)[0])
        dst.append(j[has])
        length.append(np.full(int(has.sum()), ln))
    a, b, ln_all = np.concatenate(src), np.concatenate(dst), np.concatenate(length)
    r = radius[ys, xs].astype(np.float64)
    weight = ln_all / (r[a] + r[b] + 1e-3)
    g = sparse.coo_matrix((weight, (a, b)), shape=(n, n)).tocsr()
    mst = csgraph.minimum_spanning_tree(g).tocoo()
    i, j = mst.row, mst.col
    dy, dx = ys[i] - ys[j], xs[i] - xs[j]
    ln = np.sqrt((dy * dy + dx * dx).astype(np.float64))
    tree = sparse.coo_matrix(
        (np.concatenate([ln, ln]), (np.concatenate([i, j]), np.concatenate([j, i]))), shape=(n, n)
    ).tocsr()
    return xs, ys, r, tree


def _reach(tree: Any, start: int) -> tuple[NDArray[np.intp], NDArray[np.int32], F64]:
    """Nodes of ``start``'s tree by increasing path length, predecessors and path lengths."""
    from scipy.sparse import csgraph

    dist, pred = csgraph.dijkstra(tree, directed=False, indices=start, return_predecessors=True)
    nodes = np.nonzero(np.isfinite(dist))[0]
    order = nodes[np.argsort(dist[nodes], kind="stable")]
    return order, np.asarray(pred, np.int32), np.asarray(dist, np.float64)


def _decompose(tree: Any, root: int) -> list[tuple[list[int], int | None, int]]:
    """Longest-path decomposition of the tree containing ``root``.

    Returns ``(pixel path, parent branch, index of the attachment pixel in the parent's path)``
    with parents first. The main path starts at ``root``; a child path starts at the parent
    pixel it grows from, then follows the longest way down.
    """
    order, pred, dist = _reach(tree, root)
    height: dict[int, float] = {}
    best: dict[int, int] = {}
    children: dict[int, list[int]] = {}
    for v in order[1:].tolist():
        children.setdefault(int(pred[v]), []).append(v)
    for v in order[::-1].tolist():
        if v == root:
            continue
        p = int(pred[v])
        cand = height.get(v, 0.0) + (dist[v] - dist[p])
        if p not in best or cand > height[p]:
            height[p] = cand
            best[p] = v
    out: list[tuple[list[int], int | None, int]] = []
    queue: deque[tuple[list[int], int | None, int]] = deque([([root], None, 0)])
    while queue:
        path, parent, at = queue.popleft()
        v = path[-1]
        while v in best:
            v = best[v]
            path.append(v)
        me = len(out)
        out.append((path, parent, at))
        for k in range(1 if parent is not None else 0, len(path)):
            u = path[k]
            for c in children.get(u, ()):
                if best[u] != c:
                    queue.append(([u, c], me, k))
    return out


def _beyond_junction(points: F64, thick: F64, radius: float) -> F64:
    """A child's radii near its junction (of ``radius``) replaced by its first one beyond :data:`JUNCTION_REACH`.

    A child's chain starts at the junction and crosses the parent's channel before it leaves
    it, so its first radii measure the junction, not the child.
    """
    d = np.hypot(*(points - points[0]).T)
    beyond = np.flatnonzero(d >= JUNCTION_REACH * radius)
    if len(beyond) == 0 or beyond[0] == 0:
        return thick
    out: F64 = thick.copy()
    out[: beyond[0]] = thick[beyond[0]]
    return out


def _across_junction(points: F64, thick: F64, at: int, radius: float) -> F64:
    """A parent's radii inside the disk of a junction at vertex ``at`` interpolated across it.

    The distance transform swells where a child leaves: the inscribed disk of a T reaches into
    the child's mouth.
    """
    inside = np.hypot(*(points - points[at]).T) < radius
    lo, hi = at, at
    while lo > 0 and inside[lo - 1]:
        lo -= 1
    while hi < len(points) - 1 and inside[hi + 1]:
        hi += 1
    ends = [i for i in (lo - 1, hi + 1) if 0 <= i < len(points)]  # one end alone: its radius
    if not ends:
        return thick
    out: F64 = thick.copy()
    out[lo : hi + 1] = np.interp(np.arange(lo, hi + 1), ends, thick[ends])
    return out


def _unswollen(branches: list[Branch], *, parents: bool = True) -> None:
    """:func:`_beyond_junction` on every child and (``parents``) :func:`_across_junction` on its parent, in place."""
    given = [b.thickness.copy() for b in branches]
    for b in branches:
        if b.parent is not None:
            pi, at = b.parent
            radius = float(given[pi][at])
            b.thickness = _beyond_junction(b.points, b.thickness, radius)
            if parents:
                branches[pi].thickness = _across_junction(branches[pi].points, branches[pi].thickness, at, radius)


# -- trace -----------------------------------------------------------------------------------


def _default_gap(sig: tuple[float, ...], kind: str) -> float:
    """``trace``'s default bridging gap at Otsu's threshold: none for a mask, else the filter's reach."""
    return 0.0 if kind == "mask" else 2.0 * max(sig) + 3.0


def _resolve_kind(gray: F32, sigmas: tuple[float, ...]) -> str:
    """What ``kind="auto"`` means for a gray image: a two-valued image is a mask, otherwise the
    polarity with the stronger ridge response at ``sigmas``."""
    return "mask" if np.unique(gray).size <= 2 else ridge_polarity(gray, sigmas)


def trace(
    image: Any,
    *,
    kind: Kind = "auto",
    sigmas: float | Sequence[float] = DEFAULT_SIGMAS,
    threshold: float | None = None,
    threshold_scale: float = 1.0,
    min_area: int = 30,
    min_length: float = 8.0,
    spur: float = 2.5,
    smooth: float = 1.5,
    h: float | None = None,
    root: tuple[float, float] | None = None,
    channel: int | None = None,
    gap: float | None = None,
    thickness: Thickness = "auto",
    valid: Any = None,
    blob: float | None = 8.0,
    subpixel: bool = False,
    wide: bool = True,
    edges: bool = True,
) -> Skeleton:
    """Trace the skeleton of a branching structure in an image (beyond [1]_, its future work).

    1. **Foreground.** ``kind="mask"``: pixels above ``threshold`` (default: halfway between the
       image's minimum and maximum). ``"bright"`` / ``"dark"``: a ridge filter on the gray
       image: for every scale in ``sigmas`` the scale-normalised Hessian eigenvalue across a
       bright (dark) ridge minus twice the scale-normalised gradient magnitude (which removes
       the responses beside step edges), maximum over scales; hysteresis thresholding keeps
       the pixels above ``threshold / 2`` that are connected to one above ``threshold``
       (default: Otsu's threshold of the positive responses, raised on a grainy surface:
       where 1.25 times that threshold sheds more than a third of the mask, as asphalt's or
       stone's grain does and a structure's ridges do not, it climbs by that factor until a
       step keeps three quarters of the mask, for at most four steps and none that keeps
       under a quarter; see ``docs/pipelines/branching.md``), times ``threshold_scale``.
       ``"auto"``: a
       two-valued image is a mask, otherwise the polarity with the stronger 99th-percentile
       response is used. With ``subpixel`` the filter is evaluated on a twice finer grid, so
       that lines a pixel or two wide whose centre falls between pixel centres keep their
       response. With ``wide`` the structure wider than ``sigmas`` reach is added: the same
       filter at 1.5 and 2.25 times the largest scale, hysteresis-thresholded between 0.3 and 1
       times the larger of its Otsu threshold and its median positive response plus 6 robust
       deviations; of its centre lines, the trees whose axis runs outside the fine mask for at
       least 4 of its radii are drawn in at 0.8 of their thickness by
       :func:`estimate_thickness` (a vessel tree's trunk, which the fine scales find only as
       its two edges, so that its twigs fell apart into separate trees).
    2. **Cleaning.** Components and holes smaller than ``min_area`` pixels are removed / filled.
    3. **Skeleton.** :func:`skimage.morphology.skeletonize`, radius ``r`` = Euclidean distance
       transform of the mask minus 0.5 (the distance from a centre pixel to the nearest
       background pixel centre exceeds the radius by half a pixel). Skeleton ends are joined
       to another piece straight ahead of them within ``gap`` px.
    4. **Forest.** The 8-neighbour graph of the skeleton pixels is reduced to its minimum
       spanning forest for weights ``length / (r_a + r_b)``: every cycle (braided channels,
       loops) is cut at its thinnest place.
    5. **Branches.** Each tree is rooted at ``root`` (the nearest skeleton pixel) or, by
       default, at its thickest far end: among the leaves at least 3/4 of the tree's diameter
       from their farthest pixel, or half of it where they end at the frame (within their
       radius plus 2 px of the image's or ``valid``'s border, on a photo plus the ridge
       filters' reach: the structure enters the picture there), or half of it for one 1.5
       times as thick as all those (a trunk's foot below long arms), the one with the largest
       radius over its first pixels (a mask: the mean distance-transform radius over
       ``max(5, 4 r + 1)`` pixels; a photo: the median maximum-gradient thickness of 7. over
       ``2 ⌈max_radius⌉`` pixels, because a ridge mask is about as narrow along a trunk as
       along a twig). The longest path from the root is the main branch; every subtree hanging
       off a branch becomes a child branch along its own longest path, attached at the branch
       pixel it grows from; recursively. Branches (roots too) shorter than ``spur`` times the largest radius
       along them, the attachment included, or than ``min_length`` are dropped with their
       subtree: skeletonisation spurs, and the medial axes of blobs (a wide patch of water
       whose axis is shorter than its width is not a branch).
    6. **Polylines.** Pixel chains are smoothed by a Gaussian of ``smooth`` vertices (the first
       vertex is kept so children stay attached), thickness likewise, and resampled to edge
       length ``h`` when given.
    7. **Thickness.** ``thickness="mask"`` keeps the distance-transform radius (default for
       masks). ``"gradient"`` (default for photos, whose ridge masks are narrower than the
       structure) replaces it by :func:`estimate_thickness` on the gray image with
       ``max_radius = 2 max(sigmas) + 2``, median-filtered over 5 vertices and smoothed like
       the points (before the resampling of 6.). The radii are taken without the junctions'
       own width: a child's radii within :data:`JUNCTION_REACH` junction radii of its
       junction become its first radius beyond, and (distance transform only) its parent's
       within the junction's radius are interpolated across it.
    8. **Edges.** On a photo, a further tree (not the main one, nor ``root``'s) whose median
       thickness is over the 90th percentile of the main tree's and whose two sides differ in
       brightness (at its radius plus 3 px) by over 3 times as much, relative to its depth, as
       the median tree's sides do (and by over 0.3 of its depth) is dropped: it is an edge
       between two regions, such as a dish's rim beside a tissue section, not a ridge, and
       grown it would become the new structure's thickest branches.

    Parameters
    ----------
    image : array, shape (H, W) or (H, W, C)
        A photo or a mask (a bool array with ``kind="mask"``); integer images are scaled by their dtype's maximum.
    kind : {"auto", "bright", "dark", "mask"}
        What the structure looks like (see 1.).
    sigmas : float or sequence of float
        Scales (px) of the ridge filter; about the branch radii to find / 1.5.
    threshold : float, optional
        Foreground threshold, see 1.
    threshold_scale : float
        Factor on the default threshold of a photo's ridge response (default 1; see 1.):
        below 1 keeps fainter structure, grain included (0.5 traces the shared elevation
        model's smaller valleys too), above 1 only the clearest. It needs no knowledge of the
        response's units, which ``threshold`` does; the two cannot be combined, nor is a mask's
        level scaled.
    min_area : int
        Smallest component kept and largest hole filled, in pixels.
    min_length : float
        Shortest branch kept, in px.
    spur : float
        Branches shorter than this many times the largest radius along them are dropped.
    smooth : float
        Smoothing of the pixel chains, in vertices; 0 for none.
    h : float, optional
        Resample every branch to this edge length (:meth:`Skeleton.resample`).
    root : (x, y), optional
        Where the structure starts; its component is rooted at the nearest skeleton pixel.
    channel : int, optional
        Trace this channel of a colour image instead of its luminance.
    gap : float, optional
        Join skeleton ends to another piece up to this far ahead (px; see ``_bridge``):
        ridge filters break vessels where they cross or fork. Default ``2 max(sigmas) + 3`` for
        photos, times the factor by which the default threshold climbed on a grainy surface
        (see 1.: a faint crack breaks where its response dips below the raised threshold), and
        0 (off) for masks.
    thickness : {"auto", "mask", "gradient"}
        Where the radii come from, see 7.
    valid : (H, W) array_like of bool, optional
        Where the image shows content (default everywhere; see :func:`valid_region`): only
        structure inside it is traced, and for photos none within the ridge filter's reach
        (``3 max(sigmas) + 1`` px) of its border, whose edge (a fundus photo's rim) would
        read as a ridge.
    blob : float or None, optional
        Skeleton pixels whose radius is over ``blob`` times the median radius are dropped
        (default 8; None keeps them): they lie in a lake or the sea a river mask opens into,
        a region, not a channel, whose skeleton would be traced as branches hundreds of pixels
        thick.
    subpixel : bool, optional
        Evaluate the ridge filter (photos only) on the image upsampled 2x, keeping each pixel's
        best of its four sub-positions (default False). Thin lines in a glow (lightning) are then
        traced whole instead of in pieces, but so are more of a textured surface's faint ridges
        (asphalt, bark); the trace takes about twice as long. See ``docs/pipelines/branching.md``.
    wide : bool, optional
        Also find structure wider than ``sigmas`` reach on a photo (default True; see 1.): a
        trunk that would otherwise split its tree into the twigs beside it. False traces the
        fine scales only.
    edges : bool, optional
        Drop the thick further trees that are edges between two regions on a photo (default
        True; see 8.). False keeps every tree.

    Returns
    -------
    Skeleton
        One root branch per traced component, parents before children, ``shape = (H, W)``.
        The result is deterministic.

    Raises
    ------
    ValueError
        For a constant image or one where nothing is left to trace, and for bad arguments
        (each message names the argument).

    Examples
    --------
    A T made of two bars 9 px wide (OpenCV draws ``thickness=7`` that wide): one main branch and
    one child attached to it.

    >>> import cv2
    >>> mask = np.zeros((60, 80), np.uint8)
    >>> _ = cv2.line(mask, (10, 15), (70, 15), 1, thickness=7)
    >>> _ = cv2.line(mask, (40, 15), (40, 55), 1, thickness=7)
    >>> sk = trace(mask, kind="mask")
    >>> len(sk.branches), sk.branches[1].parent[0], sk.shape
    (2, 0, (60, 80))
    >>> bool(abs(np.median(sk.branches[0].thickness) - 4.5) < 0.5)
    True
    """
    from scipy import ndimage
    from scipy.sparse import csgraph
    from skimage.morphology import skeletonize

    if kind not in _KINDS:
        raise ValueError(f"kind: expected one of {_KINDS}, got {kind!r}")
    if thickness not in ("auto", "mask", "gradient"):
        raise ValueError(f"thickness: expected 'auto', 'mask' or 'gradient', got {thickness!r}")
    gray = _traced_gray(image, kind, channel)
    shape = (int(gray.shape[0]), int(gray.shape[1]))
    sig = _sigmas(sigmas)
    min_area = check_int(min_area, "min_area", 0)
    min_length = check_float(min_length, "min_length", 0.0)
    spur = check_float(spur, "spur", 0.0)
    smooth = check_float(smooth, "smooth", 0.0)
    if h is not None:
        h = check_float(h, "h", 0.0, inclusive=False)
    if threshold is not None:
        threshold = check_float(threshold, "threshold", -math.inf)
    scale = check_float(threshold_scale, "threshold_scale", 0.0, inclusive=False)
    if scale != 1.0 and threshold is not None:
        raise ValueError("threshold_scale: scales the default threshold; with threshold given, set that instead")
    if gap is not None:
        gap = check_float(gap, "gap", 0.0)
    if blob is not None:
        blob = check_float(blob, "blob", 1.0)
    if not isinstance(subpixel, (bool, np.bool_)):
        raise TypeError(f"subpixel: expected True or False, got {subpixel!r}")
    if not isinstance(wide, (bool, np.bool_)):
        raise TypeError(f"wide: expected True or False, got {wide!r}")
    if not isinstance(edges, (bool, np.bool_)):
        raise TypeError(f"edges: expected True or False, got {edges!r}")
    if root is not None:
        try:
            rx, ry = (float(v) for v in root)
        except (TypeError, ValueError):
            raise TypeError(f"root: expected (x, y), got {root!r}") from None
        if not (
            math.isfinite(rx) and math.isfinite(ry) and -0.5 <= rx <= shape[1] - 0.5 and -0.5 <= ry <= shape[0] - 0.5
        ):
            raise ValueError(f"root: ({rx}, {ry}) is outside the {shape[1]}x{shape[0]} image")
    ok = None if valid is None else as_mask(valid, "valid", shape)
    lo, hi = _range_to_trace(gray)

    if kind == "auto":
        kind = _resolve_kind(gray, sig)  # type: ignore[assignment]
    auto_gap = gap is None
    if gap is None:
        gap = _default_gap(sig, kind)
    wide_px = np.zeros(shape, np.bool_)
    if kind == "mask":
        if scale != 1.0:
            raise ValueError("threshold_scale: a mask is thresholded at a level (threshold), not a ridge response")
        mask = gray > (0.5 * (lo + hi) if threshold is None else threshold)
    else:
        resp = _photo_response(gray, sig, kind, ok, subpixel=bool(subpixel))
        if threshold is None:
            t, climb, mask = _stable_threshold(resp, min_area)
            if scale != 1.0:
                mask = _ridge_mask(resp, t * scale)
            if auto_gap:
                # a structure's faint stretches fall below a raised threshold, so its breaks grow with it
                gap *= climb
        else:
            mask = _ridge_mask(resp, threshold)
        if wide:
            wide_px = _wide_structure(gray, sig, kind, ok, min_area, mask)
            mask |= wide_px
    if ok is not None:
        mask &= ok
    mask = _drop_small(mask, min_area)
    if not mask.any():
        raise ValueError("image: nothing to trace, no foreground left (check kind, threshold, min_area)")
    if mask.all():
        # no background pixel: every radius would be infinite
        raise ValueError("image: nothing to trace, the foreground fills the whole image (check kind, threshold)")

    dist = euclidean_distance(mask)
    radius = np.maximum(dist - 0.5, 0.5).astype(np.float32)
    skel = np.asarray(skeletonize(mask), dtype=np.bool_)  # type: ignore[no-untyped-call]
    if blob is not None and skel.any():
        # (a photo's wide structure has been measured by its edges: a trunk, not a lake)
        skel &= (radius <= blob * float(np.median(radius[skel]))) | wide_px
    if gap > 0:
        skel = _bridge(skel, gap)
    xs, ys, r, tree = _pixel_forest(skel, radius)
    n_comp, labels = csgraph.connected_components(tree, directed=False)

    start = None
    if root is not None:
        start = int(np.argmin((xs - rx) ** 2 + (ys - ry) ** 2))
    # Components largest first (by pixel count, ties by first pixel) so the main structure is branch 0.
    sizes = np.bincount(labels, minlength=n_comp)
    first = np.full(n_comp, len(labels), np.int64)
    np.minimum.at(first, labels, np.arange(len(labels)))
    comp_order = sorted(range(n_comp), key=lambda c: (-int(sizes[c]), int(first[c])))

    photo = thickness == "gradient" or (thickness == "auto" and kind != "mask")
    max_radius = 2.0 * max(sig) + 2.0
    picked = [c for c in comp_order if not (start is not None and labels[start] == c)]
    cands = [_root_candidates(tree, int(first[c]), r, 2 * math.ceil(max_radius) if photo else 0) for c in picked]
    radii = _end_radii(cands, xs, ys, r, gray if photo else None, shape, smooth, max_radius)
    frame = _at_frame(cands, xs, ys, r, ok, shape, _filter_reach(sig) if kind != "mask" else 0)
    roots = {c: _pick_root(cs, rs, fs) for c, cs, rs, fs in zip(picked, cands, radii, frame, strict=True)}
    if start is not None:
        roots[int(labels[start])] = start
    branches: list[Branch] = []
    chains: list[Branch] = []  # pixel chains and their radii, smoothed once their junctions are corrected
    given: int | None = None  # the tree of the caller's root, which is never an edge
    for c in comp_order:
        croot = roots[c]
        if start is not None and c == int(labels[start]):
            given = len(chains)
        new_index: dict[int, int] = {}
        for i, (path, parent, at) in enumerate(_decompose(tree, croot)):
            if parent is not None and parent not in new_index:
                continue  # the parent was dropped, so is its subtree
            if len(path) < 2:
                continue
            p = np.stack([xs[path], ys[path]], axis=1).astype(np.float64)
            seg = float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())
            attach_r = float(r[path].max())
            if seg < max(min_length, spur * attach_r):
                continue
            thick = r[path].astype(np.float64)
            par = None if parent is None else (new_index[parent], at)
            new_index[i] = len(chains)
            chains.append(Branch(p, thick, par))
    _unswollen(chains)
    for ch in chains:
        pts = _smooth_path(ch.points, smooth)
        # the end reflection can push a bent chain at the border a little outside the image
        np.clip(pts, 0.0, [shape[1] - 1, shape[0] - 1], out=pts)
        thick = ch.thickness
        if smooth > 0 and len(thick) > 2:
            # (a Gaussian wider than the chain is cut to it, as _smooth_path does)
            thick = ndimage.gaussian_filter1d(thick, min(smooth, len(thick)), mode="nearest")
        branches.append(Branch(pts, thick, ch.parent))
    if not branches:
        raise ValueError(f"image: nothing to trace, every branch is shorter than min_length={min_length}")
    sk = Skeleton(branches, shape)
    if photo:
        sk = estimate_thickness(gray, sk, max_radius=max_radius)
        # the children's start only: a photo's parents interpolated across their junctions
        # drift more (docs/pipelines/branching/quality.md, fifty-fifth session)
        _unswollen(sk.branches, parents=False)
        for b in sk.branches:
            if len(b) > 2:
                t = ndimage.median_filter(b.thickness, size=5, mode="nearest")
                b.thickness = ndimage.gaussian_filter1d(t, min(smooth, len(t)), mode="nearest") if smooth > 0 else t
        if kind != "mask" and edges:
            sk = _without_edges(gray, sk, given)
    return sk.resample(h) if h is not None else sk


def threshold_climb(
    image: Any,
    *,
    kind: Kind = "auto",
    sigmas: float | Sequence[float] = DEFAULT_SIGMAS,
    min_area: int = 30,
    channel: int | None = None,
    valid: Any = None,
    subpixel: bool = False,
) -> float:
    """The factor by which :func:`trace`'s default ridge threshold climbs above Otsu's on ``image``.

    1 on a clean surface, whose ridges are its structure, and on a mask; above 1 (at most
    ``1.25 ** 4``, about 2.4) on a grainy surface (asphalt, stone), whose grain answers the
    ridge filter everywhere and sheds its mask as the threshold rises (step 1 of
    :func:`trace`). :func:`render` completes the gaps of such a surface with a spread fill
    (:func:`gap_diversity_default`), since plain patch completion repeats a few of its patches.

    Parameters
    ----------
    image : array, shape (H, W) or (H, W, C)
        A photo or a mask.
    kind, sigmas, min_area, channel, valid, subpixel : optional
        As for :func:`trace`.

    Returns
    -------
    float
        At least 1.

    Raises
    ------
    ValueError
        For a constant image and bad arguments (each message names the argument).

    Examples
    --------
    >>> import cv2
    >>> rng = np.random.default_rng(0)
    >>> grain = cv2.GaussianBlur(rng.normal(0.5, 0.1, (96, 128)).astype(np.float32), (0, 0), 0.7)
    >>> bool(threshold_climb(grain) > 1)
    True
    >>> clean = np.full((96, 128), 0.8, np.float32)
    >>> _ = cv2.line(clean, (5, 60), (120, 40), 0.5, 2)
    >>> threshold_climb(clean + rng.normal(0, 0.01, clean.shape).astype(np.float32))
    1.0
    """
    if kind not in _KINDS:
        raise ValueError(f"kind: expected one of {_KINDS}, got {kind!r}")
    if not isinstance(subpixel, (bool, np.bool_)):
        raise TypeError(f"subpixel: expected True or False, got {subpixel!r}")
    gray = _traced_gray(image, kind, channel)
    sig = _sigmas(sigmas)
    min_area = check_int(min_area, "min_area", 0)
    ok = None if valid is None else as_mask(valid, "valid", gray.shape)
    _range_to_trace(gray)
    resolved = _resolve_kind(gray, sig) if kind == "auto" else kind
    if resolved == "mask":
        return 1.0
    resp = _photo_response(gray, sig, resolved, ok, subpixel=bool(subpixel))
    return _stable_threshold(resp, min_area)[1]


#: A further tree on a photo is an edge between two regions (a dish's or a frame's rim), not a
#: ridge, where the brightness on its two sides differs by more than this many times the
#: median tree's (sides at its radius plus :data:`EDGE_REACH` px, over its depth below them) ...
EDGE_SIDEDNESS = 3.0

#: ... and by more than this share of its depth in any case (a trace whose trees all have flat sides) ...
EDGE_SIDEDNESS_FLOOR = 0.3

#: ... and it is thicker (median) than the 90th percentile of the main tree's thickness: grown,
#: it would be the thickest branch of the new structure.
EDGE_THICKNESS_QUANTILE = 0.9

#: How far beyond its radius (px) a branch's two sides are sampled.
EDGE_REACH = 3.0


def _sidedness(gray: F32, skeleton: Skeleton, tree: list[int]) -> float:
    """Median brightness difference between the two sides of ``tree``'s branches over the
    median depth of their centre line below (or above) the sides' mean: about 0 for a ridge,
    large for a step between two regions."""
    side, depth = [], []
    for i in tree:
        b = skeleton.branches[i].resample(1.0)
        t = _tangents(b.points)
        off = (b.thickness + EDGE_REACH)[:, None] * np.stack([-t[:, 1], t[:, 0]], axis=1)
        xy = np.stack([b.points + off, b.points, b.points - off]).astype(np.float32)  # one side, centre, other
        a, c, z = cv2.remap(gray, xy[..., 0], xy[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        side.append(np.abs(a - z).astype(np.float64))
        depth.append(np.abs(0.5 * (a + z) - c).astype(np.float64))
    return float(np.median(np.concatenate(side)) / max(float(np.median(np.concatenate(depth))), 1e-9))


def _without_edges(gray: F32, skeleton: Skeleton, given: int | None) -> Skeleton:
    """``skeleton`` less its further trees that are edges between two regions (:data:`EDGE_SIDEDNESS`).

    A dish's rim beside a tissue section answers the ridge filter as a long thick vessel;
    grown, it becomes the thickest branches of the new structure. The main tree (branch 0's)
    and the tree of the caller's ``root`` (branch ``given``) are kept.
    """
    roots = _tree_roots(skeleton)
    trees: dict[int, list[int]] = {}
    for i, r in enumerate(roots):
        trees.setdefault(r, []).append(i)
    if len(trees) < 2:
        return skeleton
    main = np.concatenate([skeleton.branches[i].thickness for i in trees[roots[0]]])
    thick = float(np.quantile(main, EDGE_THICKNESS_QUANTILE))
    candidates = [
        r for r, t in trees.items()
        if r != roots[0] and r != given and float(np.median(np.concatenate([skeleton.branches[i].thickness for i in t]))) > thick
    ]  # fmt: skip
    if not candidates:
        return skeleton
    sided = {r: _sidedness(gray, skeleton, t) for r, t in trees.items()}
    bound = max(EDGE_SIDEDNESS * float(np.median(list(sided.values()))), EDGE_SIDEDNESS_FLOOR)
    drop = {r for r in candidates if sided[r] > bound}
    if not drop:
        return skeleton
    kept = [i for i, r in enumerate(roots) if r not in drop]
    index = {old: new for new, old in enumerate(kept)}
    branches = []
    for i in kept:
        b = skeleton.branches[i]
        parent = None if b.parent is None else (index[b.parent[0]], b.parent[1])
        branches.append(Branch(b.points, b.thickness, parent))
    return Skeleton(branches, skeleton.shape)


#: Scales of the wide ridge filter, in multiples of the largest of ``sigmas``.
WIDE_SCALES = (1.5, 2.25)

#: How far above the median positive response, in robust deviations (1.4826 MAD), the wide
#: filter's strong threshold lies at least: at its scales grain merges into webs.
WIDE_MADS = 6.0

#: The wide filter's weak threshold as a share of its strong one: a trunk's response dips
#: where it forks, and the band must run on into its arms.
WIDE_LOW = 0.3

#: Share of its measured thickness painted round the wide structure's centre line.
WIDE_FILL = 0.8

#: A wide tree is painted where its axis leaves the fine mask for at least this many of its
#: radii (twice as long as wide).
WIDE_RUN = 4.0


def _wide_structure(
    gray: F32,
    sig: tuple[float, ...],
    kind: str,
    valid: NDArray[np.bool_] | None,
    min_area: int,
    fine: NDArray[np.bool_],
) -> NDArray[np.bool_]:
    """The structure wider than ``sig`` reaches, at the width of its edges (``trace``'s step 1).

    A ridge filter at the fine scales answers beside a trunk's edges and not on its axis, so a
    vessel tree fell apart at its trunk into the twigs on either side. A second filter at
    :data:`WIDE_SCALES` keeps only what stands :data:`WIDE_MADS` robust deviations clear of its
    typical response. Its centre lines are measured by :func:`estimate_thickness`, and the trees
    among them whose axis leaves ``fine`` (the fine scales' mask) for :data:`WIDE_RUN` radii are
    painted at :data:`WIDE_FILL` of that thickness, so that the twigs' ridges meet them and the
    skeleton runs through the trunk's middle.
    """
    scales = tuple(f * max(sig) for f in WIDE_SCALES)
    resp = ridge_response(gray, scales, kind)
    # Near the image's border (or ``valid``'s) a dark margin reflected into the padding reads as
    # a wide ridge along it; the fine filter's reach of it is left out, as for ``valid`` in ``trace``.
    reach = _filter_reach(sig)
    region = np.ones(gray.shape, np.uint8) if valid is None else valid.astype(np.uint8)
    kernel = np.ones((reach, reach), np.uint8)
    inside = cv2.erode(region, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(np.bool_)
    resp = np.where(inside, resp, 0.0)
    out = np.zeros(gray.shape, np.bool_)
    pos = resp[resp > 0]
    if pos.size < 2:
        return out
    med = float(np.median(pos))
    strong = max(_otsu(resp), med + WIDE_MADS * 1.4826 * float(np.median(np.abs(pos - med))))
    band = _drop_small(_hysteresis(resp, WIDE_LOW * strong, strong), min_area)
    if not band.any():
        return out
    try:
        centre = trace(band, kind="mask", gap=0.0, blob=None, min_area=min_area)
    except ValueError:  # only stubs, shorter than a branch
        return out
    measured = estimate_thickness(gray, centre, max_radius=2.0 * max(scales) + 2.0)
    # Only the band's trees whose axis the fine mask misses over a stretch longer than wide (a
    # trunk, which the fine scales see as two edges); a bolt's core is in the fine mask already,
    # and where its glow swells at a fork the band's axis leaves it for a few px only.
    near = cv2.dilate(fine.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(np.bool_)
    tree = _tree_roots(measured)
    keep: set[int] = set()
    for i, b in enumerate(measured.branches):
        px = np.rint(b.points).astype(np.int64)
        for run in _runs(~near[px[:, 1], px[:, 0]]):
            if _arc(b.points[run]) >= WIDE_RUN * float(np.median(b.thickness[run])):
                keep.add(tree[i])
    paint = np.zeros(gray.shape, np.uint8)
    for i, b in enumerate(measured.branches):
        if tree[i] in keep:
            for (x, y), t in zip(np.rint(b.points).astype(np.int64), b.thickness, strict=True):
                cv2.circle(paint, (int(x), int(y)), max(1, round(WIDE_FILL * float(t))), 1, -1)
    return paint.astype(np.bool_)


def _runs(flags: NDArray[np.bool_]) -> list[NDArray[np.intp]]:
    """Index arrays of the maximal runs of True in ``flags``."""
    edges = np.diff(np.concatenate([[0], flags.astype(np.int8), [0]]))
    return [np.arange(a, b) for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True)]


def _arc(points: F64) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum()) if len(points) > 1 else 0.0


def _root_candidates(tree: Any, node: int, r: F64, reach: int) -> list[tuple[int, list[int], float]]:
    """The far ends of ``node``'s tree that may be its root: ``(leaf, its first pixels, eccentricity)``.

    Candidates are the leaves whose farthest other node is at least :data:`TRUNK_ECCENTRICITY`
    of the tree's diameter away (the ends of long paths, not side twigs; :func:`_pick_root`
    tells the far ends among them). Each comes with the pixels from it inward,
    ``max(5, 4 r + 1)`` of them at its own mask radius ``r``, or ``reach`` where that is more.
    """
    order, _, _ = _reach(tree, node)
    end_a = int(order[-1])
    order_a, pred_a, da = _reach(tree, end_a)
    end_b = int(order_a[-1])
    _, pred_b, db = _reach(tree, end_b)
    deg = np.diff(tree.indptr)[order_a]
    leaves = np.sort(order_a[deg <= 1])
    ecc = np.maximum(da[leaves], db[leaves])
    out = []
    for v in leaves[ecc >= TRUNK_ECCENTRICITY * da[end_b]].tolist():
        pred = pred_b if v == end_a else pred_a
        path = [v]
        want = max(5, int(4 * r[v]) + 1, reach)
        while len(path) < want and pred[path[-1]] >= 0:
            path.append(int(pred[path[-1]]))
        out.append((v, path, float(max(da[v], db[v]))))
    return out


def _at_frame(
    candidates: list[list[tuple[int, list[int], float]]],
    xs: NDArray[np.intp],
    ys: NDArray[np.intp],
    r: F64,
    valid: NDArray[np.bool_] | None,
    shape: tuple[int, int],
    reach: int,
) -> list[list[bool]]:
    """Whether each candidate ends at the frame: within its own radius plus 2 px of the image's
    border or ``valid``'s, and on a photo within the ridge filters' ``reach`` of it, where
    nothing is traced (``trace``'s step 1)."""
    inside = np.ones(shape, np.uint8) if valid is None else valid.astype(np.uint8)
    inside[[0, -1], :] = 0
    inside[:, [0, -1]] = 0
    dist = cv2.distanceTransform(inside, cv2.DIST_L2, 5)
    return [[bool(dist[ys[v], xs[v]] <= reach + r[v] + 2.0) for v, _, _ in cands] for cands in candidates]


def _pick_root(candidates: list[tuple[int, list[int], float]], radius: list[float], at_frame: list[bool]) -> int:
    """The thickest far end (eccentricity at least :data:`ROOT_ECCENTRICITY` of the largest, or
    ``at_frame``), or a nearer candidate :data:`ROOT_THICKER` times as thick as that; ties go to
    the more eccentric, then the lower index."""
    diameter = max(ecc for _, _, ecc in candidates)

    def thickest(far: bool) -> tuple[int, float]:
        best, best_key = -1, (-math.inf, -math.inf)
        for (v, _, ecc), rad, edge in zip(candidates, radius, at_frame, strict=True):
            key = (round(rad, 6), ecc)
            if (ecc >= ROOT_ECCENTRICITY * diameter or edge or not far) and key > best_key:
                best, best_key = v, key
        return best, best_key[0]

    far, far_r = thickest(True)
    trunk, trunk_r = thickest(False)
    return trunk if trunk_r >= ROOT_THICKER * far_r else far


def _end_radii(
    candidates: list[list[tuple[int, list[int], float]]],
    xs: NDArray[np.intp],
    ys: NDArray[np.intp],
    r: F64,
    gray: F32 | None,
    shape: tuple[int, int],
    smooth: float,
    max_radius: float,
) -> list[list[float]]:
    """Each candidate's radius over its first pixels: the mean mask radius, or on a photo (``gray``)
    the median of :func:`estimate_thickness` there, since a photo's ridge mask is a line a pixel or
    two wide whatever the structure's width, and would make every end equally thin."""
    radii = [[float(r[np.asarray(path)].mean()) for _, path, _ in cands] for cands in candidates]
    # (a single-pixel tree has no direction to measure across, so it keeps its mask radius)
    long = [(i, j) for i, cands in enumerate(candidates) for j, (_, path, _) in enumerate(cands) if len(path) > 1]
    if gray is None or not long:
        return radii
    paths = [candidates[i][j][1] for i, j in long]
    branches = [Branch(_smooth_path(np.stack([xs[p], ys[p]], axis=1).astype(np.float64), smooth), r[p]) for p in paths]
    thick = estimate_thickness(gray, Skeleton(branches, shape), max_radius=max_radius).branches
    for (i, j), b in zip(long, thick, strict=True):
        radii[i][j] = float(np.median(b.thickness))
    return radii
