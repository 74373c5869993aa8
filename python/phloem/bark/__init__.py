"""Tree bark from one small photo: the pipeline of Laitoch 2018, *Procedural Modeling of Tree Bark*.

The pipeline (thesis §3.2) has three stages, each with a result an artist can inspect, edit and
feed back in:

1. :func:`input_labels` segments the photo into ``n_labels`` regions (§3.5): non-local-means
   denoising, CIELAB, k-means, majority-filter erosion of tiny regions;
2. :func:`synthesize_labels` grows a new label map of any size with the same shapes (§3.6:
   Rosenberger et al. 2009 layered shape synthesis, or phloem's joint multi-label variant);
3. :func:`phloem.texture.by_numbers` paints the new label map with bark from the photo (§3.3–3.4:
   Fan et al. 2012 texture-by-numbers with smart initialisation).

:func:`generate` runs all three; give it ``labels_in`` or ``labels_out`` to resume from edited
maps. :func:`add_edge_label` is the optional extra region of §3.5.5, applied to both maps once
both exist; :func:`cylinder_preview` wraps a texture around a trunk for a quick look.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, overload

import cv2
import numpy as np
from numpy.typing import NDArray

from .. import shapes, texture
from .._api import Seed, Size, old_flag, renamed
from .._color import check_denoise, denoised_lab, rgb8
from .._progress import Progress
from .._validate import as_image, as_labels, check_int, check_seed, check_size, check_threads
from ..shapes import Rotations

__all__ = [
    "BarkResult",
    "add_edge_label",
    "cylinder_preview",
    "decode_labels",
    "encode_labels",
    "generate",
    "input_labels",
    "synthesize_labels",
]


def _kmeans(
    x: NDArray[np.float32], k: int, rng: np.random.Generator, restarts: int = 3, max_iter: int = 100
) -> tuple[NDArray[np.int32], NDArray[np.float32]]:
    """Lloyd's k-means with k-means++ seeding; the best of ``restarts`` runs by inertia.

    Works on the distinct rows of ``x`` weighted by their counts, which gives the same
    clustering as the full set at a fraction of the cost (8-bit photos repeat colours a lot).
    """
    pts, inverse, counts = np.unique(x.astype(np.float64), axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    wts = counts.astype(np.float64)
    n = len(pts)
    sq = (pts**2).sum(1)
    best: tuple[float, NDArray[np.int64], NDArray[np.float64]] | None = None
    for _ in range(restarts):
        centres = np.empty((k, pts.shape[1]), np.float64)
        centres[0] = pts[rng.choice(n, p=wts / wts.sum())]
        d2 = ((pts - centres[0]) ** 2).sum(1)
        for j in range(1, k):
            p = d2 * wts
            centres[j] = pts[rng.choice(n, p=p / p.sum())] if p.sum() > 0 else pts[rng.integers(n)]
            d2 = np.minimum(d2, ((pts - centres[j]) ** 2).sum(1))
        assign = np.full(n, -1, np.int64)
        for _ in range(max_iter):
            dist = sq[:, None] - 2 * pts @ centres.T + (centres**2).sum(1)[None, :]
            new = dist.argmin(1)
            if np.array_equal(new, assign):
                break
            assign = new
            mass = np.bincount(assign, weights=wts, minlength=k)
            for j in range(k):
                if mass[j] > 0:
                    sel = assign == j
                    centres[j] = (pts[sel] * wts[sel, None]).sum(0) / mass[j]
                else:  # an empty cluster restarts at the point farthest from its centre
                    far = int(dist[np.arange(n), assign].argmax())
                    centres[j] = pts[far]
        inertia = float((wts * ((pts - centres[assign]) ** 2).sum(1)).sum())
        if best is None or inertia < best[0]:
            best = (inertia, assign, centres)
    assert best is not None
    return best[1][inverse].astype(np.int32), best[2].astype(np.float32)


def _majority(labels: NDArray[np.int32], k: int) -> NDArray[np.int32]:
    """One pass of §3.5.4: every pixel becomes its most common 8-neighbour (ties keep the pixel's
    own label when it is among the most common, else the lowest label)."""
    kernel = np.ones((3, 3), np.float32)
    kernel[1, 1] = 0
    counts = np.stack(
        [cv2.filter2D((labels == j).astype(np.float32), -1, kernel, borderType=cv2.BORDER_REFLECT) for j in range(k)]
    )
    top = counts.max(0)
    own = np.take_along_axis(counts, labels[None].astype(np.int64), 0)[0]
    return np.where(own >= top, labels, counts.argmax(0)).astype(np.int32)


@renamed(k="n_labels")
def input_labels(
    image: Any,
    n_labels: int = 2,
    *,
    denoise: float = 10.0,
    erosion: int = 1,
    seed: Seed = 0,
) -> NDArray[np.int32]:
    """Segment a bark photo into ``n_labels`` regions: the input label map of the bark thesis (§3.5).

    Steps: non-local-means denoising (Buades et al., OpenCV's ``fastNlMeansDenoisingColored``,
    which itself works in CIELAB), conversion to CIELAB, k-means of the pixel colours into
    ``n_labels`` clusters (Lloyd's algorithm with k-means++ seeding, best of 3; the thesis used scikit-learn's
    mini-batch approximation of the same objective), then ``erosion`` passes of the majority
    filter that removes tiny regions (§3.5.4: every pixel becomes its most common neighbour).
    The thesis keeps only a grey level per region (§3.5.5); phloem numbers the regions
    ``0 … n_labels - 1`` from dark to light by the L* of their cluster centre.

    Parameters
    ----------
    image : array_like, shape (H, W, 3) or (H, W, 4) or (H, W)
        The bark photo; uint8/uint16 are scaled to [0, 1], floats are taken as [0, 1]. Alpha
        is ignored.
    n_labels : int, optional
        Number of regions (default 2; the thesis uses 2–5, §3.5). ``k`` before (deprecated).
    denoise : float, optional
        Filter strength ``h`` of the non-local-means denoising on the 0–255 scale, for both
        lightness and colour (default 10, OpenCV's documented example value); 0 skips it.
    erosion : int, optional
        Passes of the majority filter (default 1, as in the thesis).
    seed : int or numpy.random.Generator, optional
        Seed of the k-means seeding.

    Returns
    -------
    numpy.ndarray of int32, shape (H, W)
        Labels ``0 … n_labels - 1``, darkest region first.

    Raises
    ------
    ValueError
        If ``n_labels`` is below 2 or larger than the number of distinct colours in ``image``.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> lab = phloem.bark.input_labels(phloem.data.bark(), 3)
    >>> lab.shape, lab.dtype, sorted(np.unique(lab).tolist())
    ((256, 256), dtype('int32'), [0, 1, 2])
    """
    img = as_image(image, "image")
    k = check_int(n_labels, "n_labels", 2)
    erosion = check_int(erosion, "erosion", 0)
    check_denoise(denoise)
    u8 = rgb8(img)
    distinct = len(np.unique(u8.reshape(-1, 3), axis=0))
    if k > distinct:
        raise ValueError(f"n_labels: asked for {k} regions, but the image has only {distinct} distinct colours")
    lab = denoised_lab(u8, denoise)
    rng = np.random.default_rng(check_seed(seed))
    assign, centres = _kmeans(lab.reshape(-1, 3), k, rng)
    order = np.argsort(centres[:, 0], kind="stable")
    rank = np.empty(k, np.int32)
    rank[order] = np.arange(k, dtype=np.int32)
    labels = rank[assign].reshape(img.shape[:2])
    for _ in range(erosion):
        labels = _majority(labels, k)
    return labels


def add_edge_label(labels: Any, *, width: int = 1, label: int | None = None) -> NDArray[np.int32]:
    """Mark the borders between regions with a label of their own (thesis §3.5.5).

    A pixel is on an edge when a pixel within ``width`` steps (8-connected) has another label.
    The thesis found that this extra region often helps texture-by-numbers, and applies it to
    the input and the output label map after both exist (so the shape synthesis never sees it).

    Parameters
    ----------
    labels : array_like of int, shape (H, W)
        A label map.
    width : int, optional
        Half-width of the edge band in pixels (default 1: a 2-pixel band on each border).
    label : int, optional
        Value of the edge label (default: one more than the largest label).

    Returns
    -------
    numpy.ndarray of int32, shape (H, W)

    Examples
    --------
    >>> import numpy as np, phloem
    >>> lab = np.zeros((6, 6), np.int32); lab[:, 3:] = 1
    >>> phloem.bark.add_edge_label(lab)[0].tolist()
    [0, 0, 2, 2, 1, 1]
    """
    lab = as_labels(labels, "labels")
    width = check_int(width, "width", 1)
    edge_value = int(lab.max()) + 1 if label is None else int(label)
    if label is not None and np.any(lab == edge_value):
        raise ValueError(f"label: {edge_value} is already used in labels")
    size = 2 * width + 1
    kernel = np.ones((size, size), np.uint8)
    f = lab.astype(np.float32)
    # min and max filters: a pixel is on an edge when its window holds more than one label
    lo = cv2.erode(f, kernel, borderType=cv2.BORDER_REPLICATE)
    hi = cv2.dilate(f, kernel, borderType=cv2.BORDER_REPLICATE)
    return np.where(lo != hi, edge_value, lab).astype(np.int32)


def encode_labels(labels: Any) -> NDArray[np.float32]:
    """A label map as an evenly spaced grey image in [0, 1], for writing and hand editing.

    Label ``j`` of the sorted distinct labels ``v_0 < … < v_{n-1}`` becomes ``j / (n - 1)``.
    :func:`decode_labels` reverses it (up to renumbering the labels ``0 … n-1``).
    """
    lab = as_labels(labels, "labels")
    values, inv = np.unique(lab, return_inverse=True)
    n = len(values)
    return (inv.reshape(lab.shape) / max(n - 1, 1)).astype(np.float32)


def decode_labels(image: Any, *, max_labels: int = 16) -> NDArray[np.int32]:
    """A label map from an image of flat colours or grey levels: ``0 … n-1`` by sorted colour.

    Raises ``ValueError`` if the image has more than ``max_labels`` distinct colours (an
    anti-aliased brush or a JPEG, most likely).
    """
    img = as_image(image, "image")
    q = np.rint(img * 255).astype(np.int64)
    key = np.zeros(img.shape[:2], np.int64)
    for c in range(img.shape[2]):
        key = key * 256 + q[..., c]
    values, inv = np.unique(key, return_inverse=True)
    if len(values) > max_labels:
        raise ValueError(
            f"image: found {len(values)} distinct colours, expected a label map of at most {max_labels} flat colours "
            "(paint with a hard brush and save as PNG)"
        )
    return inv.reshape(img.shape[:2]).astype(np.int32)


def synthesize_labels(
    labels: Any,
    size: Size,
    *,
    method: Literal["layered", "joint"] = "joint",
    order: Sequence[int] | None = None,
    rotations: Rotations = "half",
    tileable: bool = False,
    seed: Seed = 0,
    threads: int | None = None,
    progress: Progress = None,
    **options: Any,
) -> NDArray[np.int32]:
    """A new label map of any size with the shapes of ``labels`` (thesis §3.6).

    The bark-pipeline name of :func:`phloem.shapes.synthesize_labels` (Rosenberger et al. 2009
    boundary-patch shape synthesis) with the bark pipeline's defaults: the joint method, and only
    half turns of the photo's shapes (bark grows along the trunk). See there for ``method``,
    ``order``, ``rotations`` and ``options`` (``patch_size``, ``levels``, ``iterations``).

    Examples
    --------
    >>> import numpy as np, phloem
    >>> lab = phloem.bark.input_labels(phloem.data.bark(), 2)
    >>> new = phloem.bark.synthesize_labels(lab, (96, 128), seed=1)
    >>> new.shape, sorted(np.unique(new).tolist())
    ((96, 128), [0, 1])
    """
    return shapes.synthesize_labels(
        labels, size, method=method, order=order, rotations=rotations, tileable=tileable, seed=seed, threads=threads,
        progress=progress, **options,
    )  # fmt: skip


@dataclass(frozen=True)
class BarkResult:
    """Everything :func:`generate` made, for inspection, editing and resuming.

    Attributes
    ----------
    texture : numpy.ndarray of float32, shape (h, w, C)
        The bark texture, with the photo's colour channels (alpha dropped).
    height : numpy.ndarray of float32, shape (h, w), or None
        The synthesised height map, when a height map was given.
    labels_in : numpy.ndarray of int32, shape (H, W)
        The photo's label map (edge label included when ``edge_label`` was set).
    labels_out : numpy.ndarray of int32, shape (h, w)
        The output label map the texture was painted by.
    sources : numpy.ndarray of int32, shape (h, w, 2)
        The photo's (row, col) each output pixel was copied from.
    """

    texture: NDArray[np.float32]
    height: NDArray[np.float32] | None
    labels_in: NDArray[np.int32]
    labels_out: NDArray[np.int32]
    sources: NDArray[np.int32]


def _stage(progress: Progress, lo: int, hi: int) -> Progress:
    """A progress callback that maps a stage's ``done/total`` into ``lo … hi`` of 100."""
    if progress is None:
        return None

    def report(done: int, total: int) -> None:
        progress(lo + (hi - lo) * done // max(total, 1), 100)

    return report


@overload
def generate(
    image: Any,
    size: Size | None = ...,
    *,
    n_labels: int = ...,
    height_map: Any = ...,
    labels_in: Any = ...,
    labels_out: Any = ...,
    method: Literal["layered", "joint"] = ...,
    rotations: Rotations = ...,
    edge_label: bool = ...,
    tileable: bool = ...,
    denoise: float = ...,
    label_weight: float = ...,
    feature_weight: float = ...,
    stand_in_weight: float | None = ...,
    init: Literal["smart", "random"] = ...,
    seed: Seed = ...,
    threads: int | None = ...,
    progress: Progress = ...,
    full_output: Literal[False] = ...,
) -> NDArray[np.float32]: ...
@overload
def generate(
    image: Any,
    size: Size | None = ...,
    *,
    n_labels: int = ...,
    height_map: Any = ...,
    labels_in: Any = ...,
    labels_out: Any = ...,
    method: Literal["layered", "joint"] = ...,
    rotations: Rotations = ...,
    edge_label: bool = ...,
    tileable: bool = ...,
    denoise: float = ...,
    label_weight: float = ...,
    feature_weight: float = ...,
    stand_in_weight: float | None = ...,
    init: Literal["smart", "random"] = ...,
    seed: Seed = ...,
    threads: int | None = ...,
    progress: Progress = ...,
    full_output: Literal[True],
) -> BarkResult: ...


@renamed(labels="n_labels", return_intermediates=old_flag(lambda r: r))
def generate(
    image: Any,
    size: Size | None = None,
    *,
    n_labels: int = 2,
    height_map: Any = None,
    labels_in: Any = None,
    labels_out: Any = None,
    method: Literal["layered", "joint"] = "joint",
    rotations: Rotations = "half",
    edge_label: bool = False,
    tileable: bool = False,
    denoise: float = 10.0,
    label_weight: float = 3.0,
    feature_weight: float = 8.0,
    stand_in_weight: float | None = 5.0,
    init: Literal["smart", "random"] = "smart",
    seed: Seed = 0,
    threads: int | None = None,
    progress: Progress = None,
    full_output: bool = False,
) -> NDArray[np.float32] | BarkResult:
    """A bark texture of any size from one small bark photo: the whole pipeline of the thesis.

    1. the photo's label map (:func:`input_labels`, §3.5), unless ``labels_in`` is given;
    2. a new label map of ``size`` (:func:`synthesize_labels`, §3.6), unless ``labels_out``
       is given;
    3. optionally an edge label on both maps (:func:`add_edge_label`, §3.5.5);
    4. texture-by-numbers (:func:`phloem.texture.by_numbers`, §3.3–3.4) paints the new map with
       the photo, its height map (if any) synthesised along as an extra channel.

    Give ``labels_in`` and/or ``labels_out`` to resume from maps written earlier (and perhaps
    edited by hand; see :func:`encode_labels` / :func:`decode_labels`), as §3.2 suggests.

    Parameters
    ----------
    image : array_like, shape (H, W, C) or (H, W)
        The bark photo (uint8/uint16 scaled to [0, 1]; an alpha channel is dropped).
    size : int or (int, int), optional
        Output (height, width). Required unless ``labels_out`` is given (its shape is used).
    n_labels : int, optional
        Number of regions of the input label map (default 2; §4.3 found 2–3 work best).
        ``labels`` before (deprecated).
    height_map : array_like, shape (H, W), optional
        A height (or any other) map of the photo, synthesised along with the colours.
    labels_in, labels_out : array_like of int, optional
        Ready-made input / output label maps (skip stages 1 / 2).
    method : {"layered", "joint"}, optional
        Label-map synthesis (:func:`phloem.shapes.synthesize_labels`): phloem's joint
        multi-label variant (default), or the thesis' nested layers (§3.6.4). Joint scores
        better on Eq. 3.9 on all four of the thesis' runs and does not degrade beyond three
        labels as layers do (§4.4).
    rotations : {"half", "all", "none"}, optional
        Which turns of the photo's shapes label-map synthesis may use (Eq. 3.7; see
        :func:`phloem.shapes.synthesize`). Default "half" (0° and 180°): bark grows along the
        trunk, and shapes turned by 90° make furrows look woven. "all" allows all four turns,
        for bark without a grain such as plane trees; "none" none.
    edge_label : bool, optional
        Add the §3.5.5 edge region to both maps before texture-by-numbers (default False).
    tileable : bool, optional
        Make the label map and the texture wrap around, so the output tiles (default False).
    denoise : float, optional
        Non-local-means strength of :func:`input_labels` (default 10).
    label_weight, feature_weight : float, optional
        The thesis' ``w`` (default 3) and ``z`` (default 8) of texture-by-numbers (§3.3.4).
    stand_in_weight : float or None, optional
        Cost of label stand-ins in texture-by-numbers (default 5; None: the texture follows
        the label map's every boundary, seams and all): see
        :func:`phloem.texture.by_numbers`. Pass None when painting a hand-edited map whose
        exact shapes matter more than seamless pieces.
    init : {"smart", "random"}, optional
        Texture-by-numbers initialisation (§3.4; default "smart").
    seed : int or numpy.random.Generator, optional
        Seed of every random choice; each stage gets its own stream derived from it.
    threads : int, optional
        Worker threads (default: ``PHLOEM_NUM_THREADS`` or all cores).
    progress : callable, optional
        ``progress(done, total)`` with ``total = 100`` over the whole pipeline.
    full_output : bool, optional
        Return a :class:`BarkResult` with the label maps, height map and sources
        (``return_intermediates`` before; it still works, deprecated).

    Returns
    -------
    numpy.ndarray of float32, shape (h, w, C), or BarkResult
        The texture (colour channels of the photo), or everything with ``full_output``.

    Examples
    --------
    >>> import phloem
    >>> out = phloem.bark.generate(phloem.data.bark(), (96, 128), seed=2)
    >>> out.shape, out.dtype
    ((96, 128, 3), dtype('float32'))
    """
    img = as_image(image, "image")
    if img.shape[2] in (2, 4):
        img = img[..., :-1]
    img = np.ascontiguousarray(img)
    threads = check_threads(threads)
    seeds = np.random.SeedSequence(check_seed(seed)).generate_state(3, np.uint64)
    if labels_in is None:
        lab_in = input_labels(img, n_labels, denoise=denoise, seed=int(seeds[0]))
    else:
        lab_in = as_labels(labels_in, "labels_in")
        if lab_in.shape != img.shape[:2]:
            raise ValueError(f"labels_in: expected shape {img.shape[:2]} to match image, got {lab_in.shape}")
    if progress is not None:
        progress(10, 100)
    if labels_out is None:
        if size is None:
            raise ValueError("size: required unless labels_out is given")
        shape = check_size(size)
        lab_out = synthesize_labels(
            lab_in, shape, method=method, rotations=rotations, tileable=tileable, seed=int(seeds[1]), threads=threads,
            progress=_stage(progress, 10, 40),
        )  # fmt: skip
    else:
        lab_out = as_labels(labels_out, "labels_out")
        if size is not None and check_size(size) != lab_out.shape:
            raise ValueError(f"size: {check_size(size)} does not match labels_out of shape {lab_out.shape}")
    if edge_label:
        edge = int(max(lab_in.max(), lab_out.max())) + 1
        lab_in = add_edge_label(lab_in, label=edge)
        lab_out = add_edge_label(lab_out, label=edge)
    channels = img.shape[2]
    ex = img
    if height_map is not None:
        hm = as_image(height_map, "height_map")
        if hm.shape[:2] != img.shape[:2] or hm.shape[2] != 1:
            raise ValueError(f"height_map: expected shape {img.shape[:2]} to match image, got {hm.shape}")
        ex = np.ascontiguousarray(np.concatenate([img, hm], axis=2))
    painted = texture.by_numbers(
        ex, lab_in, lab_out, label_weight=label_weight, feature_weight=feature_weight, init=init,
        stand_in_weight=stand_in_weight,
        tileable=tileable, seed=int(seeds[2]), threads=threads, full_output=True,
        progress=_stage(progress, 40, 100),
    )  # fmt: skip
    out, sources = painted.image, painted.sources
    tex = np.ascontiguousarray(out[..., :channels])
    height = np.ascontiguousarray(out[..., channels]) if height_map is not None else None
    if not full_output:
        return tex
    return BarkResult(texture=tex, height=height, labels_in=lab_in, labels_out=lab_out, sources=sources)


def cylinder_preview(
    texture: Any,
    *,
    height: Any = None,
    bump: float = 2.0,
    light: tuple[float, float, float] = (-0.6, 0.4, 1.0),
    ambient: float = 0.3,
) -> NDArray[np.float32]:
    """The texture wrapped once around a vertical trunk, seen from the front (orthographic).

    The texture's width is the trunk's circumference, so the visible half shows half of it, with
    the columns squeezed towards the silhouette as on a real trunk. Lambert shading from
    ``light``; with a ``height`` map, its gradient (scaled by ``bump``) tilts the normals.

    Parameters
    ----------
    texture : array_like, shape (H, W, C) or (H, W)
    height : array_like, shape (H, W), optional
    bump : float, optional
        Strength of the height map's relief (default 2).
    light : (float, float, float), optional
        Direction towards the light (x right, y up, z towards the viewer).
    ambient : float, optional
        Light reaching every visible point (default 0.3).

    Returns
    -------
    numpy.ndarray of float32, shape (H, round(W / π) + 2, C)
        Black outside the trunk.

    Examples
    --------
    >>> import phloem
    >>> phloem.bark.cylinder_preview(phloem.data.bark()[..., :3]).shape
    (256, 83, 3)
    """
    tex = as_image(texture, "texture")
    h, w, _ = tex.shape

    radius = w / (2 * math.pi)
    out_w = round(2 * radius) + 2
    xs = (np.arange(out_w, dtype=np.float64) + 0.5 - out_w / 2) / radius
    inside = np.abs(xs) < 1
    theta = np.arcsin(np.clip(xs, -1, 1))
    u = (theta / (2 * math.pi) + 0.25) * w  # the front half shows columns w/4 … 3w/4 around the centre w/2
    mapx = np.ascontiguousarray(np.broadcast_to((u - 0.5).astype(np.float32), (h, out_w)))
    mapy = np.ascontiguousarray(np.broadcast_to(np.arange(h, dtype=np.float32)[:, None], (h, out_w)))
    img = cv2.remap(tex, mapx, mapy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
    if img.ndim == 2:
        img = img[:, :, None]
    nx = np.broadcast_to(np.sin(theta), (h, out_w)).copy()
    ny = np.zeros((h, out_w))
    nz = np.broadcast_to(np.cos(theta), (h, out_w)).copy()
    if height is not None:
        hm = as_image(height, "height")
        if hm.shape[:2] != (h, w):
            raise ValueError(f"height: expected shape {(h, w)} to match texture, got {hm.shape[:2]}")
        hv = cv2.remap(hm[..., 0], mapx, mapy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        du = np.gradient(hv, axis=1) * bump
        dv = np.gradient(hv, axis=0) * bump
        # tangent frame: around the trunk (cos θ, 0, -sin θ) and up (0, 1, 0); image rows grow downwards
        nx, ny, nz = nx - du * np.cos(theta), ny + dv, nz + du * np.sin(theta)
    norm = np.sqrt(nx**2 + ny**2 + nz**2)
    lv = np.asarray(light, np.float64)
    lv = lv / np.linalg.norm(lv)
    shade = ambient + (1 - ambient) * np.clip((nx * lv[0] + ny * lv[1] + nz * lv[2]) / norm, 0, None)
    res = img * shade[:, :, None].astype(np.float32)
    res[:, ~inside] = 0
    return np.ascontiguousarray(res, dtype=np.float32)
