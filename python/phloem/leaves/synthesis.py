"""New leaves from a :class:`LeafModel` (Assa & Cohen-Or, §5).

Each new leaf is composed on the shared canvas in the training frame and then put into a new
shape:

1. the inpainted background of a random exemplar, under a small smooth random warp whose peak
   displacement is that exemplar's registration error (the paper: "should not exceed the
   initial registration error");
2. every other layer taken from a random exemplar other than the background's (mixing is the
   point), under its own random warp, ``1 − λ/κ`` times as large, so structural layers (veins,
   ``λ`` near ``κ``) stay put and stochastic ones (spots, ``λ`` near 0) move; the layers are
   fused with weights from their dissimilarity ``D`` normalised per pixel, the background
   taking what the layers leave;
3. the composition warped back by Eq. 7, ``W⁻¹ = Σ a_i W_i⁻¹``, the coefficients ``a_i(x)``
   a few random values on a coarse grid, Gaussian-blurred and normalised per pixel;
4. texture correction where that warp stretches or squeezes (``leaves.correct_texture``,
   when this build has it); where the analysis normalised the exemplars' sizes (a model's
   ``scale``), the leaf is scaled to the blend of their sizes Eq. 7 gave its shape; the
   largest leaf component is kept and the leaf cropped.

``docs/pipelines/leaves/synthesis.md`` gives the readings of the paper this module makes.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage  # type: ignore[import-untyped]

from .._api import Seed, Size
from .._boxes import bounding_box
from .._progress import Progress
from .._validate import check_float, check_int, check_seed, check_size, check_threads, derive_seed
from ._fields import as_field, sample_checked
from ._rgba import premultiplied, straight
from .correction import correct_texture
from .model import LeafModel

__all__ = ["blend_fields", "random_warp", "synthesize"]

F32 = NDArray[np.float32]

#: The largest Frobenius norm of a random warp's Jacobian ``J``: ``I + J`` then has singular
#: values in [0.5, 1.5], so the map ``x ↦ x + field(x)`` cannot fold.
MAX_GRADIENT = 0.5
#: Random layer warps vary over this fraction of the canvas's smaller side ("sufficiently
#: smooth"): a leaf bends as a whole, it does not ripple.
WARP_SMOOTHNESS = 0.2
#: Eq. 7's coefficient grid: this fraction of the smaller side between random coefficients
#: (Fig. 8 shows a handful of blobs over the leaf).
BLEND_SMOOTHNESS = 0.3
#: Up to this many exemplar mixes, a set of new leaves uses every mix before repeating one.
MAX_DEALT = 20_000
# The mixes' random stream: a seed sequence of its own, apart from every leaf's warps.
_MIX_STREAM = 1
#: Transparent margin in px around each cropped leaf.
MARGIN = 8
# D where it is undefined (NaN off a leaf): far beyond any threshold, weight ~1e-16.
_FAR = 1e4
# A layer's weight is 1 / (1 + (D/δ)⁴): D/δ = 1 (the layer's threshold) gets half weight; the
# fourth power keeps the layer's core at full weight (D/δ = 0.5 → 0.94) and fades it within
# the mask's rim.


def _basis(n: int, positions: NDArray[np.float64], spacing: float, sigma: float) -> NDArray[np.float64]:
    """``(len(positions), m)`` rows of normalised Gaussian weights (σ = ``sigma``) of ``m`` nodes
    ``spacing`` apart covering ``[-spacing, n - 1 + spacing]``: a separable Gaussian blur of
    values on a coarse grid, evaluated at ``positions``."""
    m = math.ceil((n - 1) / spacing) + 3
    nodes = (np.arange(m) - 1.0) * spacing
    g = np.exp(-0.5 * ((positions[:, None] - nodes[None, :]) / sigma) ** 2)
    return np.asarray(g / g.sum(axis=1, keepdims=True), dtype=np.float64)


class _Smooth:
    """Gaussian-blurred random node values, evaluated exactly on a grid of samples ``step`` px
    apart and interpolated bilinearly to every pixel (``cv2.resize``): bilinear interpolation
    is a convex combination of samples, so bounds on the samples (the largest value, the
    slopes between neighbours) are bounds on the full map, and a 2 Mpx map costs a few ms.
    The sample of index ``j`` sits where ``cv2.resize`` reads it, at ``(j + 0.5)·s − 0.5``."""

    def __init__(self, size: tuple[int, int], spacing: float, sigma: float, nodes: NDArray[np.float64]) -> None:
        self.size = size
        # a blur of σ ≥ 16 px is linear to within 1e-3 of its range over 1/16 of σ
        step = int(min(max(sigma // 16, 1), 8))
        self.counts = tuple(max(math.ceil(n / step), 1) for n in size)
        self.steps = tuple(n / c for n, c in zip(size, self.counts, strict=True))
        r, c = (
            _basis(n, np.arange(k, dtype=np.float64) * st + (0.5 * st - 0.5), spacing, sigma)
            for n, k, st in zip(size, self.counts, self.steps, strict=True)
        )
        planes = [r @ nodes[:, :, k] @ c.T for k in range(nodes.shape[2])]
        self.samples = np.ascontiguousarray(np.stack(planes, axis=2), dtype=np.float32)

    def full(self, values: NDArray[np.float32] | None = None) -> F32:
        """``values`` (default: the samples), ``(h_s, w_s, C)``, at every pixel."""
        v = self.samples if values is None else values
        h, w = self.size
        planes = [cv2.resize(v[:, :, c], (w, h), interpolation=cv2.INTER_LINEAR) for c in range(v.shape[2])]
        return np.ascontiguousarray(np.stack(planes, axis=2), dtype=np.float32)


def _rng(seed: Seed) -> np.random.Generator:
    return np.random.default_rng(check_seed(seed))


def random_warp(size: Size, magnitude: float, *, smoothness: float, seed: Seed = 0) -> F32:
    """A smooth random displacement field that moves no pixel by more than ``magnitude`` and
    cannot fold.

    Gaussian noise on a grid of nodes ``smoothness`` px apart, blurred by a Gaussian of that
    σ, scaled so the longest displacement is ``magnitude`` (on the field's exact samples; the
    interpolated pixels never exceed it), or less where that would let the displacement's
    Jacobian ``J`` reach ``‖J‖_F = 0.5``: the map ``x ↦ x + field(x)`` then has singular values
    in [0.5, 1.5], so it cannot fold and never squeezes to under half or stretches past 1.5.

    Parameters
    ----------
    size : int or (int, int)
        ``(H, W)`` of the field.
    magnitude : float
        The largest displacement in px (>= 0; 0 gives the identity).
    smoothness : float
        Node spacing and blur σ in px (>= 1: a node per pixel at most): larger is smoother.
    seed : int or numpy.random.Generator, default 0

    Returns
    -------
    (H, W, 2) ndarray of float32
        ``(dx, dy)`` per pixel, the convention of :func:`phloem.leaves.register`'s fields.
    """
    h, w = check_size(size)
    mag = check_float(magnitude, "magnitude", 0.0)
    s = check_float(smoothness, "smoothness", 1.0)
    rng = _rng(seed)
    m = math.ceil((h - 1) / s) + 3, math.ceil((w - 1) / s) + 3
    smooth = _Smooth((h, w), s, s, rng.standard_normal(m + (2,)))
    f = smooth.samples.astype(np.float64)
    peak = float(np.sqrt((f**2).sum(axis=2)).max())
    if mag == 0.0 or peak == 0.0:
        return np.zeros((h, w, 2), np.float32)
    # Inside a bilinear cell ∂f/∂col is a convex combination of the horizontal slopes of its
    # edges, ∂f/∂row of the vertical ones, so these bound the Jacobian of the full field.
    sy, sx = smooth.steps
    gx = np.sqrt((np.diff(f, axis=1) ** 2).sum(axis=2)).max(initial=0.0) / sx
    gy = np.sqrt((np.diff(f, axis=0) ** 2).sum(axis=2)).max(initial=0.0) / sy
    grad = math.hypot(gx, gy)
    scale = mag / peak
    if grad * scale > MAX_GRADIENT:
        scale = MAX_GRADIENT / grad
    return smooth.full(np.ascontiguousarray(smooth.samples * np.float32(scale)))


def _coefficients(n: int, size: tuple[int, int], *, smoothness: float, seed: Seed) -> F32:
    """Eq. 7's ``a_i(x)``: ``(H, W, n)``, non-negative, summing to 1 at every pixel.

    Independent exponential values at nodes ``smoothness`` px apart (uniform on the simplex
    once normalised), Gaussian-blurred (σ = half the spacing: a wider blur averages several
    nodes and pulls every pixel towards the mean shape), normalised per pixel."""
    rng = _rng(seed)
    m = math.ceil((size[0] - 1) / smoothness) + 3, math.ceil((size[1] - 1) / smoothness) + 3
    smooth = _Smooth(size, smoothness, 0.5 * smoothness, rng.standard_exponential(m + (n,)) + 1e-6)
    a = smooth.samples / smooth.samples.sum(axis=2, keepdims=True)
    # normalised on the samples: the bilinear interpolation of convex weights is convex
    return smooth.full(np.ascontiguousarray(a, dtype=np.float32))


def blend_fields(fields: Sequence[Any], *, seed: Seed = 0, smoothness: float) -> F32:
    """Eq. 7: a random convex combination ``W⁻¹(x) = Σ_i a_i(x) W_i⁻¹(x)`` of ``fields``.

    The coefficient map ``a_i(x)`` is a small set of random coefficients (nodes ``smoothness``
    px apart), blurred by a Gaussian (σ = ``smoothness / 2``) and normalised per pixel, so at
    every pixel the result lies in the convex hull of the fields' values there.

    Parameters
    ----------
    fields : sequence of (H, W, 2) array_like of float
        The exemplars' inverse registration fields (``LeafModel.inverse``), all one size.
    seed : int or numpy.random.Generator, default 0
    smoothness : float
        Spacing of the random coefficients in px (>= 1).

    Returns
    -------
    (H, W, 2) ndarray of float32
    """
    if isinstance(fields, np.ndarray) and fields.ndim == 4:
        fields = list(fields)
    if not isinstance(fields, Sequence) or len(fields) == 0:
        raise ValueError("fields: expected a non-empty sequence of (H, W, 2) fields")
    fs = [as_field(fields[0], "fields[0]")]
    fs += [as_field(f, f"fields[{i}]", fs[0].shape[:2]) for i, f in enumerate(fields) if i > 0]
    return _blend(fs, seed, check_float(smoothness, "smoothness", 1.0))[0]


def _blend(fs: list[F32], seed: Seed, smoothness: float) -> tuple[F32, F32]:
    """Eq. 7's field and its coefficient map."""
    a = _coefficients(len(fs), (fs[0].shape[0], fs[0].shape[1]), smoothness=smoothness, seed=seed)
    out = np.zeros_like(fs[0])
    for i, f in enumerate(fs):
        out += a[:, :, i : i + 1] * f
    return out, a


def _check_model(model: Any) -> LeafModel:
    if not isinstance(model, LeafModel):
        raise TypeError(f"model: expected a phloem.leaves.LeafModel, got {type(model).__name__}")
    n, k = model.n_exemplars, model.n_layers - 1
    if n < 2:
        raise ValueError(f"model: expected at least two exemplars to mix, got {n}")
    if k < 0:
        raise ValueError("model: expected at least the background layer, got an empty order")
    h, w = model.size
    per_exemplar: dict[str, Sequence[object]] = {
        "inverse": model.inverse,
        "residual": model.residual,
        "background": model.background,
        "layers": model.layers,
        "dissimilarity": model.dissimilarity,
    }
    for name, values in per_exemplar.items():
        if len(values) != n:
            raise ValueError(f"model: expected {n} {name} entries, one per exemplar, got {len(values)}")
    for name, per_layer in (("lam", model.lam), ("delta", model.delta)):
        if len(per_layer) != k:
            raise ValueError(f"model: expected {k} {name} values, one per non-background layer, got {len(per_layer)}")
    for i in range(n):
        if np.shape(model.inverse[i]) != (h, w, 2):
            raise ValueError(f"model: inverse[{i}] has shape {np.shape(model.inverse[i])}, expected {(h, w, 2)}")
        if np.shape(model.background[i]) != (h, w, 4):
            raise ValueError(f"model: background[{i}] has shape {np.shape(model.background[i])}, expected {(h, w, 4)}")
        if len(model.layers[i]) != k or len(model.dissimilarity[i]) != k:
            raise ValueError(f"model: exemplar {i} has {len(model.layers[i])} layers, expected {k}")
        for j in range(k):
            if np.shape(model.layers[i][j]) != (h, w, 4) or np.shape(model.dissimilarity[i][j]) != (h, w):
                raise ValueError(f"model: layer {j} of exemplar {i} is not on the {h}×{w} canvas")
    return model


def _bounds(model: LeafModel) -> list[float]:
    """Each exemplar's random-warp bound: its registration error. The training leaf's 0 is
    by construction, not a measurement, so it gets the others' mean."""
    res = [float(r) if math.isfinite(float(r)) and float(r) > 0 else 0.0 for r in model.residual]
    others = [r for i, r in enumerate(res) if i != model.training]
    mean = float(np.mean(others)) if others else 0.0
    return [mean if i == model.training else r for i, r in enumerate(res)]


def _sizes(model: LeafModel) -> NDArray[np.float64] | None:
    """Each exemplar's linear size relative to the training leaf's, ``1 / scale`` (the factor
    the analysis' pose scaled it by), or None where the model has no scales (all 1)."""
    scale = list(model.scale)
    if not scale:
        return None
    if len(scale) != model.n_exemplars:
        raise ValueError(f"model: expected {model.n_exemplars} scale values, one per exemplar, got {len(scale)}")
    s = np.asarray(scale, np.float64)
    if not (np.isfinite(s).all() and (s > 0).all()):
        raise ValueError(f"model: expected finite positive scales, got {scale}")
    return np.asarray(1.0 / s, np.float64)


def _size_factor(coefficients: F32, leaf: NDArray[np.bool_], sizes: NDArray[np.float64]) -> float:
    """The new leaf's linear size: the exemplars' sizes weighed by Eq. 7's mean coefficients
    over the leaf, so its size follows the same blend as its shape."""
    a = coefficients[leaf].mean(axis=0) if leaf.any() else np.full(len(sizes), 1.0 / len(sizes))
    return float(np.dot(a, sizes) / a.sum())


def _resize(rgba: F32, factor: float) -> F32:
    """``rgba`` (straight alpha) scaled by ``factor``, premultiplied while it is resampled."""
    if abs(factor - 1.0) < 1e-3:
        return rgba
    h, w = rgba.shape[:2]
    size = (max(round(w * factor), 1), max(round(h * factor), 1))
    mode = cv2.INTER_AREA if factor < 1 else cv2.INTER_LINEAR
    return straight(np.asarray(cv2.resize(premultiplied(rgba), size, interpolation=mode), np.float32))


def _compose(background: F32, layers: list[F32], dissimilarity: list[F32], delta: list[float]) -> F32:
    """Premultiplied composition: layer ``k`` weighs ``w_k = α_k / (1 + (D_k/δ_k)⁴)``, the
    background ``Π_k (1 − w_k)``; colours are averaged with the weights normalised per pixel
    (the total is at least 1), the alpha is the background's. Only the background's bounding
    box is computed: everything else is transparent."""
    out = np.zeros_like(background)
    box = bounding_box(background[..., 3] > 0)
    bg = background[box]
    a = bg[..., 3:4]
    colour = np.zeros(bg.shape[:2] + (3,), np.float32)
    np.divide(bg[..., :3], a, out=colour, where=a > 1e-6)
    keep = np.ones(bg.shape[:2], np.float32)
    total = np.zeros(bg.shape[:2], np.float32)
    layered = np.zeros_like(colour)
    for layer, dis, dl in zip(layers, dissimilarity, delta, strict=True):
        lay = layer[box]
        if dl > 0:
            t = np.maximum(dis[box], 0.0) * np.float32(1.0 / dl)
            t *= t
            t *= t
            g = np.reciprocal(t + 1.0, out=t)
        else:
            g = np.ones(bg.shape[:2], np.float32)
        # lay[..., :3] is premultiplied, so g · (α c) is w · c
        layered += g[..., None] * lay[..., :3]
        w = g * np.clip(lay[..., 3], 0.0, 1.0)
        total += w
        keep *= 1.0 - w
    total += keep
    colour *= keep[..., None]
    colour += layered
    colour *= (a[..., 0] / total)[..., None]
    out[box + (slice(0, 3),)] = colour
    out[box + (3,)] = a[..., 0]
    return out


def _one_leaf(alpha: NDArray[np.float32]) -> NDArray[np.float32]:
    """``alpha`` with only the largest component of ``alpha > 0.5`` and its soft rim (pixels
    of alpha <= 0.5 within 2 px of it): the new leaf is one connected piece."""
    solid = alpha > 0.5
    labels, n = ndimage.label(solid)
    if n == 0:
        return alpha
    sizes = np.bincount(labels.ravel())[1:]
    main = labels == (1 + int(np.argmax(sizes)))
    rim = ndimage.binary_dilation(main, iterations=2) & ~solid
    return np.where(main | rim, alpha, np.float32(0)).astype(np.float32)


def _crop(rgba: F32, margin: int) -> F32:
    inner = rgba[bounding_box(rgba[..., 3] > 0)]
    out = np.zeros((inner.shape[0] + 2 * margin, inner.shape[1] + 2 * margin, 4), np.float32)
    out[margin : margin + inner.shape[0], margin : margin + inner.shape[1]] = inner
    return out


def _corrector() -> Callable[..., Any]:
    """The texture correction of the last step (a seam the tests replace with a stand-in)."""
    return correct_texture


def _mixes(n_exemplars: int, n_layers: int, seed: int, count: int) -> list[tuple[int, list[int]]]:
    """The exemplars of leaves ``0 .. count - 1``: each one's background, and each layer's
    (never the background's).

    Two leaves of one mix differ only by small warps and their shape, and independent draws
    repeat mixes early (docs/pipelines/leaves/synthesis.md). So the mixes are dealt: each leaf
    takes, of the mixes used least so far, one whose
    background and then whose layers' exemplars have been used least, ties broken by a seeded
    shuffle. A set therefore repeats no mix before it has used them all, and its first leaves
    spread over the backgrounds. Leaf ``n`` depends only on the seed and ``n``. Beyond
    :data:`MAX_DEALT` mixes they are drawn independently; repeats are then rare anyway.
    """
    others = n_exemplars - 1
    total = n_exemplars * others**n_layers
    if total > MAX_DEALT:
        picks = [int(np.random.default_rng((seed, _MIX_STREAM, leaf)).integers(total)) for leaf in range(count)]
        return [_decode(k, n_exemplars, n_layers) for k in picks]
    decoded = [_decode(k, n_exemplars, n_layers) for k in range(total)]
    bg = np.array([d[0] for d in decoded], np.int64)
    lay = np.array([d[1] for d in decoded], np.int64).reshape(total, n_layers)
    rank = np.empty(total, np.int64)
    rank[np.random.default_rng((seed, _MIX_STREAM)).permutation(total)] = np.arange(total)
    uses, bg_uses, layer_uses = (
        np.zeros(total, np.int64),
        np.zeros(n_exemplars, np.int64),
        np.zeros((n_layers, n_exemplars), np.int64),
    )
    out = []
    for _ in range(count):
        cand = np.flatnonzero(uses == uses.min())
        key = bg_uses[bg[cand]]
        cand = cand[key == key.min()]
        key = layer_uses[np.arange(n_layers), lay[cand]].sum(axis=1)
        cand = cand[key == key.min()]
        k = int(cand[np.argmin(rank[cand])])
        uses[k] += 1
        bg_uses[bg[k]] += 1
        layer_uses[np.arange(n_layers), lay[k]] += 1
        out.append(decoded[k])
    return out


def _decode(k: int, n_exemplars: int, n_layers: int) -> tuple[int, list[int]]:
    """Mix number ``k``: background ``k mod n``, then each layer's exemplar among the others."""
    k, j_bg = divmod(k, n_exemplars)
    j_layers = []
    for _ in range(n_layers):
        k, j = divmod(k, n_exemplars - 1)
        j_layers.append(j if j < j_bg else j + 1)
    return j_bg, j_layers


def _training_frame(
    m: LeafModel,
    mix: tuple[int, list[int]],
    rng: np.random.Generator,
    bounds: list[float],
    structure: list[float],
    threads: int | None,
) -> F32:
    """Steps 1–2: the background of exemplar ``mix[0]`` and layer ``k`` of exemplar
    ``mix[1][k]``, randomly warped and fused by D, in the training frame (premultiplied RGBA)."""
    n_layers = m.n_layers - 1
    h, w = m.size
    j_bg, j_layers = mix
    seeds = rng.integers(0, 2**63, size=n_layers + 1)
    smooth = max(WARP_SMOOTHNESS * min(h, w), 1.0)
    field = random_warp((h, w), bounds[j_bg], smoothness=smooth, seed=int(seeds[0]))
    bg = sample_checked(premultiplied(m.background[j_bg]), field, threads)
    layers, diss = [], []
    for k, j in enumerate(j_layers):
        field = random_warp((h, w), (1.0 - structure[k]) * bounds[j], smoothness=smooth, seed=int(seeds[1 + k]))
        # D is NaN off the exemplar's leaf (leaves.induce): there the layer has no weight
        d = np.nan_to_num(np.asarray(m.dissimilarity[j][k], np.float32), nan=_FAR, posinf=_FAR, neginf=0.0)[..., None]
        warped = sample_checked(np.concatenate([premultiplied(m.layers[j][k]), d], axis=2), field, threads)
        layers.append(np.ascontiguousarray(warped[..., :4]))
        diss.append(np.ascontiguousarray(warped[..., 4]))
    return _compose(bg, layers, diss, [float(d) for d in m.delta])


def synthesize(
    model: LeafModel,
    *,
    count: int = 1,
    seed: Seed = 0,
    threads: int | None = None,
    progress: Progress = None,
) -> list[F32]:
    """New leaves of the species of ``model`` (Assa & Cohen-Or §5).

    Each leaf mixes exemplars: the inpainted background of one under a small smooth random
    warp (no larger than its registration error), each other layer from another exemplar under
    its own random warp (``1 − λ/κ`` times that, so structural layers barely move), fused by
    weights from ``D`` normalised per pixel; the composition is then warped into a new shape
    by a random convex combination of the exemplars' inverse registration fields (Eq. 7),
    texture-corrected where that warp distorts (when ``leaves.correct_texture`` is available),
    scaled to a size between the exemplars' own where the model records their pose scales
    (the same blend: Eq. 7's mean coefficients over the leaf), reduced to its largest
    connected leaf and cropped.

    Parameters
    ----------
    model : LeafModel
        The analysis of at least two exemplars (:func:`phloem.leaves.analyze`).
    count : int, default 1
        How many leaves (>= 1).
    seed : int or numpy.random.Generator, default 0
        Leaf ``n`` depends only on the seed and ``n``: the first leaves of a larger ``count``
        are the same leaves.
    threads : int, optional
        Worker threads of the samplers (default: the core's pool); the leaves do not depend
        on it.
    progress : callable, optional
        Called as ``progress(done, count)`` after each leaf; an exception it raises stops
        the run.

    Returns
    -------
    list of (h, w, 4) ndarray of float32
        RGBA leaves, straight alpha in [0, 1], each cropped to its leaf's bounding box with a
        transparent margin of 8 px (sizes vary).

    Raises
    ------
    ValueError
        ``count < 1``, a model with one exemplar, or fields not on the model's canvas.
    """
    m = _check_model(model)
    n_leaves = check_int(count, "count", 1)
    s = check_seed(seed)
    nt = check_threads(threads)
    if progress is not None and not callable(progress):
        raise TypeError(f"progress: expected a callable progress(done, total), got {progress!r}")
    side = float(min(m.size))
    bounds = _bounds(m)
    sizes = _sizes(m)
    structure = [min(max(float(lam) / m.kappa, 0.0), 1.0) for lam in m.lam]
    correct = _corrector()
    inverse = [as_field(f, f"model.inverse[{i}]") for i, f in enumerate(m.inverse)]
    mixes = _mixes(m.n_exemplars, m.n_layers - 1, s, n_leaves)
    out: list[F32] = []
    for leaf, mix in enumerate(mixes):
        rng = np.random.default_rng(derive_seed(s, leaf))
        composition = _training_frame(m, mix, rng, bounds, structure, nt)
        seeds = rng.integers(0, 2**63, size=2)
        back, coefficients = _blend(inverse, int(seeds[0]), max(BLEND_SMOOTHNESS * side, 1.0))
        pre = sample_checked(composition, back, nt)
        box = bounding_box(pre[..., 3] > 0)
        if correct is None:
            leaf_img = straight(pre[box])
        else:
            full = straight(pre)
            fixed = np.asarray(correct(full, straight(composition), back, seed=int(seeds[1]), threads=nt), np.float32)
            full[..., :3] = fixed[..., :3]  # the alpha stays the warped one
            leaf_img = full[box]
        if sizes is not None:
            leaf_img = _resize(leaf_img, _size_factor(coefficients, pre[..., 3] > 0.5, sizes))
        leaf_img[..., 3] = _one_leaf(leaf_img[..., 3])
        leaf_img[leaf_img[..., 3] <= 0] = 0.0
        out.append(_crop(np.ascontiguousarray(leaf_img, dtype=np.float32), MARGIN))
        if progress is not None:
            progress(leaf + 1, n_leaves)
    return out
