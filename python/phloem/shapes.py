"""Shape synthesis: new binary shapes and label maps like an example (Rosenberger et al. 2009).

The boundary-patch shape optimiser of thesis §3.6 (paper 001), in phloem's Rust core: from
random noise with the exemplar's area fraction, on an image pyramid from coarse to fine,
every boundary patch of the output is matched to an exemplar boundary patch (under four
rotations, each exemplar patch used equally often), the matched patches vote on the pixels
they cover, and the pixels are re-labelled so that every label keeps the exemplar's area.
Label maps are made as nested layers (``method="layered"``, the paper's layer maps) or with all
labels optimised together (``method="joint"``, which the thesis' results suggest for more than
a few labels). :func:`shape_similarity` is the paper's measure (Eq. 3.9).
"""

from __future__ import annotations

import numbers
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from . import _core, _memory
from ._api import Seed, Size, warn_deprecated
from ._progress import Progress
from ._validate import as_mask, check_int, check_patch_size, check_seed, check_size, check_threads

__all__ = [
    "MAX_LABELS",
    "MAX_PATCH",
    "METHODS",
    "ROTATIONS",
    "Rotations",
    "chord_length",
    "layer_order",
    "shape_similarity",
    "synthesize",
    "synthesize_labels",
]

#: The largest patch side (121 pixels fit in one 128-bit word).
MAX_PATCH = 11
#: The largest number of labels of a label map.
MAX_LABELS = 64
#: The ways :func:`synthesize_labels` makes a label map.
METHODS = ("layered", "joint")
#: The values of ``rotations``: which 90° turns of the example's boundary patches count.
ROTATIONS = ("all", "half", "none")
_TURNS = {"all": 4, "half": 2, "none": 1}

#: The type of ``rotations`` (True and False, the old spellings of "all" and "none", still
#: work for one release with a ``DeprecationWarning``).
Rotations = Literal["all", "half", "none"]


def _labels(labels: Any, name: str) -> tuple[NDArray[np.uint8], NDArray[Any]]:
    """``labels`` as compact ``uint8`` labels 0..k-1 and the original values (ascending)."""
    arr = np.asarray(labels)
    if arr.ndim != 2:
        raise ValueError(f"{name}: expected a 2-D label map, got shape {arr.shape}")
    if 0 in arr.shape:
        raise ValueError(f"{name}: expected a non-empty map, got shape {arr.shape}")
    if arr.dtype == np.bool_:
        arr = arr.astype(np.uint8)
    elif np.issubdtype(arr.dtype, np.floating):
        if not np.isfinite(arr).all():
            raise ValueError(f"{name}: expected finite values, found NaN or infinity")
        if (arr != np.round(arr)).any():
            raise ValueError(f"{name}: expected whole-number labels")
    elif not np.issubdtype(arr.dtype, np.integer):
        raise TypeError(f"{name}: expected an integer label map, got dtype {arr.dtype}")
    values, inverse = np.unique(arr, return_inverse=True)
    if len(values) > MAX_LABELS:
        raise ValueError(f"{name}: expected at most {MAX_LABELS} labels, got {len(values)}")
    return np.ascontiguousarray(inverse.reshape(arr.shape).astype(np.uint8)), values


def _turns(rotations: Any) -> int:
    """How many 90° turns ``rotations`` allows: 4 ("all"), 2 ("half") or 1 ("none")."""
    if rotations is True or rotations is False or isinstance(rotations, np.bool_):
        new = "all" if rotations else "none"
        warn_deprecated(f"rotations={bool(rotations)} is deprecated and goes in the next release; use {new!r}")
        rotations = new
    if isinstance(rotations, str) and rotations in _TURNS:
        return _TURNS[rotations]
    raise ValueError(f"rotations: expected one of {ROTATIONS}, got {rotations!r}")


def _patch_size(patch_size: Any) -> int:
    p = check_patch_size(patch_size)
    if p > MAX_PATCH:
        raise ValueError(f"patch_size: expected an odd size <= {MAX_PATCH}, got {p}")
    return p


def _options(
    patch_size: Any, levels: Any, iterations: Any, size: Any, example: tuple[int, ...], name: str
) -> tuple[int, int, int, int, int]:
    """Checked ``(patch_size, levels, iterations, height, width)``; the output ``size`` and the
    example map ``name`` of shape ``example`` must both hold a patch."""
    p = _patch_size(patch_size)
    lev = 0 if levels is None else check_int(levels, "levels", 1)
    its = check_int(iterations, "iterations", 1)
    h, w = check_size(size)
    if h < p or w < p:
        raise ValueError(f"size: expected at least {p}×{p} (patch_size), got {h}×{w}")
    if example[0] < p or example[1] < p:
        raise ValueError(f"{name}: expected at least {p}×{p} pixels (patch_size), got {example[0]}×{example[1]}")
    return p, lev, its, h, w


def synthesize(
    shape: Any,
    size: Size,
    *,
    patch_size: int = 11,
    levels: int | None = None,
    iterations: int = 5,
    rotations: Rotations = "all",
    tileable: bool = False,
    mask: Any = None,
    seed: Seed = 0,
    threads: int | None = None,
    progress: Progress = None,
    max_memory: int | None = None,
) -> NDArray[np.bool_]:
    """A new binary shape of ``size`` like ``shape`` (Rosenberger et al. 2009).

    Parameters
    ----------
    shape : (M, N) array_like of bool
        The example shape (any non-zero value is inside). Needs both inside and outside pixels.
    size : int or (int, int)
        Output ``(height, width)``; an int makes a square. At least ``patch_size`` on each side.
    patch_size : int, optional
        Side of the boundary patches, odd, at most :data:`MAX_PATCH` (default 11). Larger
        patches keep larger structures.
    levels : int, optional
        Pyramid levels (default: as many as keep the coarsest exemplar and output three
        patches wide, at most 6).
    iterations : int, optional
        Matching and adjustment steps per level (default 5); a level stops early once the
        shape no longer changes.
    rotations : {"all", "half", "none"}, optional
        The turns under which boundary patches are compared: ``"all"`` (default, the paper)
        all four 90° rotations; ``"none"``, for shapes with a preferred direction;
        ``"half"`` 0° and 180° only, which keeps a vertical axis vertical (e.g. bark furrows
        along the trunk) while still mirroring their ends.
    tileable : bool, optional
        Make the output wrap around (toroidal), so it tiles seamlessly.
    mask : (H, W) array_like of bool, optional
        Where the shape may be; it stays outside elsewhere and covers the exemplar's area
        fraction of the masked pixels.
    seed : int or numpy.random.Generator, optional
        The same seed gives the same shape for any ``threads``.
    threads : int, optional
        Worker threads (default ``PHLOEM_NUM_THREADS`` or all cores).
    progress : callable, optional
        Called as ``progress(done, total)`` after every iteration; an exception it raises
        stops the run.
    max_memory : int, optional
        Refuse the job with :class:`phloem.MemoryLimitError` if its estimated peak memory is
        over this many bytes (default None: 75% of the machine's memory; see ``docs/hardening/memory.md``).

    Returns
    -------
    (H, W) ndarray of bool
        The new shape; its area fraction equals the exemplar's.

    References
    ----------
    .. [1] A. Rosenberger, D. Cohen-Or, D. Lischinski, "Layered shape synthesis: automatic
       generation of control maps for non-stationary textures", ACM TOG 28(5), 2009.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> yy, xx = np.mgrid[:64, :64]
    >>> spots = (np.sin(yy / 4.0) * np.sin(xx / 5.0)) > 0.3
    >>> out = phloem.shapes.synthesize(spots, 80, patch_size=7, seed=1)
    >>> out.shape, out.dtype
    ((80, 80), dtype('bool'))
    >>> bool(abs(out.mean() - spots.mean()) < 0.01)
    True
    """
    _labels(shape, "shape")  # checks ndim, dtype and finiteness
    ex = (np.asarray(shape) != 0).astype(np.uint8)
    if ex.all() or not ex.any():
        raise ValueError("shape: expected both inside and outside pixels, the shape is empty or full")
    p, lev, its, h, w = _options(patch_size, levels, iterations, size, ex.shape, "shape")
    _memory.check_size(_memory.shapes_synthesize((h, w), ex.shape), max_memory, (h, w))
    m = None if mask is None else as_mask(mask, "mask", (h, w))
    out = _core.shape_synthesize(
        np.ascontiguousarray(ex),
        height=h,
        width=w,
        patch_size=p,
        levels=lev,
        iterations=its,
        rotations=_turns(rotations),
        tileable=bool(tileable),
        seed=check_seed(seed),
        mask=m,
        threads=check_threads(threads),
        progress=progress,
    )
    return np.asarray(out, dtype=bool)


def layer_order(labels: Any) -> list[int]:
    """The layer order :func:`synthesize_labels` infers for ``labels``, bottom layer first.

    In a map of nested layers, boundaries run between consecutive layers; the order chosen is
    the one whose boundaries between non-consecutive layers are shortest (all orders are tried
    for up to 7 labels), with its larger end at the bottom. Beyond 7 labels, and among equally
    good orders, labels go by decreasing area (the largest is the ground the others lie on).

    Examples
    --------
    >>> import numpy as np, phloem
    >>> yy, xx = np.mgrid[:40, :40]
    >>> r2 = (yy - 20) ** 2 + (xx - 20) ** 2
    >>> rings = np.where(r2 < 64, 5, np.where(r2 < 100, 9, 0))   # 5 inside 9 on 0
    >>> phloem.shapes.layer_order(rings)
    [0, 9, 5]
    """
    lab, values = _labels(labels, "labels")
    order = _core.shape_layer_order(lab, k=len(values))
    return [int(values[i]) for i in order]


def synthesize_labels(
    labels: Any,
    size: Size,
    *,
    method: Literal["layered", "joint"] = "layered",
    order: Any = None,
    patch_size: int = 11,
    levels: int | None = None,
    iterations: int = 5,
    rotations: Rotations = "all",
    tileable: bool = False,
    seed: Seed = 0,
    threads: int | None = None,
    progress: Progress = None,
    max_memory: int | None = None,
) -> NDArray[np.int32]:
    """A new label map of ``size`` like ``labels`` (Rosenberger et al. 2009, thesis §3.6.4).

    Parameters
    ----------
    labels : (M, N) array_like of int
        The example label map, e.g. from k-means on a bark photo; 2 to :data:`MAX_LABELS`
        distinct values.
    size : int or (int, int)
        Output ``(height, width)``.
    method : {"layered", "joint"}, optional
        ``"layered"`` (default): the labels are nested layers in ``order``; each layer is a
        binary shape synthesised inside the previous one (the paper's layer maps).
        ``"joint"``: all labels are optimised together, boundary patches matched within each
        pair of labels that meet; better for more than two or three labels.
    order : sequence of int, optional
        The label values bottom layer first; default :func:`layer_order`. Used by the layered
        method only (checked, then ignored, by the joint one).
    patch_size, levels, iterations, rotations, tileable, seed, threads, progress
        As in :func:`synthesize`.
    max_memory : int, optional
        Refuse the job with :class:`phloem.MemoryLimitError` if its estimated peak memory is
        over this many bytes (default None: 75% of the machine's memory; see ``docs/hardening/memory.md``).

    Returns
    -------
    (H, W) ndarray of int32
        The new map, with the values of ``labels``; every label keeps its area fraction.

    References
    ----------
    .. [1] A. Rosenberger, D. Cohen-Or, D. Lischinski, "Layered shape synthesis: automatic
       generation of control maps for non-stationary textures", ACM TOG 28(5), 2009.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> yy, xx = np.mgrid[:64, :64]
    >>> lab = (np.sin(yy / 4.0) * np.sin(xx / 5.0) > 0.3) + 2 * (np.cos(xx / 6.0 + yy / 9.0) > 0.8)
    >>> out = phloem.shapes.synthesize_labels(lab, 72, method="joint", patch_size=7)
    >>> sorted(np.unique(out).tolist()), out.dtype
    ([0, 1, 2, 3], dtype('int32'))
    """
    if method not in METHODS:
        raise ValueError(f"method: expected one of {METHODS}, got {method!r}")
    lab, values = _labels(labels, "labels")
    k = len(values)
    if k < 2:
        raise ValueError("labels: expected at least 2 distinct labels, got 1 (the map is empty)")
    p, lev, its, h, w = _options(patch_size, levels, iterations, size, lab.shape, "labels")
    _memory.check_size(_memory.shapes_labels((h, w), lab.shape, k), max_memory, (h, w))
    idx: list[int] | None = None
    if order is not None:
        try:
            items = list(order)
        except TypeError:
            raise TypeError(f"order: expected a sequence of label values, got {order!r}") from None
        if any(isinstance(v, bool) or not isinstance(v, numbers.Integral | np.integer) for v in items):
            raise TypeError(f"order: expected integer label values, got {order!r}")
        lookup = {int(v): i for i, v in enumerate(values)}
        if sorted(int(v) for v in items) != sorted(lookup):
            raise ValueError(f"order: expected a permutation of the labels {sorted(lookup)}, got {items}")
        idx = [lookup[int(v)] for v in items]
    out = _core.shape_synthesize_labels(
        lab,
        k=k,
        height=h,
        width=w,
        method=method,
        patch_size=p,
        levels=lev,
        iterations=its,
        rotations=_turns(rotations),
        tileable=bool(tileable),
        seed=check_seed(seed),
        order=idx,
        threads=check_threads(threads),
        progress=progress,
    )
    return np.asarray(values.astype(np.int32)[out], dtype=np.int32)


def shape_similarity(
    a: Any, b: Any, *, patch_size: int = 7, rotations: Rotations = "all", threads: int | None = None
) -> float:
    """The shape distance of Rosenberger et al. (thesis Eq. 3.7–3.9); lower is more alike.

    For every boundary pixel of either map (a pixel with a 4-neighbour of another label), the
    number of differing pixels between its ``patch_size²`` patch and the closest boundary
    patch of the other map (under the four 90° rotations of that patch with ``rotations``);
    the mean over the boundary pixels of both maps. Works for binary shapes and label maps
    (label values are compared as given) of any sizes. Patches reaching past a border repeat
    the border pixels. 0 when neither map has a boundary, infinite when only one has.

    Parameters
    ----------
    a, b : (M, N) array_like of int or bool
        The two maps.
    patch_size : int, optional
        Odd patch side, at most :data:`MAX_PATCH` (default 7).
    rotations : {"all", "half", "none"}, optional
        Minimise over the four 90° rotations of the other map's patch (Eq. 3.7; ``"all"``,
        the default), none (``"none"``) or the half-turn only (``"half"``).
    threads : int, optional
        Worker threads (default: ``PHLOEM_NUM_THREADS`` or all cores); the same value for any.

    Returns
    -------
    float

    Examples
    --------
    >>> import numpy as np, phloem
    >>> yy, xx = np.mgrid[:32, :32]
    >>> a = yy > 2 * xx                      # a steep wedge
    >>> phloem.shapes.shape_similarity(a, np.rot90(a))
    0.0
    >>> phloem.shapes.shape_similarity(a, np.rot90(a), rotations="none") > 1
    True
    """
    p = _patch_size(patch_size)
    turns = _turns(rotations)
    arr_a, arr_b = np.asarray(a), np.asarray(b)
    # Compare label values as given: map both through the union of their values.
    la, va = _labels(arr_a, "a")
    lb, vb = _labels(arr_b, "b")
    union = np.union1d(va, vb)
    if len(union) > MAX_LABELS:
        raise ValueError(f"b: expected at most {MAX_LABELS} labels in a and b together, got {len(union)}")
    ua = np.searchsorted(union, va).astype(np.uint8)[la]
    ub = np.searchsorted(union, vb).astype(np.uint8)[lb]
    sim = _core.shape_similarity(
        np.ascontiguousarray(ua),
        np.ascontiguousarray(ub),
        patch_size=p,
        rotations=turns,
        threads=check_threads(threads),
    )
    return float(sim)


def chord_length(labels: Any) -> float:
    """The scale of a shape or label map: its pixel-weighted mean chord length, in pixels.

    A chord is a maximal run of equal labels along a row or a column; each pixel counts the
    length of the two chords through it (runs cut by the border count as they are), and the
    mean is over all pixels and both directions, i.e. ``Σ L² / Σ L`` over all chords. Large
    smooth regions give long chords, speckle short ones; weighting by pixels keeps a few
    specks from hiding the large regions. Compare an output's value with its exemplar's to
    see whether the synthesis kept the exemplar's blob size.

    Parameters
    ----------
    labels : (M, N) array_like of int or bool
        A shape or label map.

    Returns
    -------
    float

    Examples
    --------
    >>> import numpy as np, phloem
    >>> stripes = (np.arange(40)[None, :] // 4 % 2).repeat(40, axis=0)   # 4-px columns
    >>> phloem.shapes.chord_length(stripes)                             # (40 + 4) / 2
    22.0
    """
    lab, _ = _labels(labels, "labels")
    total, count = 0.0, 0
    for a in (lab, lab.T):
        start = np.ones(a.shape, dtype=bool)  # where a run starts; every row starts one
        start[:, 1:] = a[:, 1:] != a[:, :-1]
        runs = np.diff(np.append(np.flatnonzero(start.ravel()), a.size))
        total += float((runs.astype(np.float64) ** 2).sum())
        count += int(runs.sum())
    return total / count
