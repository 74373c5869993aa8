"""Analysis of a set of leaves (Assa & Cohen-Or §3–4): :func:`analyze` → :class:`LeafModel`.

Every exemplar is posed on the training leaf (a similarity: principal axes, the better of the
four half-turn/mirror choices, area), registered to it non-rigidly and texture-corrected;
the user's scribbles are expanded to layers on the training leaf; then, one layer at a time
in removal order, the layer is induced on every exemplar and peeled (its pixels completed
from the rest of the leaf), so the next layer is induced on what remains (Fig. 7).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .. import _memory
from .._progress import Progress
from .._validate import as_image, check_float, check_int, check_seed, check_threads, derive_seed
from ._fill import fill_holes, fill_region
from ._stages import Stages, Task
from .correction import checked, correct_texture
from .induction import induce
from .model import LeafModel
from .pose import canvas, warp_rgba
from .registration import register
from .scribbles import layers_from_scribbles, read_scribbles

__all__ = ["analyze"]

F32 = NDArray[np.float32]

#: Pixels around a layer that are peeled with it: its anti-aliased edge, widened by the
#: registration warp's bilinear resampling, is half layer colour and would stay behind as a
#: ghost outline in the background layer.
PEEL_RIM = 2


def _leaves(leaves: Any) -> list[F32]:
    if isinstance(leaves, np.ndarray) or not isinstance(leaves, Sequence):
        raise TypeError("leaves: expected a list of RGBA leaf images (each (H, W, 4)), e.g. from leaves.extract")
    out = []
    for i, leaf in enumerate(leaves):
        img = as_image(leaf, f"leaves[{i}]")
        if img.shape[2] != 4:
            raise ValueError(
                f"leaves[{i}]: expected an RGBA leaf (H, W, 4), got {img.shape[2]} channel(s); cut leaves from a scan "
                "with leaves.extract"
            )
        img = np.clip(img, 0.0, 1.0)
        if not (img[..., 3] > 0.5).any():
            raise ValueError(f"leaves[{i}]: the alpha channel is empty; expected a leaf")
        out.append(img)
    if len(out) < 2:
        raise ValueError(f"leaves: expected at least 2 leaves (the training leaf and one exemplar), got {len(out)}")
    return out


def _order(order: Any, n_layers: int) -> list[int]:
    full = list(range(1, n_layers + 1))
    if order is None:
        return full
    try:
        seq = [int(v) for v in order]
    except (TypeError, ValueError):
        raise TypeError(f"order: expected a sequence of the layer labels 1..{n_layers}, got {order!r}") from None
    if sorted(seq) != full:
        raise ValueError(f"order: expected a permutation of the layer labels 1..{n_layers}, got {seq}")
    return seq


def _peel(
    image: F32, layer: NDArray[np.bool_], *, seed: int, threads: int | None, check: Callable[[], None] | None = None
) -> F32:
    """The image with ``layer``'s pixels and a rim of :data:`PEEL_RIM` px completed from the
    rest of the leaf; alpha unchanged. ``check`` runs after every completion iteration."""
    leaf = image[..., 3] > 0.5
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * PEEL_RIM + 1, 2 * PEEL_RIM + 1))
    hole = cv2.dilate(layer.astype(np.uint8), disk).astype(bool) & leaf
    if not hole.any():
        return image
    if not (leaf & ~hole).any():
        raise ValueError("scribbles: a layer covers the whole leaf; expected other layers to remain")
    return fill_region(image, hole, seed=seed, threads=threads, check=check)


def _on_pool(fill: Callable[..., F32], *args: Any, seed: int) -> Task[F32]:
    """``fill(*args, seed=seed)`` as a task of :class:`~phloem.leaves._stages.Stages` (its threads and stop check)."""

    def task(threads: int | None, check: Callable[[], None]) -> F32:
        return fill(*args, seed=seed, threads=threads, check=check)

    return task


def analyze(
    leaves: Sequence[Any],
    scribbles: Any,
    *,
    training: int = 0,
    order: Sequence[int] | None = None,
    points: int = 100,
    epsilon: float = 40.0,
    kappa: float = 1.5,
    seed: int | np.random.Generator = 0,
    threads: int | None = None,
    keep_holes: bool = False,
    progress: Progress = None,
    max_memory: int | None = None,
) -> LeafModel:
    """Analyse a set of leaves of one species from scribbles on one of them (§3–4).

    1. **Pose and canvas.** Every exemplar is moved onto the training leaf by a similarity
       (:func:`pose`), and all of them are placed on one canvas that holds them all.
    2. **Registration** (§3): each exemplar is registered to the training leaf by TPS-RPM on
       ``points`` edge keypoints (:func:`register`), warped into the training frame and
       texture-corrected where the warp stretched it (:func:`correct_texture`).
    3. **Layers from scribbles**: the scribbles are expanded to full layers on the training
       leaf (:func:`layers_from_scribbles`).
    4. **Induction and peeling** (§4): for each layer but the last, in removal order, the
       layer is induced on every exemplar (:func:`induce`: colour term, spatial term of
       falloff ``epsilon``, δ and λ with ``kappa``), then its pixels are completed from the
       rest of each leaf (:func:`phloem.texture.complete`), so the next layer is induced on
       what remains. On the training leaf the user's layer is kept as it is.
    5. **Holes** (not in the paper): interior holes of the backgrounds (insect damage) are
       completed, unless ``keep_holes``; a hole left there would appear, in the same place,
       in every new leaf built on that background.

    Parameters
    ----------
    leaves : sequence of (H, W, 4) array_like
        Two or more RGBA leaves of one species (e.g. from :func:`extract`), any sizes, any
        orientation.
    scribbles : (H, W) or (H, W, 3|4) array_like, or path
        The user's strokes on the training leaf, the size of ``leaves[training]``: an integer
        image (0 unmarked, 1..n a layer, n the residual/background layer) or an RGB(A) image
        with one opaque colour per layer (:func:`read_scribbles`).
    training : int, optional
        Index of the leaf the scribbles were drawn on (default 0).
    order : sequence of int, optional
        The layer labels 1..n in removal order, the residual layer last (default 1, 2, ..., n).
    points : int, optional
        Registration keypoints per leaf (the paper: about 100).
    epsilon : float, optional
        Spatial falloff ε of Eq. 3 in px (the paper: 40).
    kappa : float, optional
        κ of Eq. 5 (the paper: 1.5).
    seed : int or numpy.random.Generator, optional
        Seed (default 0); the model is the same for any thread count.
    threads : int, optional
        Worker threads (default: ``PHLOEM_NUM_THREADS`` or all cores); the exemplars'
        registrations and peels run side by side on them.
    keep_holes : bool, optional
        Keep the exemplars' interior holes in their backgrounds (default False: complete them).
    progress : callable, optional
        ``progress(done, total)`` after every registration, induction, peel and hole fill, in
        that order, from the calling thread.
    max_memory : int, optional
        Refuse the job with :class:`phloem.MemoryLimitError` if its estimated peak is over
        this many bytes (default: 75% of the machine's memory).

    Returns
    -------
    LeafModel
        Save it with :meth:`LeafModel.save`; :func:`synthesize` makes new leaves from it.

    Raises
    ------
    ValueError
        Fewer than two leaves, a leaf without alpha, scribbles of the wrong size or with fewer
        than two layers, an ``order`` that is not a permutation of the layers, or a layer that
        covers a whole leaf.

    Examples
    --------
    >>> import numpy as np, cv2, phloem
    >>> def leaf(w):
    ...     img = np.zeros((90, 60, 4), np.float32)
    ...     _ = cv2.ellipse(img, (30, 45), (w, 40), 0, 0, 360, (0.2, 0.5, 0.1, 1.0), -1)
    ...     _ = cv2.line(img, (30, 8), (30, 82), (0.6, 0.7, 0.3, 1.0), 2)
    ...     return img
    >>> scribbles = np.zeros((90, 60), np.int32)
    >>> scribbles[20:70, 30] = 1                   # the midrib
    >>> scribbles[40:50, 15] = 2                   # the blade (the residual layer)
    >>> model = phloem.leaves.analyze([leaf(20), leaf(22)], scribbles, points=40, epsilon=8)
    >>> model.n_exemplars, model.n_layers
    (2, 2)
    """
    imgs = _leaves(leaves)
    t = check_int(training, "training", 0)
    if t >= len(imgs):
        raise ValueError(f"training: expected an index below the number of leaves ({len(imgs)}), got {t}")
    n_points = check_int(points, "points", 3)
    eps = check_float(epsilon, "epsilon", 0.0, inclusive=False)
    kap = check_float(kappa, "kappa", 0.0, inclusive=False)
    s = check_seed(seed)
    th = check_threads(threads)
    labels_in, n_layers = read_scribbles(scribbles, imgs[t].shape[:2])
    removal = _order(order, n_layers)

    mats, scales, size = canvas(imgs, t)
    n = len(imgs)
    stages = Stages(th)
    # Side by side, each of the widest stage's tasks holds one completion's buffers.
    extra = (stages.width(n) - 1) * _memory.complete((*size, 3))
    _memory.check_size(_memory.leaves_analyze(size, n, n_layers) + extra, max_memory, size, "leaves")
    if not isinstance(keep_holes, (bool, np.bool_)):
        raise TypeError(f"keep_holes: expected True or False, got {keep_holes!r}")
    total = 2 * (n - 1) + 1 + (n_layers - 1) * (1 + n) + (0 if keep_holes else n)
    done = 0

    def tick() -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total)

    placed = [warp_rgba(img, m, size) for img, m in zip(imgs, mats)]
    ty, tx = int(np.rint(mats[t][1, 2])), int(np.rint(mats[t][0, 2]))  # whole pixels by construction
    scribble_canvas = np.zeros(size, np.int32)
    h, w = labels_in.shape
    scribble_canvas[ty : ty + h, tx : tx + w] = labels_in

    def aligner(i: int) -> Task[tuple[Any, F32]]:
        def task(threads: int | None, check: Callable[[], None]) -> tuple[Any, F32]:
            reg = register(placed[i], placed[t], points=n_points, seed=derive_seed(s, 1 + i), threads=threads)
            check()
            warped = reg.warp(placed[i], threads=threads)
            check()
            with checked(check):
                return reg, correct_texture(
                    warped, placed[i], reg.forward, seed=derive_seed(s, 101 + i), threads=threads
                )

        return task

    def expand(threads: int | None, check: Callable[[], None]) -> NDArray[np.int32]:
        return layers_from_scribbles(
            placed[t], scribble_canvas, order=removal, seed=derive_seed(s, 201), threads=threads
        )

    # Registrations (two ticks each: registered, corrected) and the scribbles' layers, which
    # need only the posed training leaf, side by side; ticks in the serial order.
    others = [i for i in range(n) if i != t]

    def ticks(k: int) -> None:
        for _ in range(1 if k == len(others) else 2):
            tick()

    first = stages.run([*(aligner(i) for i in others), expand], ticks)
    labels = first[-1]
    zero = np.zeros((*size, 2), np.float32)
    forward, inverse, residual, aligned = [zero] * n, [zero] * n, [0.0] * n, list(placed)
    for i, (reg, corrected) in zip(others, first[:-1]):
        forward[i], inverse[i], residual[i], aligned[i] = reg.forward, reg.inverse, float(reg.residual), corrected

    current = list(aligned)
    masks: list[list[NDArray[np.bool_]]] = [[] for _ in range(n)]
    dissimilarity: list[list[F32]] = [[] for _ in range(n)]
    layers: list[list[F32]] = [[] for _ in range(n)]
    lam, delta, objective = [], [], []
    for k, label in enumerate(removal[:-1]):
        user = labels == label
        ind = induce(current[t], user, current, epsilon=eps, kappa=kap, seed=derive_seed(s, 301 + k), threads=th)
        tick()
        lam.append(float(ind.lam))
        delta.append(float(ind.delta))
        objective.append(float(ind.objective))
        peels: list[Task[F32]] = []
        for i in range(n):
            m = (user if i == t else np.asarray(ind.masks[i], bool)) & (current[i][..., 3] > 0.5)
            masks[i].append(m)
            # D is undefined (NaN) off the leaf; there it is stored as the largest D there is, 1 + λ
            d = np.asarray(ind.dissimilarity[i], np.float32)
            dissimilarity[i].append(np.where(np.isnan(d), np.float32(1.0 + ind.lam), d).astype(np.float32))
            layer = current[i].copy()
            layer[..., 3] = np.where(m, current[i][..., 3], 0.0)
            layers[i].append(layer)
            peels.append(_on_pool(_peel, current[i], m, seed=derive_seed(s, 401 + 31 * k + i)))
        current = stages.run(peels, lambda _: tick())
    if not keep_holes:
        current = stages.run(
            [_on_pool(fill_holes, c, seed=derive_seed(s, 501 + i)) for i, c in enumerate(current)], lambda _: tick()
        )

    return LeafModel(
        training=t,
        order=removal,
        leaves=placed,
        forward=forward,
        inverse=inverse,
        residual=residual,
        scale=scales,
        aligned=aligned,
        masks=masks,
        dissimilarity=dissimilarity,
        layers=layers,
        background=current,
        lam=lam,
        delta=delta,
        objective=objective,
        kappa=kap,
    )
