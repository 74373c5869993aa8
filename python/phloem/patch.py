"""Patch matching: nearest-neighbour fields, k nearest patches and k-coherence candidates.

The engine is phloem's Rust core (parallel, GIL released, deterministic for a seed whatever
the number of threads). Fields map every target pixel to the *centre* of a source patch whose
``patch_size × patch_size`` footprint lies wholly inside the source; target patches are
clipped at the target border, so every target pixel gets a match.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from . import _core, _memory
from ._api import Seed
from ._validate import as_image, as_mask, check_int, check_patch_size, check_seed, check_threads

__all__ = ["EXACT_LIMIT", "candidates", "knn", "nnf", "vote"]

#: Most source × target pixel pairs :func:`nnf` accepts for ``method="exact"`` (about 2·10^10:
#: minutes on two cores). The Rust call cannot be interrupted, so larger jobs are refused.
EXACT_LIMIT = 2**34


def _weights(weights: Any, channels: int) -> NDArray[np.float32] | None:
    if weights is None:
        return None
    w = np.ascontiguousarray(np.asarray(weights, dtype=np.float32).reshape(-1))
    if w.shape != (channels,):
        raise ValueError(f"weights: expected {channels} per-channel weights, got shape {np.shape(weights)}")
    return w


def nnf(
    source: Any,
    target: Any,
    *,
    patch_size: int = 7,
    iterations: int = 5,
    method: Literal["patchmatch", "kdtree", "exact"] = "patchmatch",
    weights: Any = None,
    source_mask: Any = None,
    target_mask: Any = None,
    init: Any = None,
    levels: int = 1,
    enrich: int | NDArray[np.int32] = 0,
    tileable: bool = False,
    seed: Seed = 0,
    threads: int | None = None,
    max_memory: int | None = None,
) -> tuple[NDArray[np.int32], NDArray[np.float32]]:
    """Nearest-neighbour field from ``target`` patches to ``source`` patches.

    Parameters
    ----------
    source : (Ms, Ns[, C]) array_like
        Image the patches come from.
    target : (Mt, Nt[, C]) array_like
        Image whose every pixel gets a match; same channel count as ``source``.
    patch_size : int, optional
        Side of the square patches, odd (default 7).
    iterations : int, optional
        PatchMatch iterations per pyramid level (default 5; Barnes et al. report that 4–5
        suffice). Ignored by exact search.
    method : {"patchmatch", "kdtree", "exact"}, optional
        Randomised PatchMatch (default); ``"kdtree"``, PatchMatch started from
        propagation-assisted kd-tree search (He & Sun 2012: every target patch first tries
        the few source patches nearest to it in a 16-dimensional PCA space of the source
        patches, then ``iterations`` PatchMatch passes propagate them; full resolution
        only), which gets within 1–3 % of exact after 5 iterations between unrelated
        texture crops where plain PatchMatch stays 15–31 % above, at 3–4 times its cost
        (0.9 s against 0.23 s for 512² against 512² on 2 threads); or brute-force exact
        search, ``O(Ms·Ns·Mt·Nt)``, refused above :data:`EXACT_LIMIT` pixel pairs.
    weights : (C,) array_like, optional
        Non-negative per-channel weights of the squared differences (default all 1).
    source_mask : (Ms, Ns) array_like of bool, optional
        Source pixels that may be patch centres (default: all whose patch fits).
    target_mask : (Mt, Nt) array_like of bool, optional
        Target pixels that need a match; the others get ``(-1, -1)`` and an infinite distance.
    init : (Mt, Nt, 2) array_like of int, optional
        Initial field; ``(-1, -1)`` entries start at random. Disables the pyramid.
    levels : int, optional
        Coarse-to-fine pyramid levels for PatchMatch (default 1: full resolution only).
    enrich : int or (Ms, Ns, k, 2) array_like of int, optional
        Forward enrichment of Generalized PatchMatch (Barnes et al. 2010): every iteration
        also tries the ``k`` source patches most similar to a pixel's current match. An int
        ``k`` computes that table with :func:`knn` (cost: about ``k + 2`` PatchMatch
        iterations over the source); an array passes a table from :func:`knn` for reuse.
        Plain PatchMatch (0, the default) converges fast where target and source share
        coherent structure; enrichment is what reaches near-exact fields between unrelated
        images. Used at full resolution only.
    tileable : bool, optional
        The target is a torus (a tileable texture): a target patch near an edge continues on
        the opposite side instead of being clipped, and matches propagate across the wrap
        (default False). Source patches still lie wholly inside the source.
    seed : int or numpy.random.Generator, optional
        Seed of every random choice (default 0). The same seed gives the same field for any
        number of threads.
    threads : int, optional
        Worker threads (default: ``PHLOEM_NUM_THREADS`` or all cores).
    max_memory : int, optional
        Refuse the job with :class:`phloem.MemoryLimitError` if its estimated peak memory is
        over this many bytes (default None: 75% of the machine's memory; see ``docs/hardening/memory.md``).

    Returns
    -------
    field : (Mt, Nt, 2) ndarray of int32
        Source (row, col) patch centre for every target pixel.
    distance : (Mt, Nt) ndarray of float32
        Weighted sum of squared differences of each match.

    References
    ----------
    .. [1] C. Barnes, E. Shechtman, A. Finkelstein, D. B. Goldman, "PatchMatch: a randomized
       correspondence algorithm for structural image editing", ACM TOG 28(3), 2009.
    .. [2] K. He, J. Sun, "Computing nearest-neighbor fields via propagation-assisted
       kd-trees", CVPR 2012.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> bark = phloem.data.bark()[:64, :64, :3]
    >>> field, dist = phloem.patch.nnf(bark, bark[10:40, 5:45], patch_size=5, seed=1)
    >>> field.shape, bool(dist[2:-2, 2:-2].max() == 0.0)
    ((30, 40, 2), True)
    """
    src = as_image(source, "source")
    tgt = as_image(target, "target")
    if src.shape[2] != tgt.shape[2]:
        raise ValueError(f"target: expected {src.shape[2]} channels like source, got {tgt.shape[2]}")
    _memory.check_size(
        _memory.nnf(src.shape, tgt.shape, kdtree=method == "kdtree"), max_memory, tgt.shape[:2], "target"
    )
    if method not in ("patchmatch", "kdtree", "exact"):
        raise ValueError(f"method: expected 'patchmatch', 'kdtree' or 'exact', got {method!r}")
    if method == "exact":
        work = src.shape[0] * src.shape[1] * tgt.shape[0] * tgt.shape[1]
        if work > EXACT_LIMIT:
            raise ValueError(
                f"method: exact search would compare {work:.3g} patch pairs (limit {EXACT_LIMIT:.3g}, minutes of "
                "uninterruptible work); use method='patchmatch' (with enrich=k for near-exact fields) or smaller images"
            )
    smask = None if source_mask is None else as_mask(source_mask, "source_mask", src.shape[:2])
    tmask = None if target_mask is None else as_mask(target_mask, "target_mask", tgt.shape[:2])
    table = None
    if isinstance(enrich, (int, np.integer)) and not isinstance(enrich, bool):
        if check_int(enrich, "enrich", 0) > 0:
            table, _ = knn(src, int(enrich), patch_size=patch_size, weights=weights, seed=seed, threads=threads)
    else:
        table = np.ascontiguousarray(np.asarray(enrich), dtype=np.int32)
        if table.ndim != 4 or table.shape[:2] != src.shape[:2] or table.shape[3] != 2:
            raise ValueError(f"enrich: expected an int or a ({src.shape[0]}, {src.shape[1]}, k, 2) table from knn()")
    ini = None
    if init is not None:
        ini = np.ascontiguousarray(np.asarray(init), dtype=np.int32)
        if ini.shape != (*tgt.shape[:2], 2):
            raise ValueError(f"init: expected shape {(*tgt.shape[:2], 2)}, got {ini.shape}")
    field, dist, _ = _core.nnf(
        src,
        tgt,
        patch_size=check_patch_size(patch_size),
        iterations=check_int(iterations, "iterations", 0),
        levels=check_int(levels, "levels", 1),
        exact=method == "exact",
        seed=check_seed(seed),
        weights=_weights(weights, src.shape[2]),
        source_mask=smask,
        target_mask=tmask,
        init=ini,
        source_knn=table,
        source_cost=None,
        threads=check_threads(threads),
        kdtree=method == "kdtree",
        tileable=bool(tileable),
    )
    return field, dist


def knn(
    exemplar: Any,
    k: int,
    *,
    patch_size: int = 7,
    exact: bool = False,
    exclude: int | None = None,
    iterations: int = 6,
    weights: Any = None,
    seed: Seed = 0,
    threads: int | None = None,
    max_memory: int | None = None,
) -> tuple[NDArray[np.int32], NDArray[np.float32]]:
    """The ``k`` most similar patches of every exemplar pixel, inside the exemplar.

    These are the precomputed lists of k-coherence search (Tong et al. 2002), which the
    texture-by-numbers solver of Laitoch (2018, §3.3.6) built with FLANN. The exemplar is
    mirrored at its border so every pixel has a patch.

    Parameters
    ----------
    exemplar : (M, N[, C]) array_like
        The exemplar image.
    k : int
        Neighbours per pixel (for k-coherence with ``k`` candidates per coherent pixel, as the
        thesis counts them, pass ``k - 1``: the pixel itself always joins the set).
    patch_size : int, optional
        Side of the square patches, odd (default 7).
    exact : bool, optional
        Brute force (``O((MN)²)``, for small exemplars and tests) instead of the approximate
        k-PatchMatch search (default).
    exclude : int, optional
        Pixels within this Chebyshev distance are not neighbours (default ``patch_size // 2``),
        so lists name other places rather than the same place shifted by a pixel.
    iterations : int, optional
        Passes of the approximate search (default 6).
    weights : (C,) array_like, optional
        Per-channel weights of the squared differences.
    seed : int or numpy.random.Generator, optional
        Seed (default 0); results do not depend on the thread count.
    threads : int, optional
        Worker threads.
    max_memory : int, optional
        Refuse the job with :class:`phloem.MemoryLimitError` if its estimated peak memory is
        over this many bytes (default None: 75% of the machine's memory; see ``docs/hardening/memory.md``).

    Returns
    -------
    neighbours : (M, N, k, 2) ndarray of int32
        (row, col) of each pixel's neighbours, nearest first.
    distance : (M, N, k) ndarray of float32
        Their patch distances.

    Examples
    --------
    >>> import phloem
    >>> idx, d = phloem.patch.knn(phloem.data.bark()[:32, :32, :3], 2, patch_size=5)
    >>> idx.shape, bool((d[..., 0] <= d[..., 1]).all())
    ((32, 32, 2, 2), True)
    """
    img = as_image(exemplar, "exemplar")
    p = check_patch_size(patch_size)
    kk = check_int(k, "k", 1)
    _memory.check(
        _memory.nnf(img.shape, img.shape, kk),
        max_memory,
        "k",
        f"{kk} neighbours of {img.shape[0]}×{img.shape[1]} pixels",
    )
    return _core.knn(
        img,
        k=kk,
        patch_size=p,
        iterations=check_int(iterations, "iterations", 0),
        exact=bool(exact),
        exclude=p // 2 if exclude is None else check_int(exclude, "exclude", 0),
        seed=check_seed(seed),
        weights=_weights(weights, img.shape[2]),
        threads=check_threads(threads),
    )


def candidates(
    refs: Any,
    exemplar_shape: tuple[int, int],
    *,
    patch_size: int = 7,
    neighbours: Any = None,
    wrap: bool = False,
    threads: int | None = None,
) -> NDArray[np.int32]:
    """k-coherence candidate sets for an image of references into an exemplar.

    For each output pixel ``p0`` and each pixel ``p`` of its window, the exemplar pixel that
    ``p`` was copied from, forward-shifted by ``p0 - p``, is a candidate; with
    ``neighbours`` (from :func:`knn`) each candidate's neighbours join too (Laitoch 2018,
    §3.3.6).

    Parameters
    ----------
    refs : (M, N, 2) array_like of int
        Exemplar (row, col) each output pixel was copied from; ``(-1, -1)`` for none.
    exemplar_shape : (int, int)
        Exemplar height and width.
    patch_size : int, optional
        Window side, odd (default 7).
    neighbours : (Me, Ne, k, 2) array_like of int, optional
        The first output of :func:`knn` for the exemplar.
    wrap : bool, optional
        Forward shifts that leave the exemplar wrap around (default: they are dropped).

    Returns
    -------
    candidates : (M, N, S, 2) ndarray of int32
        Each set deduplicated in discovery order and padded with ``(-1, -1)``;
        ``S = patch_size² × (1 + k)``.
    """
    r = np.ascontiguousarray(np.asarray(refs), dtype=np.int32)
    if r.ndim != 3 or r.shape[2] != 2:
        raise ValueError(f"refs: expected shape (M, N, 2), got {r.shape}")
    eh, ew = (check_int(v, "exemplar_shape", 1) for v in exemplar_shape)
    nb = None
    if neighbours is not None:
        nb = np.ascontiguousarray(np.asarray(neighbours), dtype=np.int32)
        if nb.ndim != 4 or nb.shape[:2] != (eh, ew) or nb.shape[3] != 2:
            raise ValueError(f"neighbours: expected shape ({eh}, {ew}, k, 2), got {nb.shape}")
    return _core.coherence_candidates(
        r,
        (eh, ew),
        patch_size=check_patch_size(patch_size),
        wrap=bool(wrap),
        knn_idx=nb,
        threads=check_threads(threads),
    )


def vote(
    source: Any,
    field: Any,
    *,
    patch_size: int = 7,
    weights: Any = None,
    mean_shift: int = 0,
    tileable: bool = False,
    threads: int | None = None,
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Weighted average of the source patches a field places over each target pixel.

    The colour update of texture optimisation (Kwatra et al. 2005) and of image completion
    (Wexler et al. 2007).

    Parameters
    ----------
    source : (Ms, Ns[, C]) array_like
        Image the patches come from.
    field : (M, N, 2) array_like of int
        Source patch centre per target pixel, as returned by :func:`nnf`; ``(-1, -1)`` for none.
    patch_size : int, optional
        Patch side used to build the field (default 7).
    weights : (M, N) array_like, optional
        Non-negative weight of the patch centred at each target pixel (default 1).
    mean_shift : int, optional
        Steps of weighted mean-shift from the mean towards the dominant mode of each pixel's
        votes (Wexler et al. 2007, §3.2), so that disagreeing votes pick a side instead of
        blurring; the Gaussian kernel's bandwidth is the votes' own spread around the
        current estimate. 0 (default): the weighted mean.
    tileable : bool, optional
        The image is a torus: a patch centred near an edge also votes on the opposite side
        (default False), as :func:`nnf` matches with ``tileable=True``.

    Returns
    -------
    image : (M, N, C) ndarray of float32
        Voted values; 0 where no patch reaches.
    weight : (M, N) ndarray of float32
        Total weight that reached each pixel.
    """
    src = as_image(source, "source")
    f = np.ascontiguousarray(np.asarray(field), dtype=np.int32)
    if f.ndim != 3 or f.shape[2] != 2:
        raise ValueError(f"field: expected shape (M, N, 2), got {f.shape}")
    if 0 in f.shape:
        raise ValueError(f"field: expected a non-empty field, got shape {f.shape}")
    w = None
    if weights is not None:
        w = np.ascontiguousarray(np.asarray(weights, dtype=np.float32))
        if w.shape != f.shape[:2]:
            raise ValueError(f"weights: expected shape {f.shape[:2]} like the field, got {w.shape}")
    return _core.vote(
        src, f, patch_size=check_patch_size(patch_size), weights=w, threads=check_threads(threads),
        mean_shift=check_int(mean_shift, "mean_shift", 0), pixels=None, tileable=bool(tileable),
    )  # fmt: skip
