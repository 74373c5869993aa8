"""The whole bark pipeline (thesis §3.2): photo to label maps to texture, resumable from edited maps."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal, overload

import numpy as np
from numpy.typing import NDArray

from .. import _memory, texture
from .._api import Seed, Size, old_flag, renamed
from .._progress import Progress
from .._validate import as_image, as_labels, check_seed, check_size, check_threads
from ..shapes import Rotations
from .labels import add_edge_label, input_labels
from .synthesis import synthesize_labels

__all__ = ["BarkResult", "generate"]


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
    max_memory: int | None = ...,
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
    max_memory: int | None = ...,
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
    max_memory: int | None = None,
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
    max_memory : int, optional
        Refuse the job with :class:`phloem.MemoryLimitError` if its estimated peak memory is
        over this many bytes (default None: 75% of the machine's memory; see ``docs/hardening/memory.md``).
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
    if labels_out is None and size is not None:  # before the input labels: refuse in a moment, not after them
        shape = check_size(size)
        channels = img.shape[2] + (height_map is not None) + 1  # + the feature-distance channel
        _memory.check_size(_memory.bark(shape, img.shape, channels), max_memory, shape)
    seeds = np.random.SeedSequence(check_seed(seed)).generate_state(3, np.uint64)
    if labels_in is None:
        lab_in = input_labels(img, n_labels, denoise=denoise, seed=int(seeds[0]), progress=_stage(progress, 0, 10))
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
            progress=_stage(progress, 10, 40), max_memory=max_memory,
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
        progress=_stage(progress, 40, 100), max_memory=max_memory,
    )  # fmt: skip
    out, sources = painted.image, painted.sources
    tex = np.ascontiguousarray(out[..., :channels])
    height = np.ascontiguousarray(out[..., channels]) if height_map is not None else None
    if not full_output:
        return tex
    return BarkResult(texture=tex, height=height, labels_in=lab_in, labels_out=lab_out, sources=sources)
