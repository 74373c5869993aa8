"""Non-rigid registration of an exemplar leaf to the training leaf (Assa & Cohen-Or, §3).

About 100 keypoints on the strong edges of each leaf (Sobel over a bilateral-filtered image),
matched by TPS-RPM (Chui & Rangarajan 2003) in phloem's Rust core, give a thin-plate spline
from the training ("fixed") frame to the exemplar ("moving") frame, and from it two dense,
fold-free displacement fields. See ``docs/pipelines/leaves/registration.md``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .. import _core
from .._validate import as_image, check_int, check_seed, check_threads, derive_seed, restore_ndim
from ._fields import sample_checked

__all__ = ["Registration", "keypoints", "register"]

# TPS-RPM as phloem runs it (see the docs for why these values).
_RATE = 0.93
_ITERATIONS = 5
_FINAL_RATIO = 1e4
_LAMBDA1 = 1.0
_LAMBDA2 = 0.1
# Spacing of the nodes where the spline is evaluated exactly; bilinear in between.
_STEP = 4
# Sobel magnitude (3×3, grey levels 0–255) below which nothing counts as an edge.
_EDGE_FLOOR = 20.0


def _split(img: NDArray[np.float32]) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """Grey image (composited over black when there is alpha) and the leaf mask."""
    if img.shape[2] in (2, 4):
        alpha = np.clip(img[..., -1], 0, 1)
        grey = img[..., :-1].mean(axis=2) * alpha
        return grey.astype(np.float32), alpha > 0.5
    return img.mean(axis=2).astype(np.float32), np.ones(img.shape[:2], bool)


def keypoints(image: Any, *, points: int = 100, seed: int | np.random.Generator = 0) -> NDArray[np.float64]:
    """Keypoints on the strong edges of a leaf: ``(points, 2)`` ``(x, y)`` coordinates.

    The grey image (RGBA composited over black, so that the outline is an edge) is
    bilateral-filtered (9 px, σ_colour 50 grey levels, σ_space 5 px), its Sobel gradient
    magnitude taken, and the pixels in the top 10 % of the magnitude inside the (slightly
    dilated) leaf, and above a floor of 20, are the strong edges. From them ``points`` are
    chosen by farthest-point sampling from a first one drawn with ``seed``, so they spread
    over the outline and the veins. Fewer come back when there are fewer edge pixels.

    Parameters
    ----------
    image : (H, W[, C]) array_like
        The leaf; with 2 or 4 channels the last is alpha and only the leaf is searched.
    points : int, optional
        How many keypoints (>= 3).
    seed : int or numpy.random.Generator, optional
        Seed of the first point and of the subsampling of very large edge sets.

    Returns
    -------
    points : (N, 2) ndarray of float64
    """
    img = as_image(image, "image")
    n = check_int(points, "points", 3)
    rng = np.random.default_rng(check_seed(seed))
    grey, mask = _split(img)
    if not mask.any():
        raise ValueError("image: the alpha channel is empty; expected a leaf")
    g = cv2.bilateralFilter(np.clip(grey * 255.0, 0, 255).astype(np.float32), 9, 50.0, 5.0)
    mag = np.hypot(cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3))
    region = cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=2) > 0
    mag[~region] = 0
    if mag.max() < _EDGE_FLOOR:
        raise ValueError("image: found no edges (a blank or uniform leaf); expected a leaf with an outline or veins")
    thr = max(_EDGE_FLOOR, float(np.quantile(mag[region], 0.9)))
    ys, xs = np.nonzero(mag >= thr)
    cand = np.stack([xs, ys], axis=1).astype(np.float64)
    if len(cand) > 20000:
        cand = cand[np.sort(rng.choice(len(cand), 20000, replace=False))]
    if len(cand) < 3:
        raise ValueError(f"image: found only {len(cand)} edge pixels; expected a leaf with an outline or veins")
    chosen = [int(rng.integers(len(cand)))]
    dist = np.sum((cand - cand[chosen[0]]) ** 2, axis=1)
    for _ in range(min(n, len(cand)) - 1):
        k = int(np.argmax(dist))
        chosen.append(k)
        dist = np.minimum(dist, np.sum((cand - cand[k]) ** 2, axis=1))
    return cand[chosen]


@dataclass(frozen=True)
class Registration:
    """A registration of a moving (exemplar) leaf to a fixed (training) leaf.

    Attributes
    ----------
    forward : (H_f, W_f, 2) ndarray of float32
        For every pixel ``(row, col)`` of the fixed frame, the displacement ``(dx, dy)`` to
        the moving-frame position ``(col + dx, row + dy)`` it corresponds to. Sampling the
        exemplar by it aligns the exemplar to the training leaf: the paper's ``W_i``.
    inverse : (H_m, W_m, 2) ndarray of float32
        For every pixel of the moving frame, the displacement to its fixed-frame position.
        Sampling a training-frame image by it puts it in the exemplar's shape: the paper's
        ``W_i⁻¹`` of Eq. 7, the fields that synthesis blends.
    fixed_points, moving_points : (N, 2), (M, 2) ndarray of float64
        The keypoints ``(x, y)`` of both leaves.
    matches : (N,) ndarray of int64
        For each fixed keypoint the index of its moving keypoint, -1 for an outlier.
    residual : float
        Mean distance in px between the warped matched fixed keypoints and their partners.
    refits : int
        How many times the bending penalty was multiplied by 10 to remove a fold.
    min_jacobian : float
        The smallest Jacobian determinant of the forward map over the fixed leaf and the
        preimage of the moving leaf (> 0: fold-free).
    """

    forward: NDArray[np.float32]
    inverse: NDArray[np.float32]
    fixed_points: NDArray[np.float64]
    moving_points: NDArray[np.float64]
    matches: NDArray[np.int64]
    residual: float
    refits: int
    min_jacobian: float

    def warp(self, image: Any, *, threads: int | None = None) -> NDArray[np.float32]:
        """A moving-frame image (e.g. the exemplar) resampled into the fixed frame (bilinear;
        positions outside the image give 0, transparent for RGBA).

        The sampler is the one of :mod:`phloem.warp` (Rust core, parallel)."""
        return _sample(image, self.forward, self.inverse.shape[:2], threads)

    def warp_back(self, image: Any, *, threads: int | None = None) -> NDArray[np.float32]:
        """A fixed-frame image resampled into the moving frame (the exemplar's shape)."""
        return _sample(image, self.inverse, self.forward.shape[:2], threads)


def _sample(image: Any, field: NDArray[np.float32], shape: tuple[int, ...], threads: int | None) -> NDArray[np.float32]:
    img = as_image(image, "image")
    if img.shape[:2] != shape:
        raise ValueError(f"image: expected an image of size {tuple(shape)}, got {img.shape[:2]}")
    return restore_ndim(sample_checked(img, np.ascontiguousarray(field), check_threads(threads)), image)


def register(
    moving: Any,
    fixed: Any,
    *,
    points: int = 100,
    seed: int | np.random.Generator = 0,
    threads: int | None = None,
) -> Registration:
    """Register the leaf ``moving`` (an exemplar) to ``fixed`` (the training leaf).

    Keypoints of both (:func:`keypoints`) are matched by TPS-RPM: softassign with an outlier
    row and column (entry ``exp(−2)/√T``), Sinkhorn balancing, deterministic annealing from
    the largest squared keypoint distance down by 0.93 per step over a ratio of 10⁴, 5
    updates per temperature, a thin-plate spline fitted to Chui's targets weighted by each
    point's inlier mass, with bending penalty ``n·T`` and affine penalty ``0.1·n·T``
    (normalised units), refitted at the end on the mutual best matches. The spline is
    evaluated on the fixed pixel grid (forward field); the inverse is fitted on the warped
    keypoints and refined by Newton steps on every moving pixel, so ``forward ∘ inverse`` is
    the identity to far below a pixel. If the forward map folds anywhere in either leaf
    (Jacobian determinant <= 0), the bending penalty is raised tenfold and the spline refitted.
    The docs compare every value with Chui & Rangarajan's paper and code.

    Parameters
    ----------
    moving, fixed : (H, W[, C]) array_like
        The two leaves, RGB(A) or grey, of any sizes but the same channel count; with alpha
        (2 or 4 channels) only the leaf is searched for keypoints and checked for folds.
    points : int, optional
        Keypoints per leaf (>= 3); the paper uses about 100.
    seed : int or numpy.random.Generator, optional
        Seed of the keypoint choice; the result is the same for any thread count.
    threads : int, optional
        Worker threads (default: ``PHLOEM_NUM_THREADS`` or all cores).

    Returns
    -------
    Registration

    References
    ----------
    .. [1] H. Chui, A. Rangarajan, "A new point matching algorithm for non-rigid
       registration", CVIU 89(2–3), 2003.
    .. [2] S. Assa, D. Cohen-Or, "More of the same: synthesizing a variety by structural
       layering", §3.
    """
    mv = as_image(moving, "moving")
    fx = as_image(fixed, "fixed")
    if mv.shape[2] != fx.shape[2]:
        raise ValueError(f"moving: expected {fx.shape[2]} channels like fixed, got {mv.shape[2]}")
    n = check_int(points, "points", 3)
    s = check_seed(seed)
    th = check_threads(threads)
    try:
        kf = keypoints(fx, points=n, seed=s)
    except ValueError as e:
        raise ValueError(str(e).replace("image:", "fixed:", 1)) from None
    try:
        km = keypoints(mv, points=n, seed=derive_seed(s, 1))
    except ValueError as e:
        raise ValueError(str(e).replace("image:", "moving:", 1)) from None
    fmask = np.ascontiguousarray(_split(fx)[1])
    mmask = np.ascontiguousarray(_split(mv)[1])
    fwd, inv, matches, at, refits, det = _core.tps_register(
        kf,
        km,
        fmask,
        mmask,
        rate=_RATE,
        iterations=_ITERATIONS,
        final_ratio=_FINAL_RATIO,
        lambda1=_LAMBDA1,
        lambda2=_LAMBDA2,
        step=_STEP,
        threads=th,
    )
    ok = matches >= 0
    residual = float(np.linalg.norm(at[ok] - km[matches[ok]], axis=1).mean()) if ok.any() else float("nan")
    return Registration(fwd, inv, kf, km, matches, residual, int(refits), float(det))
