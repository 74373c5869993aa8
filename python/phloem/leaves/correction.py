"""Texture correction after a warp (Assa & Cohen-Or §3, in the spirit of Fang & Hart 2007).

A registration or synthesis warp stretches texture where it magnifies and squeezes it where it
shrinks: veins thicken, spots turn into ellipses. Where the warp's Jacobian leaves a tolerance
band, the warped pixels are replaced by texture re-synthesised from patches of the *unwarped*
source taken near the places the warp says they came from (guided quilting, then PatchMatch
search and vote), so texture keeps the source's scale and stays near its registered position;
every other pixel is returned bit for bit. See
``docs/pipelines/leaves/correction.md``.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .. import _core
from .._boxes import bounding_box, points_box
from .._validate import as_image, check_float, check_patch_size, check_seed, check_threads, derive_seed
from ._rgba import premultiplied

__all__ = ["correct_texture", "distortion"]

F32 = NDArray[np.float32]

# Search-and-vote rounds after the quilted start, and PatchMatch passes per search: the start is
# already source texture and the search starts from the quilted positions, so the rounds only
# mend block seams and one pass each does it as well as three (docs/pipelines/leaves/correction.md).
_ROUNDS = 2
_SEARCH_ITERATIONS = 1
# Side of the rigid source blocks of the quilted start, in patch sides.
_BLOCK = 1
# Search radius of a block around the warp's position, in patch sides, and the small cost per
# squared pixel of leaving that position, which breaks ties towards the warp.
_RADIUS = 1
_BIAS = 1e-4
# How far beyond the quilted positions the re-synthesis may take source patches, in patch sides.
_SOURCE_MARGIN = 4
# Alpha below which a pixel is off the leaf (straight alpha: its colour means nothing).
_ON_LEAF = 0.5


# A check that a caller running a correction on a worker thread installs, called between the
# engine calls so it can stop the correction there: Python delivers Ctrl-C only to the main
# thread (phloem.leaves.analysis).
_checks = threading.local()


@contextmanager
def checked(check: Callable[[], None]) -> Iterator[None]:
    """Within the block, corrections on this thread call ``check()`` between engine calls."""
    _checks.check = check
    try:
        yield
    finally:
        del _checks.check


def _check() -> None:
    check = getattr(_checks, "check", None)
    if check is not None:
        check()


def _field(field: Any, shape: tuple[int, int]) -> F32:
    arr = np.asarray(field)
    if arr.dtype == np.bool_ or not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise TypeError(f"field: expected a real-valued (H, W, 2) displacement field, got dtype {arr.dtype}")
    if arr.shape != (*shape, 2):
        raise ValueError(f"field: expected shape {(*shape, 2)} (dx, dy) per warped pixel, got {arr.shape}")
    out = np.ascontiguousarray(arr, dtype=np.float32)
    if not np.isfinite(out).all():
        raise ValueError("field: expected finite displacements")
    return out


def _singular_values(field: F32) -> tuple[F32, F32]:
    """Singular values (largest, smallest) of the Jacobian of ``x ↦ x + field(x)`` per pixel."""
    dx, dy = field[..., 0].astype(np.float64), field[..., 1].astype(np.float64)
    # np.gradient: central differences inside, one-sided at the border.
    a = 1.0 + np.gradient(dx, axis=1)  # ∂(x + dx)/∂x
    b = np.gradient(dx, axis=0)  # ∂(x + dx)/∂y
    c = np.gradient(dy, axis=1)  # ∂(y + dy)/∂x
    d = 1.0 + np.gradient(dy, axis=0)  # ∂(y + dy)/∂y
    energy = a * a + b * b + c * c + d * d
    det = a * d - b * c
    root = np.sqrt(np.maximum(energy * energy - 4.0 * det * det, 0.0))
    big = np.sqrt((energy + root) / 2.0)
    small = np.sqrt(np.maximum(energy - root, 0.0) / 2.0)
    return big.astype(np.float32), small.astype(np.float32)


def distortion(field: Any, *, tolerance: float = 0.25) -> NDArray[np.bool_]:
    """Pixels where a warp stretches or squeezes beyond a tolerance.

    Parameters
    ----------
    field : (H, W, 2) array_like
        Displacement ``(dx, dy)`` of each warped pixel to the source position it samples.
    tolerance : float, optional
        A pixel is distorted when a singular value of the Jacobian of ``x ↦ x + field(x)``
        (central differences) lies outside ``[1/(1 + tolerance), 1 + tolerance]`` (default 0.25).

    Returns
    -------
    mask : (H, W) ndarray of bool
        True where the warp distorts.

    Examples
    --------
    >>> import numpy as np
    >>> from phloem.leaves import distortion
    >>> f = np.zeros((8, 8, 2), np.float32); f[..., 0] = np.arange(8) * 0.5  # ×1.5 along x
    >>> bool(distortion(f).all()), bool(distortion(f, tolerance=0.6).any())
    (True, False)
    """
    tol = check_float(tolerance, "tolerance", 0.0, inclusive=False)
    arr = np.asarray(field)
    if arr.ndim != 3 or arr.shape[2] != 2 or 0 in arr.shape:
        raise ValueError(f"field: expected a non-empty (H, W, 2) displacement field, got shape {arr.shape}")
    big, small = _singular_values(_field(arr, arr.shape[:2]))
    hi = np.float32(1.0 + tol)
    return np.asarray((big > hi) | (small < np.float32(1.0) / hi))


def _features(image: F32) -> F32:
    """What patches are compared and voted on: premultiplied colour and alpha for RGBA."""
    return premultiplied(image) if image.shape[2] == 4 else image


def correct_texture(
    warped: Any,
    source: Any,
    field: Any,
    *,
    patch_size: int = 7,
    tolerance: float = 0.25,
    seed: int | np.random.Generator = 0,
    threads: int | None = None,
) -> F32:
    """Replace warp-stretched texture by patches of the unwarped source.

    ``warped`` is ``sample(source, field)``: pixel ``x`` shows ``source(x + field(x))``. Where
    the Jacobian of ``x ↦ x + field(x)`` has a singular value outside
    ``[1/(1 + tolerance), 1 + tolerance]`` (:func:`distortion`; for RGBA only on the leaf,
    alpha > 0.5) the warp has magnified or shrunk the texture, and those pixels are
    re-synthesised from the source, as Fang & Hart (2007) resynthesise stretched texture from
    the source image at the source coordinates:

    1. *Guided quilting.* Blocks of ``patch_size²`` pixels cover the distorted region in raster
       order; each is copied rigidly, so at the source's scale, from within ``patch_size`` px
       of where the warp maps its centre, choosing the position whose rim best matches the
       pixels already known around the block (undistorted ones and earlier blocks) and whose
       alpha matches the warped alpha (Efros & Freeman's image quilting with the warp as guide).
    2. *Search and vote.* Two rounds of texture optimisation restricted to the region
       (Kwatra et al. 2005; Wexler et al. 2007) mend the block seams: every patch touching the
       region is matched to a source patch by PatchMatch (the engine of
       :func:`phloem.patch.nnf`, with masks, started from the quilted positions) and each
       distorted pixel becomes the mean of the patches over it (:func:`phloem.patch.vote`).

    Only unwarped source patches are ever pasted, so the texture comes back at the source's
    scale near its registered place; the undistorted pixels steer the patches and are returned
    unchanged, bit for bit. For RGBA, patches are compared and voted premultiplied (so off-leaf
    colours count for nothing) and the alpha is ``warped``'s.

    Parameters
    ----------
    warped : (H, W[, C]) array_like
        The warped image (RGBA float in [0, 1], straight alpha, for leaves; any channels work).
    source : (Hs, Ws[, C]) array_like
        The unwarped image, same channels as ``warped``.
    field : (H, W, 2) array_like
        Displacement ``(dx, dy)`` from each warped pixel to its source position.
    patch_size : int, optional
        Patch side, odd, at least 3 (default 7).
    tolerance : float, optional
        Relative stretch tolerated before a pixel is corrected, > 0 (default 0.25).
    seed : int or numpy.random.Generator, optional
        Seed of the patch search (default 0); identical output for any thread count.
    threads : int, optional
        Worker threads (default: ``PHLOEM_NUM_THREADS`` or all cores).

    Returns
    -------
    corrected : (H, W[, C]) ndarray of float32
        ``warped`` with the distorted pixels re-synthesised; with 4 channels the alpha is
        ``warped``'s everywhere.

    References
    ----------
    .. [1] H. Fang, J. C. Hart, "Detail preserving shape deformation in image editing", ACM
       TOG 26(3), 2007.
    .. [2] A. A. Efros, W. T. Freeman, "Image quilting for texture synthesis and transfer",
       SIGGRAPH 2001.
    .. [3] Y. Wexler, E. Shechtman, M. Irani, "Space-time completion of video", IEEE TPAMI
       29(3), 2007.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> from phloem.leaves import correct_texture
    >>> src = np.tile((np.arange(48) // 3 % 2).astype(np.float32), (32, 1))
    >>> f = np.zeros((32, 48, 2), np.float32); f[..., 0] = -0.5 * np.arange(48) + 12  # ×2 along x
    >>> warped = phloem._core.tps_sample(src[..., None], f, threads=1)[..., 0]
    >>> out = correct_texture(warped, src, f, seed=1)
    >>> out.shape, bool(np.array_equal(out, warped))
    ((32, 48), False)
    """
    tgt = as_image(warped, "warped")
    src = as_image(source, "source")
    if tgt.shape[2] > 4:
        raise ValueError(f"warped: expected 1 to 4 channels (grey, RGB, RGBA), got {tgt.shape[2]}")
    if src.shape[2] != tgt.shape[2]:
        raise ValueError(f"source: expected {tgt.shape[2]} channels like warped, got {src.shape[2]}")
    p = check_patch_size(patch_size)
    if p < 3:
        raise ValueError(f"patch_size: expected an odd size >= 3, got {p}")
    if p > min(src.shape[:2]):
        raise ValueError(f"patch_size: {p} does not fit in the {src.shape[0]}×{src.shape[1]} source")
    f = _field(field, tgt.shape[:2])
    tol = check_float(tolerance, "tolerance", 0.0, inclusive=False)
    s = check_seed(seed)
    nthreads = check_threads(threads)

    rgba = tgt.shape[2] == 4
    hole = distortion(f, tolerance=tol)
    if rgba:
        hole &= tgt[..., 3] > _ON_LEAF
    if not hole.any():
        return _restore(tgt.copy(), warped)

    r = p // 2
    kernel = np.ones((p, p), np.uint8)
    # Every patch that covers a hole pixel needs a match (Wexler's completion neighbourhood).
    need = cv2.dilate(hole.astype(np.uint8), kernel).astype(bool)
    allowed = src[..., 3] > _ON_LEAF if rgba else np.ones(src.shape[:2], bool)
    allowed[:r] = allowed[-r:] = False
    allowed[:, :r] = allowed[:, -r:] = False
    if not allowed.any():
        raise ValueError("source: no patch centre lies on the leaf (alpha > 0.5) away from the border")

    src_feat = np.ascontiguousarray(_features(src))
    out = tgt.copy()
    # Fang & Hart's start: the hole is re-tiled with unwarped blocks of the source, each found
    # near where the warp says it came from and chosen to agree with what is already there.
    pos = _quilt(np.ascontiguousarray(_features(tgt)), src_feat, hole, f, rgba=rgba, patch_size=p)
    _check()
    iy, ix = pos[..., 0], pos[..., 1]
    inside = hole & (iy >= 0) & (ix >= 0) & (iy < src.shape[0]) & (ix < src.shape[1])
    cy, cx = np.clip(iy, 0, src.shape[0] - 1), np.clip(ix, 0, src.shape[1] - 1)
    placed = inside if not rgba else inside & (src[cy, cx, 3] > 0)
    if rgba:
        out[..., :3][placed] = src[cy, cx, :3][placed]
    else:
        out[placed] = src[cy, cx][placed]

    # The search and vote only need the hole's patches and their footprints (2r around the hole:
    # patches then clip exactly where they would on the whole image) and the source around the
    # quilted positions, where Fang & Hart take texture from; the crops make them cost what the
    # hole costs rather than what the image does.
    ty, tx = bounding_box(hole, 2 * r)
    sy, sx = points_box(cy[placed], cx[placed], src.shape, _SOURCE_MARGIN * p)
    allowed_box = np.ascontiguousarray(allowed[sy, sx])
    if not allowed_box.any():
        sy, sx, allowed_box = slice(0, src.shape[0]), slice(0, src.shape[1]), allowed
    src_box = np.ascontiguousarray(src_feat[sy, sx])
    hole_box, need_box = np.ascontiguousarray(hole[ty, tx]), np.ascontiguousarray(need[ty, tx])
    oy, ox = cy[ty, tx] - sy.start, cx[ty, tx] - sx.start
    ok = (inside & allowed[cy, cx])[ty, tx] & (oy >= 0) & (ox >= 0) & (oy < src_box.shape[0]) & (ox < src_box.shape[1])
    ok &= allowed_box[np.clip(oy, 0, src_box.shape[0] - 1), np.clip(ox, 0, src_box.shape[1] - 1)]
    init = np.where(ok[..., None], np.stack([oy, ox], axis=-1), -1).astype(np.int32)
    out_box = out[ty, tx].copy()
    for k in range(_ROUNDS):
        nnf, _, _ = _core.nnf(
            src_box, np.ascontiguousarray(_features(out_box)), patch_size=p, iterations=_SEARCH_ITERATIONS,
            levels=1, exact=False, seed=derive_seed(s, k), weights=None, source_mask=allowed_box,
            target_mask=need_box, init=init, source_knn=None, source_cost=None, threads=nthreads, kdtree=False,
        )  # fmt: skip
        _check()
        # Only the hole's pixels are kept, so only they are voted (each as the full vote would).
        voted, weight = _core.vote(
            src_box, nnf, patch_size=p, weights=None, threads=nthreads, mean_shift=0, pixels=hole_box
        )
        _check()
        _paste(out_box, hole_box, voted, weight)
        init = nnf
    out[ty, tx] = np.where(hole_box[..., None], out_box, out[ty, tx])
    return _restore(out, warped)


def _quilt(
    target: F32, source: F32, hole: NDArray[np.bool_], field: F32, *, rgba: bool, patch_size: int
) -> NDArray[np.int32]:
    """Source (row, col) of every hole pixel after guided quilting; ``-1`` elsewhere.

    Blocks of ``_BLOCK × patch_size`` pixels cover the hole in raster order. Each is copied
    rigidly (so at the source's scale) from the source position, within ``_RADIUS`` patch sides
    of where the warp maps its centre, whose surroundings best match the pixels already known
    around the block, undistorted or placed before (squared differences over a
    ``patch_size // 2`` rim, and alpha over the whole block for RGBA, since it is known
    everywhere), as image quilting places blocks (Efros & Freeman 2001) with the warp as guide.
    The loop is sequential, in Rust (``rust/core/src/correction.rs``).
    """
    return _core.guided_quilt(
        target, source, np.ascontiguousarray(hole), field, block=_BLOCK * patch_size, rim=patch_size // 2,
        radius=_RADIUS * patch_size, bias=_BIAS, alpha_known=rgba,
    )  # fmt: skip


def _paste(out: F32, hole: NDArray[np.bool_], voted: F32, weight: F32) -> None:
    """Write the voted features into the hole of ``out`` (straight colour; alpha stays)."""
    fill = hole & (weight > 0)
    if out.shape[2] == 4:
        a = np.maximum(voted[..., 3:4], np.float32(1e-6))
        colour = np.clip(voted[..., :3] / a, 0.0, 1.0)
        out[..., :3][fill] = colour[fill]
    else:
        out[fill] = voted[fill]


def _restore(out: F32, like: Any) -> F32:
    return out[:, :, 0] if np.ndim(like) == 2 else out
