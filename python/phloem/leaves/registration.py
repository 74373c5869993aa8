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
from .._boxes import bounding_box
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


def _mask(img: NDArray[np.float32]) -> NDArray[np.bool_]:
    """The leaf: alpha above one half (everything without alpha)."""
    if img.shape[2] in (2, 4):
        return np.ascontiguousarray(img[..., -1] > 0.5)
    return np.ones(img.shape[:2], bool)


def _grey(img: NDArray[np.float32]) -> NDArray[np.float32]:
    """Grey image, composited over black when there is alpha."""
    if img.shape[2] in (2, 4):
        alpha = np.clip(img[..., -1], 0, 1)
        g: NDArray[np.float32] = (img[..., :-1].mean(axis=2) * alpha).astype(np.float32)
    else:
        g = img.mean(axis=2).astype(np.float32)
    return g


def _box(img: NDArray[np.float32], region: NDArray[np.bool_]) -> tuple[slice, slice]:
    """The part of the image the edge filters need: all of it, or with alpha the box around
    ``region`` with a 6 px margin (the bilateral filter reaches 4 px, Sobel 1 more) when
    everything outside that box is transparent (its grey is 0, and the box holds a 0 too, so
    the image's range, on which the bilateral filter's colour table depends, is the same)."""
    h, w = region.shape
    if img.shape[2] not in (2, 4):
        return slice(0, h), slice(0, w)
    ys, xs = bounding_box(region, 6)
    y0, y1, x0, x1 = ys.start, ys.stop, xs.start, xs.stop
    a = img[..., -1]
    inside = y1 - y0 < h or x1 - x0 < w
    clear = not (a[:y0].any() or a[y1:].any() or a[y0:y1, :x0].any() or a[y0:y1, x1:].any())
    return (slice(y0, y1), slice(x0, x1)) if inside and clear else (slice(0, h), slice(0, w))


def _edges(img: NDArray[np.float32], region: NDArray[np.bool_]) -> tuple[NDArray[np.float32], tuple[slice, slice]]:
    """Sobel magnitude of the bilateral-filtered grey image over :func:`_box`, 0 outside
    ``region``, and the box."""
    box = _box(img, region)
    g8 = np.clip(_grey(img[box]) * 255.0, 0, 255).astype(np.float32)
    if g8.shape != region.shape and g8.min() > 0:
        box = (slice(0, region.shape[0]), slice(0, region.shape[1]))
        g8 = np.clip(_grey(img) * 255.0, 0, 255).astype(np.float32)
    g = cv2.bilateralFilter(g8, 9, 50.0, 5.0)
    mag: NDArray[np.float32] = np.hypot(
        cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3)
    )
    mag[~region[box]] = 0
    return mag, box


def _keypoints(img: NDArray[np.float32], n: int, rng: np.random.Generator) -> NDArray[np.float64]:
    mask = _mask(img)
    if not mask.any():
        raise ValueError("image: the alpha channel is empty; expected a leaf")
    region = cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=2) > 0
    mag, box = _edges(img, region)
    inside = region[box]
    if mag.max() < _EDGE_FLOOR:
        raise ValueError("image: found no edges (a blank or uniform leaf); expected a leaf with an outline or veins")
    thr = max(_EDGE_FLOOR, float(np.quantile(mag[inside], 0.9)))
    ys, xs = np.nonzero(mag >= thr)
    cand = np.stack([xs + box[1].start, ys + box[0].start], axis=1).astype(np.float64)
    if len(cand) > 20000:
        cand = cand[np.sort(rng.choice(len(cand), 20000, replace=False))]
    if len(cand) < 3:
        raise ValueError(f"image: found only {len(cand)} edge pixels; expected a leaf with an outline or veins")
    # Farthest-point sampling; the squared distances of whole pixels are exact in float64,
    # so any order of the arithmetic gives the same choice.
    cx, cy = np.ascontiguousarray(cand[:, 0]), np.ascontiguousarray(cand[:, 1])
    chosen = [int(rng.integers(len(cand)))]
    dist = (cx - cx[chosen[0]]) ** 2 + (cy - cy[chosen[0]]) ** 2
    dx, dy = np.empty_like(cx), np.empty_like(cy)
    for _ in range(min(n, len(cand)) - 1):
        k = int(np.argmax(dist))
        chosen.append(k)
        np.subtract(cx, cx[k], out=dx)
        np.subtract(cy, cy[k], out=dy)
        np.multiply(dx, dx, out=dx)
        np.multiply(dy, dy, out=dy)
        np.add(dx, dy, out=dx)
        np.minimum(dist, dx, out=dist)
    return cand[chosen]


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
    return _keypoints(img, n, np.random.default_rng(check_seed(seed)))


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
        kf = _keypoints(fx, n, np.random.default_rng(s))
    except ValueError as e:
        raise ValueError(str(e).replace("image:", "fixed:", 1)) from None
    try:
        km = _keypoints(mv, n, np.random.default_rng(derive_seed(s, 1)))
    except ValueError as e:
        raise ValueError(str(e).replace("image:", "moving:", 1)) from None
    fmask, mmask = _mask(fx), _mask(mv)
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
