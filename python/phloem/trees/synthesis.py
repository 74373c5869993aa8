"""Random tree variations from a library, from scratch or of a user's tree (Argudo et al. 2017 §3, §5)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _memory
from .._api import Seed, renamed
from .._progress import Progress
from .._validate import check_float, check_int, check_seed
from ._checks import F32, F64
from .library import Library
from .preprocessing import Tree, prepare
from .transfer import match_histograms, morph

__all__ = ["Variation", "variation", "vary"]


@dataclass
class Variation:
    """One synthesised tree and how it was made.

    Attributes
    ----------
    image : (S, S, 4) float32 ndarray
        The new RGBA tree.
    sources : list of int
        Library indices of the exemplars combined.
    weights : (k,) float64 ndarray
        Their contour weights.
    color_weights : (k,) float64 ndarray
        Their colour weights.
    reference : int or None
        Library index of the histogram reference, if any.
    """

    image: F32
    sources: list[int]
    weights: F64
    color_weights: F64
    reference: int | None = None

    def describe(self, library: Library) -> dict[str, Any]:
        """A JSON-ready record (names and weights) for a result sidecar."""
        return {
            "exemplars": [library.names[i] for i in self.sources],
            "weights": [round(float(v), 6) for v in self.weights],
            "color_weights": [round(float(v), 6) for v in self.color_weights],
            "histogram_reference": None if self.reference is None else library.names[self.reference],
        }


_COLORS = ("random", "contour", "single")


def _draw_weights(rng: np.random.Generator, k: int, spread: float) -> F64:
    # (1 - spread)/k + spread * Dirichlet(1): for two sources w_1 is uniform on
    # [(1 - spread)/2, (1 + spread)/2], i.e. [0.3, 0.7] for the default spread as in Fig. 16.
    return np.asarray((1.0 - spread) / k + spread * rng.dirichlet(np.ones(k)), dtype=np.float64)


def _color_weights(rng: np.random.Generator, w: F64, colors: str, spread: float) -> F64:
    if colors == "contour":
        return w
    if colors == "single":
        out = np.zeros_like(w)
        out[int(rng.choice(len(w), p=w))] = 1.0
        return out
    return _draw_weights(rng, len(w), spread)


def _check_variation_args(library: Any, n_sources: Any, spread: Any, colors: Any) -> tuple[int, float]:
    if not isinstance(library, Library):
        raise TypeError(f"library: expected a phloem.trees.Library, got {type(library).__name__}")
    k = check_int(n_sources, "n_sources", 1)
    spread = check_float(spread, "spread", 0.0)
    if spread > 1.0:
        raise ValueError(f"spread: expected a value in [0, 1], got {spread}")
    if colors not in _COLORS:
        raise ValueError(f"colors: expected one of {_COLORS}, got {colors!r}")
    return k, spread


@renamed(sources="n_sources")
def variation(
    library: Library,
    *,
    n_sources: int = 2,
    seed: Seed = 0,
    spread: float = 0.4,
    colors: str = "random",
    histogram: bool = False,
    threads: int | None = None,
    max_memory: int | None = None,
) -> Variation:
    """A new tree from ``n_sources`` exemplars drawn at random from the library (paper §3, §5).

    The contour is a random convex combination of the exemplars' contours (§5.1) and is filled
    by RGBA colour transfer from all of them (§5.2); see :func:`morph`.

    Parameters
    ----------
    library : Library
    n_sources : int, optional
        How many distinct exemplars to combine (2 in the paper's Fig. 16; ``sources``
        before, deprecated).
    seed : int or numpy.random.Generator, optional
        Seed of the random choices; the same seed gives the same tree.
    spread : float, optional
        Contour weights are ``(1 - spread)/k + spread * Dirichlet(1, ..., 1)``; with two sources
        and the default 0.4, ``w_1`` is uniform on [0.3, 0.7] as in the paper's Fig. 16.
    colors : {"random", "contour", "single"}, optional
        Colour weights: a second random convex combination (§5.2, the default), the contour's
        weights, or one source picked with probability equal to its weight (both in Fig. 16).
    histogram : bool, optional
        Match the colour histogram to another random exemplar of the library (§5.3).
    threads : int, optional
        Worker threads for the warp.
    max_memory : int, optional
        Refuse the job with :class:`phloem.MemoryLimitError` if its estimated peak memory is
        over this many bytes (default None: 75% of the machine's memory; see ``docs/hardening/memory.md``).

    Returns
    -------
    Variation

    Raises
    ------
    ValueError
        If the library holds fewer than ``n_sources`` trees.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> img = np.zeros((120, 80, 4), np.float32); img[..., 1] = 0.5
    >>> img[..., 3] = 0; img[10:70, 10:70, 3] = 1.0; img[70:110, 35:45, 3] = 1.0
    >>> lib = phloem.trees.Library.from_images([img, img[:, ::-1], img[20:]], size=128)
    >>> v = phloem.trees.variation(lib, seed=3)
    >>> v.image.shape, len(v.sources), bool(abs(v.weights.sum() - 1) < 1e-9)
    ((128, 128, 4), 2, True)
    """
    k, spread = _check_variation_args(library, n_sources, spread, colors)
    if len(library) < k:
        raise ValueError(
            f"library: has {len(library)} tree(s) but n_sources={k}; a variation combines {k} distinct exemplars"
        )
    _memory.check(_memory.trees(library.size, 0), max_memory, "library", f"a tree of {library.size}×{library.size}")
    rng = np.random.default_rng(check_seed(seed))
    idx = [int(i) for i in rng.choice(len(library), size=k, replace=False)]
    w = _draw_weights(rng, k, spread)
    cw = _color_weights(rng, w, colors, spread)
    return _make(library, idx, w, cw, rng, histogram, threads)


def _make(
    library: Library,
    idx: list[int],
    w: F64,
    cw: F64,
    rng: np.random.Generator,
    histogram: bool,
    threads: int | None,
    extra: Tree | None = None,
) -> Variation:
    ts = ([extra] if extra is not None else []) + [library.trees[i] for i in idx]
    img = morph(ts, w, color_weights=cw, m=len(ts[0].simplified), threads=threads)
    ref = None
    if histogram:
        choices = [i for i in range(len(library)) if i not in idx] or list(range(len(library)))
        ref = int(rng.choice(choices))
        if img[..., 3].any():
            img = match_histograms(img, library.trees[ref].image)
    return Variation(img, idx, w, cw, ref)


@renamed(n="n_variations", sources="n_sources")
def vary(
    tree: Any,
    library: Library,
    *,
    n_variations: int,
    seed: Seed = 0,
    n_sources: int = 2,
    weight: tuple[float, float] = (0.6, 0.9),
    spread: float = 0.4,
    colors: str = "contour",
    histogram: bool = False,
    threads: int | None = None,
    progress: Progress = None,
    max_memory: int | None = None,
) -> list[Variation]:
    """``n_variations`` variations of one tree ``T``, combined with library exemplars at a lower weight (§3).

    ``T`` is preprocessed like the exemplars (an RGBA image, or a :class:`Tree` made at the
    library's size), then each variation combines ``T`` with ``n_sources - 1`` random library
    exemplars. ``T``'s contour weight is drawn uniformly from ``weight``; the rest is shared
    among the others as in :func:`variation`. By default the colour weights equal the contour
    weights, so the variations keep ``T``'s look.

    Parameters
    ----------
    tree : (M, N, 4) ndarray or Tree
        The user's tree ``T``.
    library : Library
    n_variations : int
        Number of variations (``n`` before, deprecated).
    seed : int or numpy.random.Generator, optional
    n_sources : int, optional
        Trees per variation, ``T`` included (at least 2; ``sources`` before, deprecated).
    weight : (float, float), optional
        Range of ``T``'s contour weight.
    spread, colors, histogram, threads : optional
        As in :func:`variation`.
    progress : callable, optional
        ``progress(done, n_variations)`` after each finished variation (about 0.2 s each at
        1024²); an exception it raises stops the run. :func:`variation` makes one tree and
        takes none.
    max_memory : int, optional
        Refuse the job with :class:`phloem.MemoryLimitError` if its estimated peak memory is
        over this many bytes (default None: 75% of the machine's memory; see ``docs/hardening/memory.md``).

    Returns
    -------
    list of Variation
        ``sources`` lists the library exemplars only; ``weights[0]`` is ``T``'s.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> img = np.zeros((120, 80, 4), np.float32); img[..., 1] = 0.5
    >>> img[..., 3] = 0; img[10:70, 10:70, 3] = 1.0; img[70:110, 35:45, 3] = 1.0
    >>> lib = phloem.trees.Library.from_images([img[:, ::-1], img[20:]], size=128)
    >>> vs = phloem.trees.vary(img, lib, n_variations=2, seed=1)
    >>> len(vs), [bool(0.6 <= v.weights[0] <= 0.9) for v in vs]
    (2, [True, True])
    """
    k, spread = _check_variation_args(library, n_sources, spread, colors)
    n = check_int(n_variations, "n_variations", 1)
    if k < 2:
        raise ValueError(f"n_sources: a variation of a tree combines it with at least one exemplar, got {k}")
    if len(library) < k - 1:
        raise ValueError(f"library: has {len(library)} tree(s) but n_sources={k} needs {k - 1} besides the tree")
    lo, hi = (check_float(v, "weight", 0.0) for v in weight)
    if not lo <= hi <= 1.0:
        raise ValueError(f"weight: expected 0 <= low <= high <= 1, got {weight!r}")
    _memory.check(_memory.trees(library.size, 1), max_memory, "library", f"a tree of {library.size}×{library.size}")
    t = tree if isinstance(tree, Tree) else prepare(tree, size=library.size)
    first = library.trees[0]
    if t.image.shape != first.image.shape or t.split != first.split:
        raise ValueError("tree: prepared with another size or split than the library's trees")
    rng = np.random.default_rng(check_seed(seed))
    out = []
    for _ in range(n):
        idx = [int(i) for i in rng.choice(len(library), size=k - 1, replace=False)]
        wt = float(rng.uniform(lo, hi))
        w = np.concatenate([[wt], (1.0 - wt) * _draw_weights(rng, k - 1, spread)])
        cw = _color_weights(rng, w, colors, spread)
        out.append(_make(library, idx, w, cw, rng, histogram, threads, extra=t))
        if progress is not None:
            progress(len(out), n)
    return out
