"""Re-drawing an object along new strokes (Luo, Lin, Shen & Chen): :func:`edit`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal, overload

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage  # type: ignore[import-untyped]

from .. import _memory, blend
from .._progress import Progress
from .._validate import as_image, as_mask, check_float, check_threads
from . import fetch as _fetch
from .compose import compose, keep_on_strokes, seam_map
from .sampling import Sampling, sample
from .stroke_set import StrokeError, StrokeSet
from .tone import match_seams

__all__ = ["EditResult", "edit"]

F32 = NDArray[np.float32]
SAMPLINGS = ("dp", "uniform")


@dataclass(frozen=True)
class EditResult:
    """What :func:`edit` made (``full_output=True``).

    Attributes
    ----------
    image : (H, W, 4) ndarray of float32
        The object re-drawn along the target strokes, on a transparent background (or pasted
        into ``background``).
    pieces : (H, W) ndarray of int32
        The piece each pixel comes from (numbered along each stroke, stroke after stroke), -1
        where none.
    seams : (H, W) ndarray of bool
        Pixels where two pieces meet.
    stroke_of_piece : (P,) ndarray of int32
        The stroke pair each piece belongs to.
    samplings : list of Sampling
        Per stroke pair, the target samples and the source positions the dynamic programme
        chose for them, with its energy and the uniform mapping's.
    energy : float
        The summed energy of the composition's cuts.
    mask : (h, w) ndarray of bool
        The source object's mask that was used.
    """

    image: F32
    pieces: NDArray[np.int32]
    seams: NDArray[np.bool_]
    stroke_of_piece: NDArray[np.int32]
    samplings: list[Sampling]
    energy: float
    mask: NDArray[np.bool_]


def _object_alpha(img: F32, mask: Any) -> F32:
    """The source object's alpha: ``mask`` if given, else the image's own alpha if it has one,
    else the objects :func:`phloem.leaves.extract` finds on a plain background."""
    h, w = img.shape[:2]
    if mask is not None:
        m = as_mask(mask, "mask", (h, w))
        if not m.any():
            raise ValueError("mask: is empty; expected the object's pixels set")
        return m.astype(np.float32)
    if img.shape[2] in (2, 4):
        alpha = np.clip(img[..., -1], 0.0, 1.0)
        if not (alpha > 0).any():
            raise ValueError("image: its alpha is zero everywhere; expected the object opaque")
        return np.ascontiguousarray(alpha)
    from ..leaves import extract  # the background removal of the leaves pipeline

    try:
        found = extract(img, full_output=True)
    except ValueError:
        raise ValueError(
            "mask: none given, the image has no alpha, and no object stands out from a plain background; pass mask="
        ) from None
    alpha = np.zeros((h, w), np.float32)
    for leaf, (y0, y1, x0, x1) in zip(found.leaves, found.boxes, strict=True):
        sy0, sx0 = max(0, -y0), max(0, -x0)
        ty0, tx0 = max(0, y0), max(0, x0)
        ty1, tx1 = min(h, y1), min(w, x1)
        part = leaf[sy0 : sy0 + ty1 - ty0, sx0 : sx0 + tx1 - tx0, 3]
        alpha[ty0:ty1, tx0:tx1] = np.maximum(alpha[ty0:ty1, tx0:tx1], part)
    return alpha


def _rgb(img: F32) -> F32:
    c = img.shape[2]
    if c in (1, 2):
        return np.repeat(img[..., :1], 3, axis=2)
    if c in (3, 4):
        return img[..., :3]
    raise ValueError(f"image: expected 1 to 4 channels (gray, gray + alpha, RGB, RGBA), got {c}")


def _stroke_set(source: Any, target: Any, controls: Any, widths: Any, shape: tuple[int, int], size: Any) -> StrokeSet:
    if isinstance(source, StrokeSet):
        if target is not None or controls is not None or widths is not None:
            raise ValueError(
                "target: expected None when source is a StrokeSet (it holds the targets, controls and widths)"
            )
        sset = source
        if size is None and sset.target_size is not None:
            size = sset.target_size
        if sset.source_shape is not None and sset.source_shape != shape:
            raise StrokeError(f"source: the stroke set is for a {sset.source_shape} image, got {shape}")
    elif target is None:
        raise ValueError("target: expected the target strokes (or pass a StrokeSet as source)")
    else:
        sset = StrokeSet.from_lists(source, target, controls=controls, widths=widths)
    return StrokeSet(sset.pairs, source_shape=shape, target_size=shape if size is None else _size(size))


def _size(size: Any) -> tuple[int, int]:
    ok = isinstance(size, (tuple, list)) and len(size) == 2
    ok = ok and all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 1 for v in size)
    if not ok:
        raise ValueError(f"size: expected (H, W) with two positive integers, got {size!r}")
    return int(size[0]), int(size[1])


def _into(rgba: F32, scene: F32, *, threads: int | None) -> F32:
    """``rgba`` pasted into ``scene`` by Poisson image editing over its opaque part, its soft
    edge blended by alpha; opaque."""
    alpha = rgba[..., 3:]
    inside = alpha[..., 0] >= 0.5
    if not inside.any():
        return np.ascontiguousarray(np.concatenate([scene, np.ones_like(alpha)], axis=2), dtype=np.float32)
    # Off the object its colours are undefined: each takes the nearest object colour, so no
    # gradient is imported across the object's border and the border takes the scene's colour.
    near = ndimage.distance_transform_edt(~inside, return_distances=False, return_indices=True)
    src = rgba[..., :3][near[0], near[1]]
    pasted = blend.seamless(src, scene, inside, (0, 0), threads=threads)
    rgb = np.clip(alpha * pasted + (1 - alpha) * scene, 0.0, 1.0)
    return np.ascontiguousarray(np.concatenate([rgb, np.ones_like(alpha)], axis=2), dtype=np.float32)


@overload
def edit(
    image: Any,
    source: Any,
    target: Any = ...,
    *,
    size: Any = ...,
    mask: Any = ...,
    controls: Any = ...,
    widths: Any = ...,
    spacing: float | None = ...,
    stretch: float = ...,
    sampling: str = ...,
    background: Any = ...,
    threads: int | None = ...,
    progress: Progress = ...,
    max_memory: int | None = ...,
    full_output: Literal[False] = ...,
) -> F32: ...
@overload
def edit(
    image: Any,
    source: Any,
    target: Any = ...,
    *,
    size: Any = ...,
    mask: Any = ...,
    controls: Any = ...,
    widths: Any = ...,
    spacing: float | None = ...,
    stretch: float = ...,
    sampling: str = ...,
    background: Any = ...,
    threads: int | None = ...,
    progress: Progress = ...,
    max_memory: int | None = ...,
    full_output: Literal[True],
) -> EditResult: ...
def edit(
    image: Any,
    source: Any,
    target: Any = None,
    *,
    size: Any = None,
    mask: Any = None,
    controls: Any = None,
    widths: Any = None,
    spacing: float | None = None,
    stretch: float = 2.0,
    sampling: str = "dp",
    background: Any = None,
    threads: int | None = None,
    progress: Progress = None,
    max_memory: int | None = None,
    full_output: bool = False,
) -> F32 | EditResult:
    """Re-draw the object of ``image`` along new strokes (Luo, Lin, Shen & Chen).

    Each source stroke runs along the object's skeleton in ``image``; the object is
    synthesised along the corresponding target stroke in a new image, bent, stretched or
    branched, its texture running along the stroke. Samples about ``spacing`` apart along
    each target stroke take a piece of the object around a corresponding source sample,
    turned so that the strokes' directions agree and as wide as the object is there (only the
    object pixels nearest that source stroke); which source sample, between the control
    pairs, is chosen by dynamic programming so that the compositing energy of neighbouring
    pieces is least; the pieces are joined by graph cuts with the paper's energy (Eqs. 1–2).
    Strokes that meet compose into one object; parts of the result that touch no target stroke
    (slivers from beyond a stroke's end) are dropped. The method has no random choice: the same
    input gives the same image at any thread count.

    Parameters
    ----------
    image : (h, w[, C]) array_like
        The photo of the object: gray, RGB or with alpha; uint8, uint16 or float in [0, 1].
    source : StrokeSet or list of (N, 2) array_like
        The source strokes as ``(x, y)`` points on ``image``, or a stroke set holding sources,
        targets and controls (then ``target`` and ``controls`` stay None).
    target : list of (N, 2) array_like
        One target stroke per source stroke, in the output's pixels.
    size : (H, W), optional
        The output's size (default: the background's, else the stroke set's ``target_size``,
        else the image's).
    mask : (h, w) array_like of bool, optional
        The object in ``image``. Default: the image's alpha when it has one (fully opaque: the
        whole image), else the objects found on a plain background as
        :func:`phloem.leaves.extract` finds them.
    controls : list of (K, 2) array_like, optional
        Per stroke pair, control pairs of arc-length fractions ``(u_source, u_target)`` from
        ``(0, 0)`` to ``(1, 1)`` (default the end points).
    widths : list, optional
        Per stroke pair, the object's width wanted along the target stroke in output px: None
        (the object's own width, the paper's default), a number, or ``(u, width)`` pairs at
        arc-length fractions of the target. Each piece is then scaled, texture and all, by the
        ratio of the wanted width to the object's width across the source stroke there
        (within 1/8 to 8). A :class:`StrokeSet`'s pairs carry their own ``width``.
    spacing : float, optional
        Distance in px between samples along a target stroke, half a piece's length (default:
        the object's median half width along the source strokes, within 4–64).
    stretch : float, optional
        Largest factor by which the dynamic programme may stretch or squeeze the source between
        neighbouring samples, relative to the uniform mapping (default 2, at least 1).
    sampling : {"dp", "uniform"}, optional
        ``"dp"`` (the paper's global texture sampling) or the uniform arc-length mapping.
    background : (H, W[, C]) array_like, optional
        A scene to put the object in: the object is pasted into it by Poisson image editing
        (:func:`phloem.blend.seamless`, its gradients kept, its colours matched to the scene at
        its border) and the result is opaque.
    threads : int, optional
        Worker threads (default: all cores).
    progress : callable, optional
        ``progress(done, total)`` as the strokes are sampled and their pieces composed.
    max_memory : int, optional
        Refuse (``phloem.MemoryLimitError``) an edit whose estimated peak memory is over this
        many bytes (default 75 % of the machine's).
    full_output : bool, optional
        Return an :class:`EditResult` with the piece map, seams and correspondences.

    Returns
    -------
    (H, W, 4) ndarray of float32
        The new image, RGBA, transparent where no piece reaches (opaque over a
        ``background``); an :class:`EditResult` with ``full_output``.

    Raises
    ------
    ValueError
        Bad image, mask or option; StrokeError (a ValueError) for strokes that are malformed,
        lie outside the image or the output, or do not pair up.

    Examples
    --------
    A striped bar drawn along a straight stroke, re-drawn along an arc:

    >>> import numpy as np, phloem
    >>> bar = np.zeros((40, 120, 4), np.float32)
    >>> bar[14:26, 10:110] = [0.6, 0.4, 0.2, 1.0]
    >>> bar[14:26, 10:110:8, :3] = 0.1
    >>> arc = [[60 + 45 * np.cos(a), 70 - 45 * np.sin(a)] for a in np.linspace(np.pi, 0, 30)]
    >>> out = phloem.strokes.edit(bar, [[[12, 20], [108, 20]]], [arc], size=(100, 120))
    >>> out.shape, bool(out[70, 15, 3] > 0.5), bool(out[20, 60, 3] > 0.5), bool(out[60, 60, 3] > 0)
    ((100, 120, 4), True, True, False)
    """
    img = as_image(image, "image")
    rgb = _rgb(img)
    alpha = _object_alpha(img, mask)
    shape = (img.shape[0], img.shape[1])
    scene = None
    if background is not None:
        scene = _rgb(as_image(background, "background"))
        if size is not None and _size(size) != scene.shape[:2]:
            raise ValueError(f"background: expected the output size {_size(size)}, got {scene.shape[:2]}")
        size = scene.shape[:2]
    sset = _stroke_set(source, target, controls, widths, shape, size)
    out_size = sset.target_size or shape
    _memory.check_size(_memory.strokes_edit(out_size, img.shape), max_memory, out_size)
    st = check_float(stretch, "stretch", 1.0)
    if sampling not in SAMPLINGS:
        raise ValueError(f"sampling: expected one of {SAMPLINGS}, got {sampling!r}")
    th = check_threads(threads)
    rgba = np.ascontiguousarray(np.concatenate([rgb, alpha[..., None]], axis=2), dtype=np.float32)
    parts = _fetch.stroke_sources(rgba, [p.source for p in sset.pairs])
    for i, part in enumerate(parts):
        if part.half_width == 0:
            raise StrokeError(f"pairs[{i}].source: the stroke does not run over the object (mask)")
    wanted = [None if p.width is None else 0.5 * float(np.median(p.width[:, 1])) for p in sset.pairs]
    h = _fetch.default_spacing(parts, wanted) if spacing is None else check_float(spacing, "spacing", 1.0)

    samplings: list[Sampling] = []
    n_pairs = len(sset.pairs)
    # Progress: each pair once sampled, then once composed.
    for i, (pair, part) in enumerate(zip(sset.pairs, parts, strict=True)):
        if progress is not None:
            progress(i, 2 * n_pairs)
        samplings.append(sample(pair, part, spacing=h, stretch=st, uniform=sampling == "uniform", threads=th))
    pieces: list[_fetch.Piece] = []
    owner: list[int] = []
    for i, (pair, part, smp) in enumerate(zip(sset.pairs, parts, samplings, strict=True)):
        rows = _fetch.specs(pair, smp.target_arc, smp.source_arc, part, smp.half_length)
        got = _fetch.fetch(part, rows, threads=th)
        pieces.extend(got)
        owner.extend([i] * len(got))

    def check(k: int) -> None:
        if progress is not None:
            progress(n_pairs + owner[k], 2 * n_pairs)

    ends = np.array([[p.target.points[0], p.target.points[-1]] for p in sset.pairs], np.float64)
    comp = compose(pieces, out_size, threads=th, owner=owner, ends=ends, check=check)
    on = np.concatenate([p.target.at(np.linspace(0, 1, max(2, int(p.target.length())))) for p in sset.pairs])
    comp = keep_on_strokes(comp, on)
    owned = np.array(owner, np.int64)
    stroke_of = np.where(comp.labels >= 0, owned[np.maximum(comp.labels, 0)], -1)
    piece_half = np.array([0.5 * sum(p.widths) for p in pieces])
    halves = np.array([np.median(piece_half[owned == i]) if (owned == i).any() else 0.0 for i in range(n_pairs)])
    rgba = match_seams(comp.rgba, stroke_of, halves, ends, threads=th)
    out = rgba if scene is None else _into(rgba, scene, threads=th)
    if progress is not None:
        progress(2 * n_pairs, 2 * n_pairs)
    if not full_output:
        return out
    return EditResult(
        image=out,
        pieces=comp.labels,
        seams=seam_map(comp.labels),
        stroke_of_piece=np.array(owner, np.int32),
        samplings=samplings,
        energy=comp.energy,
        mask=alpha > 0,
    )
