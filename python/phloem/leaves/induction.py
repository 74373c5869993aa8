"""Layer induction (Assa & Cohen-Or, §4, Eqs. 2–6): the user's layer on the training leaf, carried
to every aligned exemplar by colour and position together.

For a layer ``c`` (pixels of the training leaf ``t``) and an exemplar ``e`` aligned to ``t``:

- ``S^e(x)`` — Eq. 1, :func:`~phloem.leaves.color_distance`: normalised EMD between the colours
  of ``x``'s 8 × 8 neighbourhood on ``e`` and the colours of ``c``; ``S^t`` the same on ``t``.
- ``F(x) = exp(−d(x)² / (ε² (1 − S^t(x))))`` — Eq. 3, ``d`` the Euclidean distance from ``x`` to
  ``c``: 1 on the layer, falling off with ε, narrower where the training leaf separates the
  layer's colours well (``S^t`` near 1), wider where it does not.
- ``D(x) = λ (1 − F(x)) + S^e(x)`` — Eq. 2 read as a dissimilarity (printed ``λF + S`` would
  penalise the pixels near the layer that F exists to favour).
- ``λ = κ |∩ L̃| / |∪ L̃|`` over the training leaf and the exemplars — Eqs. 5–6, with
  ``L̃ = {x : S(x) < τ and d(x) < 2ε}``, ``τ`` the printed 0.1 or, if larger, the threshold at
  which colour alone best reproduces the layer on the training leaf (a layer thinner than the
  window never gets ``S < 0.1``).
- ``δ`` maximises the Eq. 4 objective, read as the IoU of ``{D^t < δ}`` with ``c`` on the
  training leaf; the induced layer on ``e`` is ``{D^e < δ}``.

``docs/pipelines/leaves/induction.md`` gives the reasons for each reading.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage  # type: ignore[import-untyped]

from .._api import Seed
from .._validate import as_image, as_mask, check_float, check_seed, check_threads
from ._stages import Stages, Task
from .color import color_distance

__all__ = ["Induction", "induce", "liberal_layer"]

F32 = NDArray[np.float32]

#: The colour threshold of Eq. 6's liberal layer (the paper's 0.1), the least one used.
LIBERAL_COLOR = 0.1


@dataclass(frozen=True)
class Induction:
    """One layer induced on a list of aligned exemplars (:func:`induce`).

    Index ``i`` runs over the exemplars in the order given. Maps are ``(H, W)`` on the shared
    canvas; float maps are NaN off the exemplar's leaf (alpha ≤ 0.5), masks False there.

    Attributes
    ----------
    masks : list of (H, W) ndarray of bool
        The induced layer ``{x : D(x) < delta}`` on each exemplar.
    dissimilarity : list of (H, W) ndarray of float32
        ``D = lam * (1 - F) + S`` (Eq. 2 as a dissimilarity): 0 for a pixel on the user's
        layer with the layer's colours, up to ``1 + lam``.
    color : list of (H, W) ndarray of float32
        ``S`` (Eq. 1) of each exemplar against the user's layer, in [0, 1].
    spatial : list of (H, W) ndarray of float32
        ``F`` (Eq. 3), in [0, 1]: 1 on the user's layer. It depends on the training leaf only,
        so it is the same map on every exemplar, cut to that exemplar's leaf.
    lam : float
        ``λ`` of Eq. 5, in ``[0, kappa]``: large for a structural layer (its liberal layers
        overlap across the leaves), small for one that is not (spots); 0 when no leaf has a
        liberal pixel.
    delta : float
        The threshold ``δ``; a float32 value, so ``D < delta`` reads the same in float32 and
        float64.
    objective : float
        The Eq. 4 objective that ``delta`` reaches on the training leaf (IoU of
        ``{D^t < delta}`` with the user's layer, :func:`phloem.metrics.layer_objective`).
    """

    masks: list[NDArray[np.bool_]]
    dissimilarity: list[F32]
    color: list[F32]
    spatial: list[F32]
    lam: float
    delta: float
    objective: float


def _leaf_image(image: Any, name: str, shape: tuple[int, int] | None = None) -> F32:
    img = as_image(image, name)
    if img.shape[2] != 4:
        raise ValueError(f"{name}: expected an RGBA leaf of shape (H, W, 4), got {np.shape(image)}")
    if shape is not None and img.shape[:2] != shape:
        raise ValueError(f"{name}: expected shape {(*shape, 4)} like training (one canvas), got {img.shape}")
    if not (img[..., 3] > 0.5).any():
        raise ValueError(f"{name}: the leaf has no pixels (alpha > 0.5)")
    return img


def _distance(layer: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Exact Euclidean distance from each pixel to the nearest pixel of ``layer`` (0 on it)."""
    return np.asarray(ndimage.distance_transform_edt(~layer), dtype=np.float64)


def spatial_term(
    distance: NDArray[np.float64], training_color: NDArray[np.float32], training_leaf: NDArray[np.bool_], epsilon: float
) -> NDArray[np.float64]:
    """``F`` of Eq. 3 on the whole canvas, from the distance to the layer and ``S^t``.

    Off the training leaf ``S^t`` is undefined; there it takes the value of the nearest
    training-leaf pixel, so an exemplar that reaches past the training outline (registration
    error) is judged by the training leaf's nearest separability.
    """
    st = np.asarray(training_color, dtype=np.float64)
    if not training_leaf.all():
        idx = ndimage.distance_transform_edt(~training_leaf, return_distances=False, return_indices=True)
        st = st[idx[0], idx[1]]
    width = epsilon**2 * np.clip(1.0 - st, 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.exp(-(distance**2) / width)  # width 0 (S^t = 1): F = 0 off the layer
    f[distance == 0] = 1.0  # on the layer, whatever the width
    return np.asarray(f)


def liberal_layer(
    color: NDArray[np.float32], distance: NDArray[np.float64], epsilon: float, tau: float = LIBERAL_COLOR
) -> NDArray[np.bool_]:
    """Eq. 6's liberal layer ``{x : S(x) < tau and d(x) < 2ε}`` (NaN ``S`` is never in it)."""
    with np.errstate(invalid="ignore"):
        return np.asarray((color < tau) & (distance < 2.0 * epsilon))


def best_threshold(
    dissimilarity: NDArray[np.float32], layer: NDArray[np.bool_], leaf: NDArray[np.bool_]
) -> tuple[float, float]:
    """``(δ, objective)``: the threshold whose ``{D < δ}`` on ``leaf`` has the largest IoU with
    ``layer`` (Eq. 4 as implemented), and that IoU.

    The objective only changes where ``δ`` passes a value of ``D``, so every cut between two
    consecutive distinct sorted values is tried (and the cut above all of them); of equal
    objectives the smallest ``δ`` wins. ``δ`` is put halfway between the last value kept and
    the first left out (in float32, so exemplars whose ``D`` falls between them are split
    evenly rather than by rounding).
    """
    vals = dissimilarity[leaf].astype(np.float32)
    in_c = layer[leaf]
    order = np.argsort(vals, kind="stable")
    v = vals[order]
    tp = np.cumsum(in_c[order], dtype=np.int64)
    n = len(v)
    k = np.arange(1, n + 1)
    # A cut after position k-1 is possible only where the next value is larger (ties stay together).
    cut = np.ones(n, bool)
    cut[:-1] = v[1:] > v[:-1]
    iou = np.where(cut, tp / (int(in_c.sum()) + k - tp), -1.0)
    j = int(np.argmax(iou))
    last = v[j]
    if j + 1 < n:
        mid = np.float32((np.float64(last) + np.float64(v[j + 1])) / 2.0)
    else:
        mid = np.float32(np.float64(last) + max(1e-3, abs(float(last)) * 1e-3))
    if not mid > last:  # adjacent float32 values: the next one up still separates them
        mid = np.nextafter(last, np.float32(np.inf))
    return float(mid), float(iou[j])


def induce(
    training: Any,
    layer: Any,
    exemplars: Sequence[Any],
    *,
    epsilon: float = 40.0,
    kappa: float = 1.5,
    window: int = 8,
    n_bins: int = 16,
    seed: Seed = 0,
    threads: int | None = None,
) -> Induction:
    """Induce the user's layer of the training leaf on aligned exemplars (§4, Eqs. 2–6).

    Parameters
    ----------
    training : (H, W, 4) array_like
        The training leaf, RGBA (the leaf is alpha > 0.5), on the shared canvas.
    layer : (H, W) array_like of bool
        The user's (expanded) layer ``c`` on it; every pixel must lie on the training leaf.
    exemplars : list of (H, W, 4) array_like
        Exemplars aligned to the training leaf on the same canvas (RGBA). The training leaf
        may be one of them; it changes neither ``lam`` nor the other exemplars' results.
    epsilon : float
        The spatial falloff ε in px (the paper: 40, about the largest registration error).
    kappa : float
        κ of Eq. 5 (the paper: 1.5), ``>= 0``; 0 turns the spatial term off (colour alone).
    window : int
        Side of the neighbourhood of ``S`` (the paper: 8).
    n_bins : int
        Palette size of ``S``, 2 to 32 (:func:`~phloem.leaves.color_distance`).
    seed : int or numpy.random.Generator
        Seeds the colour palettes.
    threads : int, optional
        Worker threads (default: phloem's pool size); the result is the same for any number.

    Returns
    -------
    Induction
        Per exemplar the induced mask and the maps ``D``, ``S``, ``F``; and ``lam``,
        ``delta``, ``objective``.

    Examples
    --------
    >>> import numpy as np
    >>> from phloem.leaves import induce
    >>> leaf = np.zeros((32, 32, 4), np.float32); leaf[4:28, 4:28] = (0.2, 0.6, 0.1, 1.0)
    >>> leaf[14:18, 4:28, :3] = (0.8, 0.8, 0.3)  # a midrib
    >>> vein = np.zeros((32, 32), bool); vein[14:18, 4:28] = True
    >>> result = induce(leaf, vein, [leaf], epsilon=8.0, window=4)
    >>> round(result.objective, 2), bool(result.masks[0][15, 10]), bool(result.masks[0][6, 10])
    (1.0, True, False)
    """
    t = _leaf_image(training, "training")
    shape = (t.shape[0], t.shape[1])
    c = as_mask(layer, "layer", shape)
    if not c.any():
        raise ValueError("layer: the layer has no pixels")
    leaf_t = t[..., 3] > 0.5
    off = int((c & ~leaf_t).sum())
    if off:
        raise ValueError(f"layer: {off} pixel(s) lie off the training leaf (alpha <= 0.5)")
    if isinstance(exemplars, np.ndarray) or not isinstance(exemplars, Sequence) or isinstance(exemplars, str):
        raise TypeError(f"exemplars: expected a list of RGBA leaves, got {type(exemplars).__name__}")
    if len(exemplars) == 0:
        raise ValueError("exemplars: expected at least one exemplar")
    ex = [_leaf_image(e, f"exemplars[{i}]", shape) for i, e in enumerate(exemplars)]
    epsilon = check_float(epsilon, "epsilon", 0.0, inclusive=False)
    kappa = check_float(kappa, "kappa", 0.0)
    seed = check_seed(seed)
    threads = check_threads(threads)

    # The training leaf itself with `reference=` gives the same palette and map: it is computed
    # once. The maps are independent and partly serial (palette, quantisation): side by side.
    own = [i for i, e in enumerate(ex) if not np.array_equal(e, t)]

    def map_of(image: F32) -> Task[F32]:
        def task(threads: int | None, check: Callable[[], None]) -> F32:
            return color_distance(image, c, reference=t, window=window, n_bins=n_bins, seed=seed, threads=threads)

        return task

    s_t, *maps = Stages(threads).run([map_of(t), *(map_of(ex[i]) for i in own)], lambda _: None)
    s_e = [s_t] * len(ex)
    for i, m in zip(own, maps, strict=True):
        s_e[i] = m
    d = _distance(c)
    f = spatial_term(d, s_t, leaf_t, epsilon)

    # λ (Eqs. 5–6): the training leaf is always one of the leaves compared (∩ and ∪ are
    # idempotent, so passing it among the exemplars too changes nothing). The colour bound is
    # never stricter than what colour alone needs to find the layer on the training leaf: no
    # window of a vein thinner than the window is all vein, so S < 0.1 would leave thin
    # layers no liberal pixels and λ = 0, the opposite of what Eq. 5 is for.
    tau = max(LIBERAL_COLOR, best_threshold(s_t, c, leaf_t)[0])
    liberal = [liberal_layer(s, d, epsilon, tau) for s in [s_t, *s_e]]
    inter = np.logical_and.reduce(liberal)
    union = np.logical_or.reduce(liberal)
    n_union = int(union.sum())
    lam = kappa * int(inter.sum()) / n_union if n_union else 0.0

    penalty = (lam * (1.0 - f)).astype(np.float32)
    d_t = (penalty + s_t).astype(np.float32)
    delta, objective = best_threshold(d_t, c, leaf_t)

    masks, dis, spatial = [], [], []
    f32 = f.astype(np.float32)
    for e, s in zip(ex, s_e, strict=True):
        leaf = e[..., 3] > 0.5
        de = np.where(leaf, penalty + s, np.float32(np.nan)).astype(np.float32)
        with np.errstate(invalid="ignore"):
            masks.append(np.ascontiguousarray(leaf & (de < np.float32(delta))))
        dis.append(de)
        spatial.append(np.where(leaf, f32, np.float32(np.nan)).astype(np.float32))
    return Induction(
        masks=masks,
        dissimilarity=dis,
        color=[np.asarray(s, dtype=np.float32) for s in s_e],
        spatial=spatial,
        lam=float(lam),
        delta=delta,
        objective=objective,
    )
