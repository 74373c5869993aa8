"""The gaps between the painted branches (Sibbing, Pavić, Kobbelt 2010, §5.4): patch-based
completion from the input's background only, then a gradient-domain paste of the completed gaps
against the painted structure.

:func:`fill_gaps` is the step :func:`~phloem.branching.render` runs after the fragments.
:func:`_complete_background` runs :func:`phloem.texture.complete` with patches only from the
``allowed`` pixels of the input (the source structure, dilated to the fragment radius, is
excluded, so no pseudo-branches appear); on photos and fields :func:`_relight` gives the
completed gaps the input background's large-scale layout with its regions' edges
(:func:`_with_edges`), which patches copied into large gaps average away (the light that
surrounds the whole structure, :func:`_proximity_profile`, laid round the new structure), and
:func:`_recolour` its colour cast, which a fill settled on a few patches can lose; :func:`_match_borders` shifts the completed gaps in the gradient domain so that
they meet the structure without a colour step, as §5.3 does for the fragments.
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .. import texture
from ..blend import seamless
from ._pixels import F32, F64, _by_channels, _clip_channels, _paste, _pt, _robust_z, two_level
from .fragments import MIN_RADIUS
from .skeleton import Skeleton
from .trace import threshold_climb

__all__ = ["GRAINY_GAP_DIVERSITY", "fill_gaps", "gap_diversity_default"]

#: The gaps' ``gap_diversity`` on a grainy surface (:func:`gap_diversity_default`).
GRAINY_GAP_DIVERSITY = 1.0

#: The :func:`~phloem.branching.trace` options that :func:`gap_diversity_default` reads.
_CLIMB_OPTIONS = ("kind", "sigmas", "min_area", "channel", "subpixel")

#: Background detail farther than this many robust deviations from the typical is no source
#: for a spread fill (``gap_diversity > 0``): the leaf crop's blue backdrop, not its grain.
OUTLIER_MADS = 6.0

#: How far round the structure, in median radii of it, its own light is measured (at most the
#: layout's scale): farther out the profile measures the lighting where the structure lies.
GLOW_REACH = 10.0

#: The gaps' layout keeps a step of the background's brightness where it varies by more than
#: this share of its 1-99 % range over half the layout's scale (``_with_edges``); finer
#: variation is averaged (docs/pipelines/branching/quality.md, forty-seventh session).
LAYOUT_EDGE = 0.15
#: Detail finer than this share of the layout's scale is smoothed before the edges are kept:
#: a pole or a wire in the background would otherwise stand as its ghost.
LAYOUT_DETAIL = 0.15
#: Search-and-copy iterations of the gaps' full-resolution level (where there are coarser
#: ones) on photos and fields; a two-level mask's flat background needs none.
FINEST_ITERATIONS = 1


def gap_diversity_default(
    image: Any, *, valid: Any = None, trace_options: dict[str, Any] | None = None, gap_diversity: float | None = None
) -> float:
    """:func:`~phloem.branching.render`'s default ``gap_diversity`` for this input image.

    :data:`GRAINY_GAP_DIVERSITY` (1) on a grainy surface, where :func:`~phloem.branching.trace`'s
    default threshold climbs above Otsu's (:func:`~phloem.branching.threshold_climb`: asphalt,
    stone), else 0, the paper's plain completion. Plain completion of a grainy surface settles
    on a few of its patches and repeats them in a lattice; the spread fill keeps the grain, and
    there the grain is texture, not faint structure that the fill would carry into the gaps
    (a leaf's veinlets, a bark's fissures, a bolt's faint branches), as it is on the inputs
    where the threshold stays.

    Parameters
    ----------
    image : array, shape (H, W) or (H, W, C)
        The input image.
    valid : (H, W) array_like of bool, optional
        Where it shows content, as for :func:`~phloem.branching.render`.
    trace_options : dict, optional
        The options the structure was traced with; ``kind``, ``sigmas``, ``min_area``,
        ``channel`` and ``subpixel`` are used.
    gap_diversity : float, optional
        A value chosen by the caller, returned as it is.

    Returns
    -------
    float

    Examples
    --------
    >>> import numpy as np, cv2
    >>> rng = np.random.default_rng(0)
    >>> asphalt = cv2.GaussianBlur(rng.normal(0.5, 0.1, (96, 128)).astype(np.float32), (0, 0), 0.7)
    >>> gap_diversity_default(asphalt), gap_diversity_default(np.eye(64, dtype=np.float32))
    (1.0, 0.0)
    """
    if gap_diversity is not None:
        return gap_diversity
    opts = {k: v for k, v in (trace_options or {}).items() if k in _CLIMB_OPTIONS}
    return GRAINY_GAP_DIVERSITY if threshold_climb(image, valid=valid, **opts) > 1.0 else 0.0


def _complete_background(
    canvas: F32,
    hole: NDArray[np.bool_],
    source: F32,
    allowed: NDArray[np.bool_],
    *,
    patch_size: int,
    iterations: int,
    seed: int,
    threads: int | None,
    diversity: float = 0.0,
    detail_sigma: float | None = None,
    finest_iterations: int = FINEST_ITERATIONS,
) -> F32:
    """Completion of ``hole`` in ``canvas`` whose patches come only from the ``allowed`` pixels
    of ``source`` (the input's background), by :func:`phloem.texture.complete` on one frame:
    the canvas above, the source below, a separator between them.

    With ``diversity`` the completion starts from random background blocks
    (``start="blocks"``). With ``detail_sigma`` too, it runs on the background's detail: the
    source and the painted canvas less their brightness smoothed over ``detail_sigma`` source
    pixels (:func:`_layout`), the source's layout added back in the hole. Blocks from a plateau
    and a lowland would otherwise make a patchwork at the scale of the blocks. Background
    pixels whose detail is far from the typical (:func:`_outlying`) are then left out.
    ``finest_iterations`` are the full-resolution level's searches (0: it copies the
    upsampled coarser field).
    """
    if diversity > 0 and detail_sigma is not None:
        lay_src = _layout(source, allowed, detail_sigma, source.shape[:2]).mean(axis=2, keepdims=True)
        # A fill spread over many sources reaches the rare ones too: leave out those unlike the rest.
        allowed = allowed & ~_outlying(source - lay_src, allowed)
        lay_out = _layout(source, allowed, detail_sigma, canvas.shape[:2]).mean(axis=2, keepdims=True)
        scale = math.sqrt(canvas.shape[0] * canvas.shape[1] / (source.shape[0] * source.shape[1]))
        own, dens = _smooth_masked(canvas, (~hole).astype(np.float32), detail_sigma * scale)
        own = np.where(dens[..., None] > 1e-6, own.mean(axis=2, keepdims=True), lay_out).astype(np.float32)
        detail = _complete_background(
            canvas - own, hole, source - lay_src, allowed, patch_size=patch_size, iterations=iterations, seed=seed,
            threads=threads, diversity=diversity, finest_iterations=finest_iterations,
        )  # fmt: skip
        relit: F32 = canvas.copy()
        relit[hole] = (detail + lay_out)[hole]
        return relit
    p = patch_size
    H, W = canvas.shape[:2]
    hs, ws = source.shape[:2]
    rows, cols = np.flatnonzero(hole.any(axis=1)), np.flatnonzero(hole.any(axis=0))
    extent = max(int(rows[-1] - rows[0]) + 1, int(cols[-1] - cols[0]) + 1)
    # Gaps are a few fragment radii wide: enough levels that they are a few patches wide.
    levels = max(1, min(5, int(math.log2(max(extent / (4 * p), 1.0))) + 1))
    # The separator is a patch wide at the coarsest level, so no level's pyramid kernel or patch
    # reaches from the canvas's border into the source.
    gap = p << (levels - 1)
    frame = np.zeros((H + gap + hs, max(W, ws), canvas.shape[2]), np.float32)
    frame[:H, :W] = canvas
    frame[H + gap :, :ws] = source
    # The separator is context for the canvas's border patches: the background's typical colour
    # (a median: a mean over a mask's background is a grey that only branch pieces match).
    bg = np.median(source[allowed] if allowed.any() else source.reshape(-1, source.shape[2]), axis=0)
    outside = np.ones(frame.shape[:2], bool)
    outside[:H, :W] = False
    outside[H + gap :, :ws] = False
    frame[outside] = bg
    fhole = np.zeros(frame.shape[:2], bool)
    fhole[:H, :W] = hole
    source_mask = np.zeros(frame.shape[:2], bool)
    source_mask[H + gap :, :ws] = allowed
    # The finest level copies its matches' centre pixels (a vote of the overlapping matches
    # averages a grainy background into a smooth fill), after searches of its own: the coarse
    # levels see few background patches where the background is small or in narrow bands, and
    # the upsampled field alone would repeat those few, or leave the gaps flat where there are
    # none. The half-resolution level runs half the iterations.
    coarser = [iterations] if levels == 2 else [max(1, iterations // 2), iterations]
    schedule = [iterations] if levels == 1 else [finest_iterations, *coarser]
    try:
        out = texture.complete(
            frame, fhole, source_mask=source_mask, patch_size=p, levels=levels, iterations=schedule,
            search_iterations=[1] * (levels - 1) + [3], pyramid="strict", gradient_weight=0.0,
            diversity=diversity, finest="copy", start="blocks" if diversity > 0 else "auto", seed=seed,
            threads=threads,
        )  # fmt: skip
    except ValueError as e:
        if "source_mask" not in str(e):
            raise
        raise ValueError(
            "source_skeleton: the input image has no background region free of branches to complete the gaps from"
        ) from None
    res: F32 = canvas.copy()
    res[hole] = out[:H, :W][hole]
    return res


#: Distance (px) of every pixel to a skeleton's centre lines, and the row and column of the
#: centre-line pixel nearest to it.
_Nearest = tuple[F32, NDArray[np.intp], NDArray[np.intp]]


def _relight(
    canvas: F32,
    hole: NDArray[np.bool_],
    source: F32,
    allowed: NDArray[np.bool_],
    *,
    sigma: float,
    near: tuple[_Nearest, _Nearest] | None = None,
    reach: float = math.inf,
) -> F32:
    """The completed ``hole`` of ``canvas`` with its large-scale brightness (the mean over
    channels) replaced by that of ``source``'s ``allowed`` pixels (both smoothed by a Gaussian
    of ``sigma`` source pixels; the layout resampled to the canvas).

    Patch completion of gaps that make up most of the canvas settles on one level, so a
    terrain's plateau and lowland, or a photo's uneven lighting, become one flat grey. Only
    the brightness moves, so no other patch (no untraced structure) is drawn into the gaps.

    With ``near`` (each pixel's distance to the source's and to the canvas's structure, and
    the structure pixel nearest to it: :func:`_nearest_structure`), the part of the layout
    within ``reach`` (at most ``sigma``) of the structure that surrounds all of it (:func:`_proximity_profile`: a
    lightning bolt's glow) moves with the structure; the rest stays where it is in the source,
    stretched. Without it the glow round the input's bolt lights the gaps where that bolt was.
    """
    H, W = canvas.shape[:2]
    hs, ws = source.shape[:2]
    if near is None:
        layout = _layout(source, allowed, sigma, (H, W))
    else:
        centres, profile = _proximity_profile(source, allowed, near[0], reach=min(sigma, reach))
        own_g = np.interp(near[0][0], centres, profile, right=0.0).astype(np.float32)[..., None]
        layout = _layout(source - own_g, allowed, sigma, (H, W))
        layout += np.interp(near[1][0], centres, profile, right=0.0).astype(np.float32)[..., None]
    own, _ = _smooth_masked(canvas, hole.astype(np.float32), sigma * math.sqrt(H * W / (hs * ws)))
    # One shift for all channels: the layout's brightness, not its hue (a leaf's blue backdrop
    # would tint the leaf's texture).
    shift = (layout - own).mean(axis=2, keepdims=True)
    res: F32 = canvas.copy()
    np.add(res, shift, out=res, where=hole[..., None])
    return res


def _nearest_structure(skeleton: Skeleton, shape: tuple[int, int]) -> _Nearest:
    """:data:`_Nearest` of ``skeleton`` drawn on a ``shape`` image (SciPy's exact transform,
    which also gives the nearest pixel)."""
    from scipy import ndimage  # type: ignore[import-untyped]

    free = np.ones(shape, np.uint8)
    for b in skeleton.branches:
        pts = np.round(np.asarray(b.points, np.float64) * 16).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(free, [pts], False, 0, 1, cv2.LINE_8, shift=4)
    dist, (rows, cols) = ndimage.distance_transform_edt(free, return_indices=True)
    return np.asarray(dist, np.float32), np.asarray(rows, np.intp), np.asarray(cols, np.intp)


def _proximity_profile(
    source: F32, allowed: NDArray[np.bool_], near: _Nearest, *, reach: float, step: float = 2.0, min_count: int = 16
) -> tuple[F64, F64]:
    """The background's brightness against the distance to the structure: how much brighter
    (or darker) the ``allowed`` pixels are, in bins of ``step`` px of distance, than those
    round the same part of the structure at ``reach`` to ``1.5 reach`` px.

    A structure's own light (a bolt's glow) surrounds all of it; lighting that is brighter
    where part of it lies (a bright patch of sky behind one bolt) does not. So the profile is
    measured separately round each ``reach``-sized cell of the structure (by the structure
    pixel nearest to each background pixel), against that cell's own ring, and a bin counts
    only where three quarters of the cells with at least ``min_count`` pixels in it and in
    their ring agree on its sign, at the value three quarters of them reach (a bin no cell
    measures takes its farther neighbour's value). It keeps the sign of its nearest bin and a
    magnitude that never grows outward (a glow or a shadow falls off), and fades to 0 over the
    second half of ``reach`` (a cosine), so that no edge shows where it ends. Returns the bin
    centres and the profile.
    """
    dist, rows, cols = near
    nb = max(1, math.ceil(reach / step))
    centres = (np.arange(nb + 1, dtype=np.float64) + 0.5) * step
    profile = np.zeros(nb + 1)
    inside = allowed & (dist < 1.5 * reach)
    if not inside.any():
        return centres, profile
    size = max(1, round(reach))
    ncols = -(-source.shape[1] // size)
    _, cell = np.unique((rows[inside] // size) * ncols + cols[inside] // size, return_inverse=True)
    cell = cell.ravel()
    k = np.minimum((dist[inside] / step).astype(np.int64), nb)  # bin nb: the ring
    key = cell * (nb + 1) + k
    n_keys = (int(cell.max()) + 1) * (nb + 1)
    light = source.mean(axis=2)[inside].astype(np.float64)
    count = np.bincount(key, minlength=n_keys).reshape(-1, nb + 1)
    total = np.bincount(key, weights=light, minlength=n_keys).reshape(-1, nb + 1)
    ok = (count >= min_count) & (count[:, nb : nb + 1] >= min_count)
    diff = np.where(ok, total / np.maximum(count, 1) - (total[:, nb] / np.maximum(count[:, nb], 1))[:, None], np.nan)
    for i in range(nb - 1, -1, -1):  # from far to near
        col = diff[:, i][np.isfinite(diff[:, i])]
        if col.size == 0:
            profile[i] = profile[i + 1]
            continue
        low, high = np.percentile(col, [25, 75])
        profile[i] = low if low > 0 else high if high < 0 else 0.0
    # A structure's own light falls off away from it: the nearest bin's sign, a magnitude that
    # never grows outward. Bumps farther out are the layout's (the next valley of a terrain)
    # and, moved with the new structure, would draw rings round every branch.
    same = np.sign(profile) == np.sign(profile[0])
    profile = np.sign(profile[0]) * np.minimum.accumulate(np.where(same, np.abs(profile), 0.0))
    t = np.clip((centres - 0.5 * reach) / (0.5 * reach), 0.0, 1.0)
    return centres, profile * 0.5 * (1.0 + np.cos(np.pi * t))


def _recolour(canvas: F32, hole: NDArray[np.bool_], source: F32, allowed: NDArray[np.bool_]) -> F32:
    """The completed ``hole`` of ``canvas`` with its colour cast moved to that of ``source``'s
    ``allowed`` pixels: one shift per channel, the difference of the two medians less its mean
    over channels (brightness is :func:`_relight`'s).

    A completion that settles on a few background patches can settle on grey soil among red
    (the minirhizotron roots of ``docs/pipelines/branching/quality.md``), and the gaps lose the
    background's colour although their brightness follows its layout. Medians, so that a
    backdrop that is a minority of the background does not tint the gaps; one shift for the
    whole canvas, so that no layout of hue is drawn in.
    """
    if canvas.shape[2] < 2 or not hole.any() or not allowed.any():
        return canvas
    step = _median_colour(source, allowed) - _median_colour(canvas, hole)
    res: F32 = canvas.copy()
    np.add(res, (step - step.mean()).astype(np.float32), out=res, where=hole[..., None])
    return res


def _median_colour(image: F32, where: NDArray[np.bool_], samples: int = 1 << 18) -> F32:
    """Per-channel median of ``image`` over ``where``, from at most ``samples`` evenly spread pixels."""
    idx = np.flatnonzero(where)
    idx = idx[:: max(1, len(idx) // samples)]
    return np.asarray(np.median(image.reshape(-1, image.shape[2])[idx], axis=0), np.float32)


def _outlying(detail: F32, allowed: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """The ``allowed`` pixels whose ``detail`` lies more than :data:`OUTLIER_MADS` robust
    deviations (1.4826 × the median absolute deviation) beyond the median distance from the
    detail's median colour: a backdrop, a frame's rim, an optic disc."""
    d = np.linalg.norm(detail - np.median(detail[allowed], axis=0), axis=2)
    far = np.zeros_like(allowed)
    far[allowed] = _robust_z(d[allowed]) > OUTLIER_MADS
    return far


def _layout(source: F32, allowed: NDArray[np.bool_], sigma: float, shape: tuple[int, int]) -> F32:
    """The large-scale brightness of ``source``'s ``allowed`` pixels (a Gaussian of ``sigma``
    source pixels; their median where none is near) with the background's edges kept
    (:func:`_with_edges`), stretched to ``shape``."""
    layout, dens = _smooth_masked(source, allowed.astype(np.float32), sigma)
    layout[dens <= 1e-6] = np.median(source[allowed], axis=0)
    layout = _with_edges(layout, source, allowed, sigma)
    H, W = shape
    if layout.shape[:2] != (H, W):  # the input's layout, stretched to the output
        layout = np.asarray(cv2.resize(layout, (W, H), interpolation=cv2.INTER_LINEAR), np.float32).reshape(H, W, -1)
    return layout


def _with_edges(layout: F32, source: F32, allowed: NDArray[np.bool_], sigma: float) -> F32:
    """``layout`` (the background's brightness smoothed by a Gaussian of ``sigma``) with the
    background's edges put back: the steps between its regions, a fundus's macula and optic
    disc, a terrain's scarp, a bark's plates, which the Gaussian smooths away.

    A self-guided filter (He, Sun and Tang, "Guided Image Filtering", 2013) of the
    background's brightness (the structure's pixels taken from ``layout``), in boxes of
    ``sigma / 2``: where the brightness varies by more than :data:`LAYOUT_EDGE` of its 1–99 %
    range it is kept, where less it is averaged. Detail finer than :data:`LAYOUT_DETAIL`
    times ``sigma`` (grain, a pole, a wire) is smoothed first, so that only regions' edges
    stand. Only the brightness moves, as in :func:`_relight`.
    """
    smooth = layout.mean(axis=2)
    bright = source.mean(axis=2)
    lo, hi = np.percentile(bright[allowed], [1, 99])
    gray = cv2.GaussianBlur(np.where(allowed, bright, smooth).astype(np.float32), (0, 0), LAYOUT_DETAIL * sigma)
    eps = (LAYOUT_EDGE * max(float(hi - lo), 1e-6)) ** 2
    k = 2 * max(1, int(sigma / 2)) + 1

    def box(x: F32) -> F32:
        return np.asarray(cv2.boxFilter(x, -1, (k, k), borderType=cv2.BORDER_REFLECT), np.float32)

    mean = box(gray)
    var = box(gray * gray) - mean * mean
    a = np.asarray(var / (var + eps), np.float32)
    edged = box(a) * gray + box(mean - a * mean)
    return np.asarray(layout + (edged - smooth)[..., None], np.float32)


def _smooth_masked(vals: F32, w: F32, sigma: float) -> tuple[F32, F32]:
    """Normalised Gaussian convolution ``G * (w v) / G * w`` (0 where no weight is near) and
    ``G * w``, computed at a resolution of about 4 pixels per ``sigma``."""
    h, wd = w.shape
    f = max(1, int(sigma / 4))
    small = (max(1, -(-wd // f)), max(1, -(-h // f)))
    num = _by_channels(lambda part: cv2.resize(part, small, interpolation=cv2.INTER_AREA), vals * w[..., None])
    den = cv2.resize(w, small, interpolation=cv2.INTER_AREA)
    num = _by_channels(lambda part: cv2.GaussianBlur(part, (0, 0), sigma / f), num)
    den = cv2.GaussianBlur(den, (0, 0), sigma / f)
    m = num / np.maximum(den, 1e-12)[..., None] * (den > 1e-6)[..., None]
    out = _by_channels(lambda part: cv2.resize(part, (wd, h), interpolation=cv2.INTER_LINEAR), m)
    dens = cv2.resize(den, (wd, h), interpolation=cv2.INTER_LINEAR)
    return out.astype(np.float32), dens.astype(np.float32)


def _match_borders(
    canvas: F32, hole: NDArray[np.bool_], lo: F32, hi: F32, *, radius: float, threads: int | None
) -> F32:
    """Gradient-domain paste of the completed gaps against the painted structure.

    The completion copies background patches whose brightness need not match the fragments'
    own background where the two meet (an unevenly lit photo, a terrain's large-scale slope),
    and every fragment disk then shows as a lighter or darker circle. As for the fragments
    themselves (§5.3), the gaps keep their gradients and are shifted to meet the structure
    at their border: a Poisson solve over the gaps whose border values are the completion's
    own (carried one pixel into the structure) plus the *smooth* part of the colour step
    there. The step is smoothed over about a fragment radius (a local median), counting
    small steps only (weight ``1 / (1 + (|step| / τ)²)`` with τ a quarter of the image's range): a lighting
    difference is small and smooth, while a large step is content (a branch cut off at a
    disk's edge, a river against dry land in a mask) and must not be smeared across the gap.
    Where large steps make up most of the nearby border (a share of small ones below ¾),
    the correction fades out, to nothing below a quarter.
    """
    known = (~hole).astype(np.float32)
    k4 = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], np.float32)
    cnt = cv2.filter2D(1.0 - known, -1, k4, borderType=cv2.BORDER_CONSTANT)
    ring = ~hole & (cnt > 0)
    if not ring.any():
        return canvas
    src = canvas.copy()
    inner = np.where(hole[..., None], canvas, 0.0).astype(np.float32)
    acc = cv2.filter2D(inner, -1, k4, borderType=cv2.BORDER_CONSTANT).reshape(canvas.shape)
    src[ring] = acc[ring] / cnt[ring][:, None]
    step = np.zeros_like(canvas)
    step[ring] = canvas[ring] - src[ring]
    tau = 0.25 * max(float(np.linalg.norm(hi - lo)), 1e-6)
    w = np.zeros(hole.shape, np.float32)
    w[ring] = 1.0 / (1.0 + (np.linalg.norm(step[ring], axis=1) / tau) ** 2)
    smooth, den = _smooth_masked(step, w, radius)
    _, den_all = _smooth_masked(step, ring.astype(np.float32), radius)
    # A local median rather than a mean (iteratively reweighted, Weiszfeld): a border that is
    # mostly matched with a few small steps (a mask's anti-aliased edges) gets no correction.
    for _ in range(4):
        dev = np.linalg.norm((step - smooth)[ring], axis=1)
        wm = np.zeros_like(w)
        wm[ring] = w[ring] / np.maximum(dev, 0.01 * tau)
        smooth, _ = _smooth_masked(step, wm, radius)
    # Share of small steps along the nearby border: none below a quarter, full above three.
    share = den / np.maximum(den_all, 1e-12)
    smooth *= np.clip((share - 0.25) * 2.0, 0.0, 1.0)[..., None]
    dst = canvas.copy()
    dst[ring] = src[ring] + smooth[ring]
    out = seamless(src, dst, hole, (0, 0), tol=1e-4, threads=threads)
    res: F32 = canvas.copy()
    _paste(res, _clip_channels(out, lo, hi), hole)
    return res


def _background(skeleton: Skeleton, shape: tuple[int, int], factor: float) -> NDArray[np.bool_]:
    """Pixels farther from the structure than ``factor ×`` its thickness (at least 2 px)."""
    zone = np.zeros(shape, np.uint8)
    for b in skeleton.branches:
        for (a, bb), (r0, r1) in zip(zip(b.points[:-1], b.points[1:]), zip(b.thickness[:-1], b.thickness[1:])):
            rr = max(factor * 0.5 * (r0 + r1), MIN_RADIUS)
            cv2.line(
                zone, _pt(a), _pt(bb), 1, thickness=min(max(1, round(2 * rr)), 32767), lineType=cv2.LINE_8, shift=4
            )
    return np.asarray(zone == 0)


def fill_gaps(
    canvas: F32,
    filled: NDArray[np.bool_],
    image: F32,
    source_skeleton: Skeleton,
    *,
    target_skeleton: Skeleton | None = None,
    valid: NDArray[np.bool_] | None,
    radius_factor: float,
    radius: float,
    lo: F32,
    hi: F32,
    match_borders: bool | None,
    photometric: bool,
    patch_size: int,
    iterations: int,
    seed: int,
    threads: int | None,
    diversity: float = 0.0,
) -> F32:
    """Complete the pixels of ``canvas`` outside ``filled`` from the background of ``image`` (§5.4).

    Patches come from ``image`` minus its structure widened to ``radius_factor`` times its
    thickness, and only from inside ``valid``; with ``match_borders`` (None: on unless ``image``
    is a two-level mask) and ``photometric`` the completed gaps are then pasted in the gradient
    domain against the structure, the step smoothed over about ``radius``. ``diversity`` is
    the weight of the occurrence penalty in the completion (:func:`phloem.texture.complete`).
    """
    H0, W0 = image.shape[:2]
    ok = np.ones((H0, W0), bool) if valid is None else valid
    # Where the structure is so dense that less than a sixth of the image would be left (a
    # retina), the structure is widened less, down to a quarter of its thickness.
    if valid is not None:  # a patch may not straddle the border of the valid region
        ok = cv2.erode(ok.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    for factor in (radius_factor, 2.0, 1.25):
        allowed = _background(source_skeleton, (H0, W0), factor) & ok
        if allowed.mean() >= 1 / 6:
            break
    mask = two_level(image, lo, hi)
    # Large-scale: an eighth of the input's shorter side, and never finer than four patches.
    sigma = max(min(H0, W0) / 8, 4.0 * patch_size)
    canvas = _complete_background(
        canvas, ~filled, image, allowed, patch_size=patch_size, iterations=iterations, seed=seed, threads=threads,
        diversity=diversity, detail_sigma=None if mask else sigma, finest_iterations=0 if mask else FINEST_ITERATIONS,
    )  # fmt: skip
    if not mask:  # a mask's background is one level
        near = None
        if target_skeleton is not None:
            near = (
                _nearest_structure(source_skeleton, (H0, W0)),
                _nearest_structure(target_skeleton, canvas.shape[:2]),
            )
        thick = np.concatenate([b.thickness for b in source_skeleton.branches])
        reach = GLOW_REACH * max(float(np.median(thick)), 1.0)
        canvas = _relight(canvas, ~filled, image, allowed, sigma=sigma, near=near, reach=reach)
        canvas = _clip_channels(_recolour(canvas, ~filled, image, allowed), lo, hi)
    if match_borders is None:  # a mask has no lighting to match
        match_borders = not mask
    if photometric and match_borders:
        canvas = _match_borders(canvas, ~filled, lo, hi, radius=radius, threads=threads)
    return canvas
