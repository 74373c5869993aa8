"""Fragment-based image synthesis along a branching structure (Sibbing, Pick, Kobbelt 2010, §5).

Given an input image with its (source) skeleton and a new (target) skeleton, :func:`render`
paints the target structure with disk-shaped fragments of the input:

1. :func:`fragments` covers every source branch with disks of radius ``3 × thickness`` whose
   centres are ``λ (s_i + s_(i+1))`` apart (``λ = 0.75``), plus one disk at every furcation
   (§5.1). Each fragment carries its *shape*: the skeleton segment through its centre resampled
   to ``k`` samples (positions and thicknesses); a furcation fragment has the parent segment and
   the child segment, ``2k`` samples.
2. The target skeleton is covered the same way. Branch by branch (parents first) each target
   fragment takes the source fragment minimising ``S + ω_C C`` (§5.2): ``S`` is the shape
   distance after the closed-form rigid alignment (:func:`rigid_align`), ``C`` the colour
   difference with what is already painted in the overlap; one of the ``c`` best is drawn
   with probability inversely proportional to its objective.
3. The chosen fragment is deformed by the smooth displacement field that carries its skeleton
   samples onto the target's (the energy of :func:`phloem.blend.interpolate_field`, solved
   directly on a grid of ~8 cells per radius and upsampled; scaled down where it would fold
   the fragment), cut against the painted pixels along a minimum-cost seam
   (:func:`phloem.seams.seam`) and pasted in the gradient domain with its colours held fixed
   where it borders unpainted pixels (:func:`phloem.blend.seamless` with ``fixed``, §5.3).
   Before a sub-branch starts, the disk of its furcation fragment is deleted from the output
   and repainted by a furcation fragment (Fig. 6).
4. The gaps between the branches are completed automatically (§5.4) by patch-based
   completion (Wexler et al.) whose patches may come only from the input image's background:
   the source structure, dilated to the fragment radius, is excluded, so no pseudo-branches
   of the traced structure appear.

Beyond the paper (each needed for clean junctions, see the tests):

- a sub-branch crosses the banks its parent's fragments painted; there the seam must give
  the sub-branch's own structure pixels to the new fragment, and the Poisson paste keeps
  their colours (a colour seam cut the sub-branch off, the Poisson boundary faded it out);
- source branch fragments that hold part of another branch (a sub-branch's start) are left
  to the furcation fragments: pasted along a plain target branch they left stubs;
- furcation fragments are also offered mirrored (``mirror=True``), since with rotations only
  a target sub-branch on the other side of its parent may have no match;
- the completed gaps are pasted in the gradient domain against the structure
  (``match_borders``), as §5.3 does for the fragments: the background patches the completion
  copies need not match the brightness the fragments bring along, and each disk showed.

Perspective (Fig. 8): :func:`rectify` warps a photo taken at an angle, with its skeleton, by
a user-given homography to a frontal view; synthesise there, then :func:`unrectify` distorts
the result back. Finding the homography is left to the user (four point pairs and
``cv2.getPerspectiveTransform``).
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, field
from typing import Any, Literal, overload

import cv2
import numpy as np
from numpy.typing import NDArray

from .. import _core
from .._progress import Progress
from .._validate import as_image, as_mask, check_float, check_int, check_patch_size, check_seed, check_threads
from ..blend import interpolate_field, seamless
from ..seams import seam
from ..texture import WEXLER_GAMMA, WEXLER_SIGMA_PERCENTILE, _downsample, _fill_inward, _patch_masks, _upsample_field
from .skeleton import Branch, Skeleton

__all__ = ["Fragment", "RenderResult", "fragments", "rectify", "render", "rigid_align", "unrectify"]

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]

#: Samples per skeleton segment of a fragment's shape vector (the paper's k; it gives no value).
DEFAULT_SAMPLES = 9
#: Smallest fragment radius in pixels (a skeleton of zero thickness still needs a disk).
MIN_RADIUS = 2.0


@dataclass
class Fragment:
    """A disk-shaped fragment on a skeleton (§5.1).

    Attributes
    ----------
    center : ndarray of float64, shape (2,)
        ``(x, y)`` of the disk centre, on the skeleton.
    radius : float
        Disk radius in pixels (``radius_factor ×`` the interpolated thickness at the centre).
    points : ndarray of float64, shape (m, 2)
        The shape: skeleton samples relative to ``center``. ``m = k`` for a branch fragment
        (the segment from arc length ``a − radius`` to ``a + radius``, clamped to the branch);
        ``m = 2k`` for a furcation fragment (that parent segment, then the child's first
        ``radius`` of arc).
    thickness : ndarray of float64, shape (m,)
        Skeleton thickness at each sample.
    branch : int
        Index of the branch the centre lies on (the child branch for a furcation fragment).
    arc : float
        Arc length of the centre along that branch.
    furcation : bool
        Whether this is a furcation fragment.
    """

    center: F64
    radius: float
    points: F64
    thickness: F64
    branch: int
    arc: float
    furcation: bool = False


@dataclass
class RenderResult:
    """Everything :func:`render` computed.

    Attributes
    ----------
    image : ndarray of float32, shape (H, W, C)
        The synthesised image.
    labels : ndarray of int32, shape (H, W)
        Index into ``targets`` of the fragment each pixel came from; ``-1`` for pixels filled
        by the gap completion.
    sources, targets : list of Fragment
        The source fragments and the target fragments, in synthesis order.
    choice : ndarray of int64
        ``sources`` index chosen for each target fragment.
    mirrored : ndarray of bool
        Whether that source fragment was used mirrored (furcations only, see ``mirror``).
    structure : ndarray of float32, shape (H, W, C)
        The image before gap completion (unpainted pixels are 0).
    """

    image: F32
    labels: NDArray[np.int32]
    sources: list[Fragment]
    targets: list[Fragment]
    choice: NDArray[np.int64]
    mirrored: NDArray[np.bool_]
    structure: F32 = field(repr=False)


# -- geometry -------------------------------------------------------------------------------


def rigid_align(
    source_points: Any,
    target_points: Any,
    *,
    source_center: Any = None,
    target_center: Any = None,
) -> tuple[F64, F64]:
    """Closed-form rigid transform (rotation and translation, no scaling) of 2D point sets.

    Finds ``R`` (a rotation) and ``t`` minimising ``Σ_l ‖R p_l + t − q_l‖²``. With the centres
    given, ``R p + t`` maps ``source_center`` onto ``target_center`` and only the rotation is
    optimised: one step of 2D ICP with known correspondences, as in §5.2. Without them the
    centroids are used (2D Kabsch/Procrustes). The optimal angle is
    ``atan2(Σ p × q, Σ p · q)`` over the centred points.

    Parameters
    ----------
    source_points, target_points : (k, 2) array_like
        Corresponding points ``p_l`` and ``q_l``.
    source_center, target_center : (2,) array_like, optional
        Centres to align (both or neither).

    Returns
    -------
    R : (2, 2) ndarray
        Rotation matrix.
    t : (2,) ndarray
        Translation; ``q ≈ p @ R.T + t``.

    Examples
    --------
    >>> import numpy as np
    >>> p = np.array([[0.0, 0], [1, 0], [2, 1]])
    >>> a = 0.3
    >>> R0 = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    >>> R, t = rigid_align(p, p @ R0.T + [5, -2])
    >>> bool(np.allclose(R, R0)), t.round(6).tolist()
    (True, [5.0, -2.0])
    """
    p = _points2(source_points, "source_points")
    q = _points2(target_points, "target_points")
    if p.shape != q.shape:
        raise ValueError(f"target_points: expected shape {p.shape} like source_points, got {q.shape}")
    if (source_center is None) != (target_center is None):
        raise ValueError("source_center: give both source_center and target_center, or neither")
    if source_center is None:
        cp, cq = p.mean(axis=0), q.mean(axis=0)
    else:
        cp = _points2(np.reshape(np.asarray(source_center, dtype=np.float64), (1, 2)), "source_center")[0]
        cq = _points2(np.reshape(np.asarray(target_center, dtype=np.float64), (1, 2)), "target_center")[0]
    theta = _best_angles((p - cp)[None], q - cq)[0]
    c, s = math.cos(theta), math.sin(theta)
    R = np.array([[c, -s], [s, c]])
    return R, cq - R @ cp


def _points2(points: Any, name: str) -> F64:
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name}: expected an array of (x, y) points") from None
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] == 0:
        raise ValueError(f"{name}: expected shape (k, 2) with k >= 1, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name}: points contain NaN or infinity")
    return arr


def _best_angles(P: F64, Q: F64) -> F64:
    """Optimal rotation angle for each of ``n`` centred point sets ``P (n, m, 2)`` onto ``Q (m, 2)``."""
    dot = np.einsum("nmd,md->n", P, Q)
    cross = (P[..., 0] * Q[None, :, 1] - P[..., 1] * Q[None, :, 0]).sum(axis=1)
    return np.asarray(np.arctan2(cross, dot), dtype=np.float64)


def _dense(branch: Branch, step: float = 0.5) -> tuple[F64, F64, F64]:
    """The branch sampled every ``step`` pixels of arc: arc lengths, points, thicknesses."""
    seg = np.linalg.norm(np.diff(branch.points, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    total = float(cum[-1])
    s = np.linspace(0.0, total, max(2, math.ceil(total / step) + 1))
    pts = np.stack([np.interp(s, cum, branch.points[:, 0]), np.interp(s, cum, branch.points[:, 1])], axis=1)
    return s, pts, np.interp(s, cum, branch.thickness)


def _at(branch: Branch, cum: F64, arcs: F64) -> tuple[F64, F64]:
    a = np.clip(arcs, 0.0, cum[-1])
    pts = np.stack([np.interp(a, cum, branch.points[:, 0]), np.interp(a, cum, branch.points[:, 1])], axis=1)
    return pts, np.interp(a, cum, branch.thickness)


def _cum(branch: Branch) -> F64:
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(branch.points, axis=0), axis=1))])


def _radius_cap(skeleton: Skeleton, rf: float) -> float:
    """Largest fragment radius: ``rf`` times twice the 90th percentile of the thickness.

    A traced mask can hold a few blob-like parts (a lake, the sea) whose "thickness" is ten
    times a channel's; uncapped, their fragments would be disks hundreds of pixels wide.
    """
    th = np.concatenate([b.thickness for b in skeleton.branches])
    return max(rf * 2.0 * float(np.quantile(th, 0.9)), MIN_RADIUS)


def _centres(branch: Branch, lam: float, rf: float, rmax: float = np.inf) -> list[float]:
    """Arc lengths of the fragment centres: consecutive Euclidean distance ``λ (s_i + s_(i+1))``."""
    s, pts, th = _dense(branch)
    rad = np.clip(rf * th, MIN_RADIUS, max(rmax, MIN_RADIUS))
    out = [0]
    i = 0
    n = len(s)
    while True:
        d = np.linalg.norm(pts[i + 1 :] - pts[i], axis=1)
        ok = np.nonzero(d >= lam * (rad[i] + rad[i + 1 :]))[0]
        if len(ok) == 0:
            # The end is not yet a full step away: add it if the last disk does not cover it.
            if np.linalg.norm(pts[-1] - pts[i]) > 0.5 * rad[i] and i != n - 1:
                out.append(n - 1)
            break
        i = i + 1 + int(ok[0])
        out.append(i)
    return [float(s[j]) for j in out]


def _segment(branch: Branch, cum: F64, arc: float, radius: float, k: int, *, child: bool = False) -> tuple[F64, F64]:
    t = np.linspace(0.0, 1.0, k) if child else np.linspace(-1.0, 1.0, k)
    return _at(branch, cum, arc + radius * t)


def _check_params(lam: Any, radius_factor: Any, samples: Any) -> tuple[float, float, int]:
    lam_f = check_float(lam, "lam", 0.0, inclusive=False)
    if lam_f > 1.0:
        raise ValueError(f"lam: expected a value in (0, 1] so that neighbouring fragments overlap, got {lam}")
    return lam_f, check_float(radius_factor, "radius_factor", 0.0, inclusive=False), check_int(samples, "samples", 2)


def _check_skeleton(skeleton: Any, name: str, shape: tuple[int, int] | None) -> Skeleton:
    if not isinstance(skeleton, Skeleton):
        raise TypeError(f"{name}: expected a phloem.branching.Skeleton, got {type(skeleton).__name__}")
    if not skeleton.branches:
        raise ValueError(f"{name}: the skeleton has no branches")
    for i, b in enumerate(skeleton.branches):
        if not (np.isfinite(b.points).all() and np.isfinite(b.thickness).all()):
            raise ValueError(f"{name}: branches[{i}] has NaN or infinite points or thickness")
    if shape is not None:
        skeleton.check_inside(shape, name)
    return skeleton


def _fragments(
    skeleton: Skeleton, lam: float, rf: float, k: int, *, order: bool, furcations: bool = True
) -> list[Fragment]:
    """Fragments of every branch; with ``order``, in synthesis order (a furcation fragment
    replaces the first fragment of its child branch and follows the parent's fragments).
    Without ``furcations`` no furcation fragments are made."""
    out: list[Fragment] = []
    cums = [_cum(b) for b in skeleton.branches]
    rmax = _radius_cap(skeleton, rf)
    for bi, b in enumerate(skeleton.branches):
        cum = cums[bi]
        arcs = _centres(b, lam, rf, rmax)
        fur: Fragment | None = None
        if b.parent is not None and furcations:
            pb, pv = b.parent
            parent = skeleton.branches[pb]
            pc = cums[pb]
            centre = parent.points[pv]
            radius = min(max(rf * float(parent.thickness[pv]), MIN_RADIUS), rmax)
            pp, pt = _segment(parent, pc, float(pc[pv]), radius, k)
            cp, ct = _segment(b, cum, 0.0, radius, k, child=True)
            fur = Fragment(centre.copy(), radius, np.vstack([pp, cp]) - centre, np.concatenate([pt, ct]), bi, 0.0, True)
        frs = []
        for a in arcs:
            c, t = _at(b, cum, np.array([a]))
            radius = min(max(rf * float(t[0]), MIN_RADIUS), rmax)
            pts, th = _segment(b, cum, a, radius, k)
            frs.append(Fragment(c[0], radius, pts - c[0], th, bi, a))
        if fur is not None:
            if order:
                frs = [fur] + frs[1:]
            else:
                frs.append(fur)
        out.extend(frs)
    return out


def fragments(
    image: Any,
    skeleton: Skeleton,
    *,
    lam: float = 0.75,
    radius_factor: float = 3.0,
    samples: int = DEFAULT_SAMPLES,
) -> list[Fragment]:
    """Cover a skeleton with disk-shaped fragments (§5.1).

    Along each branch the first centre is the branch's start; each next one is the first point
    of the branch at Euclidean distance ``lam (s_i + s_(i+1))`` from the previous centre,
    where ``s = radius_factor ×`` the linearly interpolated thickness (at least 2 px). The end
    of a branch gets a last fragment when the previous disk does not reach it. Each furcation
    (a child's attachment vertex) gets an extra furcation fragment.

    Parameters
    ----------
    image : (H, W[, C]) array_like or None
        The image the skeleton belongs to (used to check that the skeleton lies inside it;
        ``None`` to skip the check). Fragments hold geometry only; :func:`render` reads the
        pixels.
    skeleton : Skeleton
        The structure.
    lam : float, optional
        Spacing factor λ (default 0.75, the paper's value), in (0, 1].
    radius_factor : float, optional
        Fragment radius over branch thickness (default 3), at most 3 times twice the
        skeleton's 90th-percentile thickness (so blob-like parts such as a lake do not make
        giant fragments).
    samples : int, optional
        Samples ``k`` per skeleton segment of the shape vector (default 9).

    Returns
    -------
    list of Fragment
        Branch fragments branch by branch, then each branch's furcation fragment after them.

    Examples
    --------
    >>> import numpy as np
    >>> from phloem.branching import Branch, Skeleton, fragments
    >>> sk = Skeleton([Branch([[10, 50], [190, 50]], 4.0), Branch([[100, 50], [100, 90]], 2.0, parent=(0, 0))])
    >>> frs = fragments(None, sk)
    >>> [round(f.radius) for f in frs if f.branch == 0][:3], sum(f.furcation for f in frs)
    ([12, 12, 12], 1)
    >>> round(float(np.linalg.norm(frs[1].center - frs[0].center)), 1)   # 0.75 * (12 + 12)
    18.0
    """
    lam_f, rf, k = _check_params(lam, radius_factor, samples)
    shape = None if image is None else as_image(image, "image").shape[:2]
    sk = _check_skeleton(skeleton, "skeleton", shape)
    return _fragments(sk, lam_f, rf, k, order=False)


# -- synthesis ------------------------------------------------------------------------------


def _disk(shape: tuple[int, int], c: F64, r: float) -> tuple[slice, slice, NDArray[np.bool_], int, int]:
    """Crop around a disk (clipped to ``shape``) and the disk mask inside it."""
    h, w = shape
    x0, x1 = max(0, math.floor(c[0] - r)), min(w, math.ceil(c[0] + r) + 1)
    y0, y1 = max(0, math.floor(c[1] - r)), min(h, math.ceil(c[1] + r) + 1)
    yy, xx = np.mgrid[y0:y1, x0:x1]
    disk = (xx - c[0]) ** 2 + (yy - c[1]) ** 2 <= r * r
    return slice(y0, y1), slice(x0, x1), disk, y0, x0


def _reaches_out(f: Fragment, ok: NDArray[np.bool_]) -> bool:
    """Whether the disk of source fragment ``f`` holds a pixel outside ``ok``."""
    ys, xs, disk, _, _ = _disk(ok.shape, f.center, f.radius)
    return bool((disk & ~ok[ys, xs]).any())


def _clip_channels(x: F32, lo: F32, hi: F32) -> F32:
    """Clip each channel of ``x`` (H, W, C) to ``[lo[c], hi[c]]`` in place. (One ``np.clip``
    with ``(C,)`` bounds runs its inner loop over the 3 channels: 9× slower.)"""
    for c in range(x.shape[2]):
        np.clip(x[..., c], lo[c], hi[c], out=x[..., c])
    return x


def _paste(dst: F32, src: F32, mask: NDArray[np.bool_]) -> None:
    """``dst[mask] = src[mask]`` for (H, W, C) images, through a mask repeated over the
    channels so the copy runs along whole rows (3-7× faster than either masked indexing or a
    broadcast ``where``)."""
    np.copyto(dst, src, where=np.repeat(mask[..., None], dst.shape[2], axis=2))


def _rot(theta: float) -> F64:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


class _Library:
    """Source fragments stacked for vectorised shape distances.

    Entries are fragments, plus (with ``mirror``) every furcation fragment mirrored: its shape
    reflected in the fragment's local frame, and its pixels read through the same reflection.
    """

    def __init__(self, frs: list[Fragment], *, mirror: bool, exclude: NDArray[np.bool_] | None = None) -> None:
        self.frs = frs
        frag = [i for i in range(len(frs)) if exclude is None or not exclude[i]]
        flip = [False] * len(frag)
        if mirror:
            extra = [i for i, f in enumerate(frs) if f.furcation and (exclude is None or not exclude[i])]
            frag += extra
            flip += [True] * len(extra)
        self.frag = np.array(frag, dtype=np.int64)
        self.flip = np.array(flip, dtype=bool)
        self.points = [frs[i].points * ([1.0, -1.0] if fl else [1.0, 1.0]) for i, fl in zip(frag, flip, strict=True)]
        self.groups: dict[int, NDArray[np.int64]] = {}
        for m in {len(f.points) for f in frs}:
            self.groups[m] = np.array([e for e, i in enumerate(frag) if len(frs[i].points) == m], dtype=np.int64)
        self.P = {m: np.stack([self.points[e] for e in idx]) for m, idx in self.groups.items()}
        self.T = {m: np.stack([frs[frag[e]].thickness for e in idx]) for m, idx in self.groups.items()}

    def to_source(self, e: int, theta: float) -> F64:
        """Linear part of the map from target offsets to source offsets for entry ``e``."""
        Rt: F64 = _rot(theta).T
        return Rt * np.array([[1.0], [-1.0]]) if self.flip[e] else Rt

    def shape_distance(self, g: Fragment, omega_s: float) -> tuple[NDArray[np.int64], F64, F64]:
        """Entries, their S (Eq. 1) and their rotation angles for target fragment ``g``."""
        m = len(g.points)
        P = self.P[m]
        theta = _best_angles(P, g.points)
        return self._score(self.groups[m], P, self.T[m], g.points, g.thickness, theta, omega_s)

    @staticmethod
    def _score(
        idx: NDArray[np.int64], P: F64, T: F64, q: F64, nu: F64, theta: F64, omega_s: float
    ) -> tuple[NDArray[np.int64], F64, F64]:
        c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
        rx = c * P[..., 0] - s * P[..., 1]
        ry = s * P[..., 0] + c * P[..., 1]
        S = ((rx - q[None, :, 0]) ** 2 + (ry - q[None, :, 1]) ** 2 + omega_s * (T - nu[None]) ** 2).sum(axis=1)
        return idx, S, theta


def _sample(img: F32, mapx: F32, mapy: F32) -> F32:
    out = cv2.remap(img, mapx, mapy, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101)
    return np.ascontiguousarray(out.reshape(*mapx.shape, img.shape[2]), dtype=np.float32)


def _displacement(disk_shape: tuple[int, int], y0: int, x0: int, q_abs: F64, d: F64, r: float) -> F32:
    """The smooth displacement field over a crop that takes the values ``d`` at ``q_abs``
    (§5.3, :func:`phloem.blend.interpolate_field`), solved on a grid coarsened to at most ~8
    cells per radius and upsampled bilinearly: the field is smooth by construction, and the
    full-resolution solve costs ~100× more."""
    h, w = disk_shape
    f = max(1, math.ceil(r / 8))
    ch, cw = max(2, -(-h // f)), max(2, -(-w // f))
    rows = np.clip(np.round((q_abs[:, 1] - y0) / f).astype(np.int64), 0, ch - 1)
    cols = np.clip(np.round((q_abs[:, 0] - x0) / f).astype(np.int64), 0, cw - 1)
    key = rows * cw + cols
    uniq, inv = np.unique(key, return_inverse=True)
    vals = np.zeros((len(uniq), 2))
    np.add.at(vals, inv, d)
    vals /= np.bincount(inv, minlength=len(uniq))[:, None]
    pts = np.stack([uniq // cw, uniq % cw], axis=1)
    # The field engine factors grids this small directly (a banded Cholesky, one CG step).
    coarse = interpolate_field(np.ones((ch, cw), bool), pts, vals, threads=1)
    if f == 1:
        return np.ascontiguousarray(coarse[:h, :w])
    # Coarse cell (i, j) sits at fine pixel (i f, j f): map fine pixels back to coarse coordinates.
    ys = (np.arange(h, dtype=np.float32) / f)[:, None] * np.ones((1, w), np.float32)
    xs = np.ones((h, 1), np.float32) * (np.arange(w, dtype=np.float32) / f)[None, :]
    out = cv2.remap(coarse, xs, ys, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return np.ascontiguousarray(out, dtype=np.float32)


def _fold_free(dfield: F32, disk: NDArray[np.bool_], *, min_det: float = 0.5) -> float:
    """Largest of 1, ¾, ½, ¼, 0 by which the field can be scaled so that ``p ↦ p + α d(p)``
    stays injective over the disk (Jacobian determinant at least ``min_det``).

    §5.3 assumes the deviation left after the rigid alignment is small; it is not at a target
    furcation whose angle no source furcation has, and there the full field folds the fragment
    onto its skeleton. The field is linear in the constraints, so scaling it is the field of
    the scaled constraints: the skeleton is then only partly straightened, without folding.
    """
    dux = np.gradient(dfield[..., 0], axis=1)
    duy = np.gradient(dfield[..., 0], axis=0)
    dvx = np.gradient(dfield[..., 1], axis=1)
    dvy = np.gradient(dfield[..., 1], axis=0)
    a1 = (dux + dvy)[disk]
    a2 = (dux * dvy - duy * dvx)[disk]
    for alpha in (1.0, 0.75, 0.5, 0.25):
        if a1.size == 0 or float((1.0 + alpha * a1 + alpha * alpha * a2).min()) >= min_det:
            return alpha
    return 0.0


def _complete_background(
    canvas: F32,
    hole: NDArray[np.bool_],
    source: F32,
    allowed: NDArray[np.bool_],
    *,
    patch_size: int,
    iterations: int,
    seed: int,
    threads: int | None,
) -> F32:
    """Wexler-style completion of ``hole`` in ``canvas`` whose patches come only from the
    ``allowed`` pixels of ``source`` (the input's background), coarse to fine."""
    p = patch_size
    r = p // 2
    H, W = canvas.shape[:2]
    hs, ws = source.shape[:2]
    gap = p
    # One frame: the canvas above, the source below, a separator between them.
    ww = max(W, ws)
    frame = np.zeros((H + gap + hs, ww, canvas.shape[2]), np.float32)
    frame[:H, :W] = canvas
    frame[H + gap :, :ws] = source
    fhole = np.zeros(frame.shape[:2], bool)
    fhole[:H, :W] = hole
    forbid = np.ones(frame.shape[:2], bool)  # pixels a source patch may not touch
    forbid[H + gap :, :ws] = ~allowed
    bg = source[allowed].mean(axis=0) if allowed.any() else source.reshape(-1, source.shape[2]).mean(axis=0)
    frame[:H, :W][hole] = bg
    outside = np.ones(frame.shape[:2], bool)
    outside[:H, :W] = False
    outside[H + gap :, :ws] = False
    frame[outside] = bg

    levels = 1
    ys, xs = np.nonzero(hole)
    extent = max(int(np.ptp(ys)) + 1, int(np.ptp(xs)) + 1)
    # Gaps are a few fragment radii wide: enough levels that they are a few patches wide.
    levels = max(1, min(5, int(math.log2(max(extent / (4 * p), 1.0))) + 1))
    pyr: list[tuple[F32, NDArray[np.bool_], NDArray[np.bool_], NDArray[np.bool_]]] = []
    for lv in range(levels):
        h, w = max(1, round(frame.shape[0] / 2**lv)), max(1, round(frame.shape[1] / 2**lv))
        if lv == 0:
            img_l, hole_l, forbid_l = frame, fhole, forbid
        else:
            img_l = _downsample(frame, (h, w))
            hole_l = cv2.resize(fhole.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA) > 0.001
            forbid_l = cv2.resize(forbid.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA) > 0.001
        need, _ = _patch_masks(hole_l, p)
        _, smask = _patch_masks(hole_l | forbid_l, p)
        if min(h, w) < p or not smask.any():
            break
        pyr.append((img_l, hole_l, need, smask))
    if not pyr:
        raise ValueError(
            "source_skeleton: the input image has no background region free of branches to complete the gaps from"
        )
    fieldv: NDArray[np.int32] | None = None
    cur: F32 | None = None
    for lv in range(len(pyr) - 1, -1, -1):
        orig, hole_l, need, smask = pyr[lv]
        depth = cv2.distanceTransform(hole_l.astype(np.uint8), cv2.DIST_L2, 3)
        # Wexler's confidence γ^−d, with d capped: gaps between branches are hundreds of pixels
        # wide and the weights deep inside underflowed float32 (pixels voted 0, black specks).
        # Patches voting on one pixel have depths within a patch width, so the cap only
        # flattens their relative weights where all are deep.
        conf = np.power(WEXLER_GAMMA, -np.minimum(depth, 40.0)).astype(np.float32)
        cur = orig.copy()
        init = None
        if fieldv is not None:
            up = _upsample_field(fieldv, hole_l.shape, orig.shape[:2], r)
            up[~need] = -1
            bad = ~smask[np.maximum(up[..., 0], 0), np.maximum(up[..., 1], 0)] & need
            up[bad] = -1
            voted, wsum = _core.vote(orig, up, patch_size=p, weights=None, threads=threads, mean_shift=0)
            fill = hole_l & (wsum > 1e-30)
            cur[fill] = voted[fill]
            rest = hole_l & ~fill
            if rest.any():
                cur = _fill_inward(cur, rest)
            init = up
        # At full resolution the field found at half resolution, upsampled, already copies
        # full-resolution pixels: a search there took 40% of the time and looked the same on
        # our scenes, so it runs only when there is no coarser level. At half resolution, with
        # coarser levels below, half the iterations (most of the rest of the time; same look).
        if lv == 0 and len(pyr) > 1:
            n_it = 0
        elif lv == 1 and len(pyr) > 2:
            n_it = max(1, iterations // 2)
        else:
            n_it = iterations
        for it in range(n_it):
            # A warm-started search (from the previous iteration's field) needs one pass.
            fieldv, dist, _ = _core.nnf(
                cur, cur, patch_size=p, iterations=3 if it == 0 else 1, levels=1, exact=False,
                seed=seed + 7919 * (lv * 64 + it + 1), weights=None, source_mask=smask, target_mask=need,
                init=init, source_knn=None, source_cost=None, threads=threads, kdtree=False,
            )  # fmt: skip
            dd = dist[need]
            sigma2 = max(float(np.percentile(dd, WEXLER_SIGMA_PERCENTILE)), 1e-8)
            wvote = np.zeros(dist.shape, np.float32)
            wvote[need] = np.exp(-dd / (2.0 * sigma2)) * conf[need]
            voted, wsum = _core.vote(cur, fieldv, patch_size=p, weights=wvote, threads=threads, mean_shift=0)
            fill = hole_l & (wsum > 1e-30)
            cur[fill] = voted[fill]
            init = fieldv
    assert cur is not None
    out: F32 = canvas.copy()
    out[hole] = cur[:H, :W][hole]
    return out


@overload
def render(
    image: Any,
    source_skeleton: Skeleton,
    target_skeleton: Skeleton,
    *,
    seed: int | np.random.Generator = ...,
    c: int = ...,
    omega_s: float = ...,
    omega_c: float = ...,
    lam: float = ...,
    radius_factor: float = ...,
    samples: int = ...,
    deform: bool = ...,
    photometric: bool = ...,
    seams: bool = ...,
    mirror: bool = ...,
    complete: bool = ...,
    match_borders: bool | None = ...,
    valid: Any = ...,
    patch_size: int = ...,
    completion_iterations: int = ...,
    threads: int | None = ...,
    progress: Progress = ...,
    full_output: Literal[False] = ...,
) -> F32: ...
@overload
def render(
    image: Any,
    source_skeleton: Skeleton,
    target_skeleton: Skeleton,
    *,
    seed: int | np.random.Generator = ...,
    c: int = ...,
    omega_s: float = ...,
    omega_c: float = ...,
    lam: float = ...,
    radius_factor: float = ...,
    samples: int = ...,
    deform: bool = ...,
    photometric: bool = ...,
    seams: bool = ...,
    mirror: bool = ...,
    complete: bool = ...,
    match_borders: bool | None = ...,
    valid: Any = ...,
    patch_size: int = ...,
    completion_iterations: int = ...,
    threads: int | None = ...,
    progress: Progress = ...,
    full_output: Literal[True],
) -> RenderResult: ...


def render(
    image: Any,
    source_skeleton: Skeleton,
    target_skeleton: Skeleton,
    *,
    seed: int | np.random.Generator = 0,
    c: int = 2,
    omega_s: float = 2.0,
    omega_c: float = 1.0,
    lam: float = 0.75,
    radius_factor: float = 3.0,
    samples: int = DEFAULT_SAMPLES,
    deform: bool = True,
    photometric: bool = True,
    seams: bool = True,
    mirror: bool = True,
    complete: bool = True,
    match_borders: bool | None = None,
    valid: Any = None,
    patch_size: int = 7,
    completion_iterations: int = 4,
    threads: int | None = None,
    progress: Progress = None,
    full_output: bool = False,
) -> F32 | RenderResult:
    """Synthesise an image of ``target_skeleton`` from fragments of ``image`` (§5).

    See the module docstring for the steps. The colour term is
    ``C = k r² · mean_overlap ‖colour difference‖²`` (colours in [0, 1]): the paper's sum over
    the overlap, rescaled so that it grows with the fragment like ``S`` does and a default
    ``ω_C = 1`` balances the two on images of ordinary contrast. ``C`` is evaluated for the
    ``max(4c, 8)`` fragments of smallest ``S`` only.

    Parameters
    ----------
    image : (H, W[, C]) array_like
        The input image; integer images are scaled to [0, 1].
    source_skeleton : Skeleton
        The structure in ``image`` (every vertex inside it).
    target_skeleton : Skeleton
        The structure to paint; its ``shape`` gives the output size.
    seed : int or numpy.random.Generator, optional
        Seed of the random choice among the ``c`` best and of the completion (default 0).
    c : int, optional
        Number of best candidates to choose from (default 2, as in §4.2; 1 is deterministic).
    omega_s : float, optional
        Weight ω_S of the thickness term of the shape distance (default 2).
    omega_c : float, optional
        Weight ω_C of colour consistency against shape (default 1).
    lam : float, optional
        Fragment spacing factor λ (default 0.75).
    radius_factor : float, optional
        Fragment radius over thickness (default 3; capped as in :func:`fragments`).
    samples : int, optional
        Samples ``k`` per skeleton segment of a fragment's shape (default 9).
    deform : bool, optional
        Deform fragments by the interpolated displacement field (default True).
    photometric : bool, optional
        Gradient-domain pasting with boundary constraints (default True).
    seams : bool, optional
        Graph-cut seams between overlapping fragments (default True).
    mirror : bool, optional
        Also offer every source furcation fragment mirrored (default True). An extension: the
        paper aligns by rotation only, so with few source furcations a target sub-branch on the
        other side of its parent finds no match and is painted with a stub on the wrong side.
        ``False`` is the paper's behaviour.
    complete : bool, optional
        Fill the gaps between the branches (§5.4, default True); without it they stay 0.
    match_borders : bool, optional
        Shift the completed gaps in the gradient domain so that they meet the painted
        structure without a colour step (only the smooth part of the step, made of small
        steps: a branch cut off at a disk's edge is left alone). Without it every fragment
        disk of an unevenly lit photo or a terrain shows as a lighter or darker circle.
        Default (None): on, except for two-level images such as masks, which have no
        lighting to match. Needs ``photometric``.
    valid : (H, W) array_like of bool, optional
        Where ``image`` shows real content (default everywhere), e.g. the photo inside the
        frame of :func:`rectify` or a fundus photo's disc: only fragments that lie wholly
        inside it are pasted, and the gap completion copies only from there.
    patch_size : int, optional
        Patch side of the gap completion (default 7, odd).
    completion_iterations : int, optional
        Search-and-vote iterations per pyramid level of the completion (default 4); the
        full-resolution level copies pixels through the upsampled half-resolution field
        without a search of its own.
    threads : int, optional
        Worker threads (default: all cores). Fragments that do not overlap are painted at
        the same time, one per thread, each waiting only for the earlier fragments whose
        crops meet its own, so the image is the same for any count. (Each fragment's seam and
        Poisson solve runs on one thread: on crops of a few 10⁴ pixels more threads per
        solve only add overhead.) The gap completion uses all of them.
    progress : callable, optional
        Called as ``progress(done, total)`` after each target fragment (and once at the end).
    full_output : bool, optional
        Return a :class:`RenderResult` (with the fragment map) instead of the image.

    Returns
    -------
    image : (H, W, C) ndarray of float32, or RenderResult
        ``H, W`` from ``target_skeleton.shape``; ``C`` as in ``image``.

    References
    ----------
    .. [1] D. Sibbing, D. Pick, L. Kobbelt, "Image Synthesis for Branching Structures",
       Computer Graphics Forum 29(7), 2010, §5.

    Examples
    --------
    >>> import numpy as np
    >>> from phloem.branching import Branch, Skeleton, render
    >>> img = np.full((64, 96), 0.8, np.float32); img[29:35, :] = 0.1     # a dark horizontal river
    >>> src = Skeleton([Branch([[2, 31.5], [93, 31.5]], 3.0)], (64, 96))
    >>> tgt = Skeleton([Branch([[31.5, 2], [31.5, 61]], 3.0)], (64, 64))  # the same, vertical
    >>> out = render(img, src, tgt, seed=0)
    >>> out.shape, bool(out[30, 29:35].mean() < 0.3), bool(out[30, 5].mean() > 0.6)
    ((64, 64, 1), True, True)
    """
    img = as_image(image, "image")
    H0, W0 = img.shape[:2]
    src_sk = _check_skeleton(source_skeleton, "source_skeleton", (H0, W0))
    if not isinstance(target_skeleton, Skeleton):
        raise TypeError(f"target_skeleton: expected a phloem.branching.Skeleton, got {type(target_skeleton).__name__}")
    if target_skeleton.shape is None:
        raise ValueError("target_skeleton: its shape (the output size) must be set")
    out_shape = target_skeleton.shape
    tgt_sk = _check_skeleton(target_skeleton, "target_skeleton", out_shape)
    lam_f, rf, k = _check_params(lam, radius_factor, samples)
    c_n = check_int(c, "c", 1)
    w_s = check_float(omega_s, "omega_s", 0.0)
    w_c = check_float(omega_c, "omega_c", 0.0)
    p = check_patch_size(patch_size)
    c_iters = check_int(completion_iterations, "completion_iterations", 1)
    s = check_seed(seed)
    t = check_threads(threads)
    rng = np.random.default_rng(s)

    ok = np.ones((H0, W0), bool) if valid is None else as_mask(valid, "valid", (H0, W0))
    sources = _fragments(src_sk, lam_f, rf, k, order=False)
    # Fragments that reach outside the valid region would paste its outside (a fundus
    # photo's black frame) into the output.
    outside = np.array([valid is not None and _reaches_out(f, ok) for f in sources], bool)
    if all(outside[i] for i, f in enumerate(sources) if not f.furcation):
        raise ValueError("valid: every source branch fragment reaches outside it; nothing is left to paint with")
    # Without furcation fragments in the source a target furcation is painted by branch fragments.
    furcations = any(f.furcation and not out for f, out in zip(sources, outside, strict=True))
    targets = _fragments(tgt_sk, lam_f, rf, k, order=True, furcations=furcations)
    lib = _Library(sources, mirror=mirror, exclude=_foreign(src_sk, sources, keep=max(3, c_n)) | outside)
    H, W = out_shape
    C = img.shape[2]
    canvas = np.zeros((H, W, C), np.float32)
    filled = np.zeros((H, W), bool)
    labels = np.full((H, W), -1, np.int32)
    # Which target branch's structure each pixel lies on, and which branch painted it: a
    # sub-branch must cross its parent's already painted banks (Fig. 6), where a colour seam
    # would cut it off and the Poisson boundary would fade it into the bank.
    struct = _branch_map(tgt_sk, (H, W))
    owner = np.full((H, W), -1, np.int32)
    choice = np.zeros(len(targets), np.int64)
    mirrored = np.zeros(len(targets), bool)
    n_eval = max(4 * c_n, 8)
    # Per-channel range (reducing over rows first: an axis-0 reduction of (N, C) is 30× slower).
    lo = img.reshape(H0, -1).min(axis=0).reshape(-1, C).min(axis=0)
    hi = img.reshape(H0, -1).max(axis=0).reshape(-1, C).max(axis=0)
    draws = rng.random(len(targets))
    crops, disks, boxes = [], [], np.zeros((len(targets), 4), np.int64)
    for j, g in enumerate(targets):
        ys, xs, disk, y0, x0 = _disk((H, W), g.center, g.radius)
        crops.append((ys, xs))
        disks.append((disk, y0, x0))
        boxes[j] = ys.start, ys.stop, xs.start, xs.stop

    def paint(j: int) -> None:
        g = targets[j]
        ys, xs = crops[j]
        disk, y0, x0 = disks[j]
        # Colour consistency is measured against what is painted, including the parent's
        # pixels a furcation fragment is about to replace: they are the best colour reference.
        over = disk & filled[ys, xs]
        if g.furcation:
            # Fig. 6: the parent's fragments are deleted where the furcation fragment goes.
            filled[ys, xs] &= ~disk
        fill_c = filled[ys, xs]
        idx, S, theta = lib.shape_distance(g, w_s)
        order = np.argsort(S, kind="stable")[:n_eval]
        obj = S[order].copy()
        if w_c > 0 and over.any():
            oy, ox = np.nonzero(over)
            step = max(1, int(math.sqrt(len(oy) / 400)))
            oy, ox = oy[::step], ox[::step]
            rel = np.stack([ox + x0 - g.center[0], oy + y0 - g.center[1]], axis=1)
            painted = canvas[ys, xs][oy, ox]
            # The overlap as seen through every candidate, sampled in one remap.
            ents = idx[order]
            maps = np.stack([lib.to_source(int(e), float(a)) for e, a in zip(ents, theta[order], strict=True)])
            centres = np.stack([lib.frs[int(lib.frag[e])].center for e in ents])
            # Written out: a stacked matmul calls BLAS (see render's threads), an einsum is 8× slower.
            rx, ry = rel[:, 0], rel[:, 1]
            mx = maps[:, 0, 0, None] * rx + maps[:, 0, 1, None] * ry + centres[:, 0, None]
            my = maps[:, 1, 0, None] * rx + maps[:, 1, 1, None] * ry + centres[:, 1, None]
            vals = _sample(img, mx.astype(np.float32), my.astype(np.float32))
            diff = (vals - painted[None]).reshape(len(order), -1)  # (channel sums over a trailing
            obj += w_c * k * g.radius**2 * np.einsum("ij,ij->i", diff, diff) / len(oy)  # axis of 3: slow)
        best = np.argsort(obj, kind="stable")[:c_n]
        wts = 1.0 / np.maximum(obj[best], 1e-9)
        # Inverse-CDF draw from this fragment's own uniform: the same pick whatever order the
        # fragments are painted in.
        cdf = np.cumsum(wts)
        pick = int(best[min(int(np.searchsorted(cdf, draws[j] * cdf[-1], side="right")), len(best) - 1)])
        cand = int(order[pick])
        e = int(idx[cand])
        si = int(lib.frag[e])
        f = lib.frs[si]
        choice[j] = si
        mirrored[j] = bool(lib.flip[e])
        R = _rot(float(theta[cand]))
        M = lib.to_source(e, float(theta[cand]))  # target offsets → source offsets

        # Target pixel → source position: rigid inverse of (p + d(p)), d the displacement field.
        hh, ww = disk.shape
        gy, gx = np.mgrid[y0 : y0 + hh, x0 : x0 + ww].astype(np.float64)
        px, py = gx - g.center[0], gy - g.center[1]
        if deform:
            d = lib.points[e] @ R.T - g.points
            dfield = _displacement((hh, ww), y0, x0, g.points + g.center, d, g.radius)
            alpha = _fold_free(dfield, disk)
            px = px + alpha * dfield[..., 0]
            py = py + alpha * dfield[..., 1]
        mapx = (M[0, 0] * px + M[0, 1] * py + f.center[0]).astype(np.float32)
        mapy = (M[1, 0] * px + M[1, 1] * py + f.center[1]).astype(np.float32)
        warped = _sample(img, mapx, mapy)

        region = disk & fill_c
        if seams and region.any() and (disk & ~fill_c).any():
            # The cut only needs the overlap and its 1-pixel ring (where the border ties live).
            ry, rx = np.nonzero(region)
            sub = (slice(max(0, ry.min() - 1), ry.max() + 2), slice(max(0, rx.min() - 1), rx.max() + 2))
            cross = region & (struct[ys, xs] == g.branch) & (owner[ys, xs] != g.branch)
            seeds = np.where(cross, 2, 0).astype(np.uint8)[sub] if cross.any() else None
            take = seam(
                canvas[ys, xs][sub], warped[sub], region[sub], a_mask=fill_c[sub], b_mask=disk[sub], seeds=seeds,
                border_weight=None if seeds is None else 1e4, threads=1,
            )  # fmt: skip
            new = disk & ~fill_c
            new[sub] |= region[sub] & take
        else:
            new = disk.copy()
        if not new.any():
            return
        if photometric and (fill_c & ~new).any():
            known = new | (fill_c & ~new)
            pad = np.pad(known, 1, constant_values=True)
            nb_ok = pad[:-2, 1:-1] & pad[2:, 1:-1] & pad[1:-1, :-2] & pad[1:-1, 2:]
            fixed = new & ~nb_ok
            # Where this branch's own structure meets what another branch painted, keep its
            # colours too: that border is structure against bank, not a colour mismatch.
            foreign = np.pad(fill_c & ~new & (owner[ys, xs] != g.branch), 1, constant_values=False)
            touch = foreign[:-2, 1:-1] | foreign[2:, 1:-1] | foreign[1:-1, :-2] | foreign[1:-1, 2:]
            fixed |= new & touch & (struct[ys, xs] == g.branch)
            # Solve on the box of the new pixels and their 1-pixel ring only (the same system).
            ny, nx = np.nonzero(new)
            bx = (slice(max(0, ny.min() - 1), ny.max() + 2), slice(max(0, nx.min() - 1), nx.max() + 2))
            dst = canvas[ys, xs][bx].copy()
            _paste(dst, warped[bx], ~fill_c[bx])
            # tol 1e-3: within 0.0013 of the exact solve (a third of an 8-bit level) on the
            # river bench's fragments, and a quarter faster than 1e-4.
            res = seamless(warped[bx], dst, new[bx], (0, 0), fixed=fixed[bx], tol=1e-3, max_iterations=100, threads=1)
            # The gradient-domain paste can overshoot where a border mismatches strongly; keep
            # the output within the input's range. (Basic slices: views of canvas.)
            res = _clip_channels(res.reshape(*dst.shape), lo, hi)
            _paste(canvas[ys, xs][bx], res, new[bx])
        else:
            _paste(canvas[ys, xs], warped, new)
        filled[ys, xs] |= new
        np.copyto(labels[ys, xs], j, where=new)
        np.copyto(owner[ys, xs], g.branch, where=new)

    _in_order(boxes, paint, workers=t if t is not None else _core.default_threads(), progress=progress)

    structure = canvas.copy() if full_output else canvas
    if complete and (~filled).any():
        # The source minus its structure widened to the fragment radius; where the structure
        # is so dense that less than a sixth of the image would be left (a retina), widened
        # less, down to the structure plus a quarter of its thickness.
        if valid is not None:  # a patch may not straddle the border of the valid region
            ok = cv2.erode(ok.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        for factor in (rf, 2.0, 1.25):
            allowed = _background(src_sk, (H0, W0), factor) & ok
            if allowed.mean() >= 1 / 6:
                break
        canvas = _complete_background(
            canvas, ~filled, img, allowed, patch_size=p, iterations=c_iters, seed=s, threads=t
        )
        if match_borders is None:  # a mask: (nearly) every pixel at its minimum or maximum
            match_borders = float(((img == lo) | (img == hi)).all(axis=2).mean()) < 0.95
        if photometric and match_borders:
            radius = float(np.median([g.radius for g in targets]))
            canvas = _match_borders(canvas, ~filled, lo, hi, radius=radius, threads=t)
    if progress is not None:
        progress(len(targets) + 1, len(targets) + 1)
    if full_output:
        return RenderResult(canvas, labels, sources, targets, choice, mirrored, structure)
    return canvas


def _smooth_masked(vals: F32, w: F32, sigma: float) -> tuple[F32, F32]:
    """Normalised Gaussian convolution ``G * (w v) / G * w`` (0 where no weight is near) and
    ``G * w``, computed at a resolution of about 4 pixels per ``sigma``."""
    h, wd = w.shape
    f = max(1, int(sigma / 4))
    small = (max(1, -(-wd // f)), max(1, -(-h // f)))
    num = cv2.resize(vals * w[..., None], small, interpolation=cv2.INTER_AREA).reshape(small[1], small[0], -1)
    den = cv2.resize(w, small, interpolation=cv2.INTER_AREA)
    num = cv2.GaussianBlur(num, (0, 0), sigma / f).reshape(small[1], small[0], -1)
    den = cv2.GaussianBlur(den, (0, 0), sigma / f)
    m = num / np.maximum(den, 1e-12)[..., None] * (den > 1e-6)[..., None]
    out = cv2.resize(m, (wd, h), interpolation=cv2.INTER_LINEAR).reshape(h, wd, -1)
    dens = cv2.resize(den, (wd, h), interpolation=cv2.INTER_LINEAR)
    return out.astype(np.float32), dens.astype(np.float32)


def _match_borders(
    canvas: F32, hole: NDArray[np.bool_], lo: F32, hi: F32, *, radius: float, threads: int | None
) -> F32:
    """Gradient-domain paste of the completed gaps against the painted structure.

    The completion copies background patches whose brightness need not match the fragments'
    own background where the two meet (an unevenly lit photo, a terrain's large-scale slope),
    and every fragment disk then shows as a lighter or darker circle. As for the fragments
    themselves (§5.3), the gaps keep their gradients and are shifted to meet the structure
    at their border: a Poisson solve over the gaps whose border values are the completion's
    own (carried one pixel into the structure) plus the *smooth* part of the colour step
    there. The step is smoothed over about a fragment radius (a local median), counting
    small steps only (weight ``1 / (1 + (|step| / τ)²)`` with τ a quarter of the image's range): a lighting
    difference is small and smooth, while a large step is content (a branch cut off at a
    disk's edge, a river against dry land in a mask) and must not be smeared across the gap.
    Where large steps make up most of the nearby border (a share of small ones below ¾),
    the correction fades out, to nothing below a quarter.
    """
    known = (~hole).astype(np.float32)
    k4 = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], np.float32)
    cnt = cv2.filter2D(1.0 - known, -1, k4, borderType=cv2.BORDER_CONSTANT)
    ring = ~hole & (cnt > 0)
    if not ring.any():
        return canvas
    src = canvas.copy()
    inner = np.where(hole[..., None], canvas, 0.0).astype(np.float32)
    acc = cv2.filter2D(inner, -1, k4, borderType=cv2.BORDER_CONSTANT).reshape(canvas.shape)
    src[ring] = acc[ring] / cnt[ring][:, None]
    step = np.zeros_like(canvas)
    step[ring] = canvas[ring] - src[ring]
    tau = 0.25 * max(float(np.linalg.norm(hi - lo)), 1e-6)
    w = np.zeros(hole.shape, np.float32)
    w[ring] = 1.0 / (1.0 + (np.linalg.norm(step[ring], axis=1) / tau) ** 2)
    smooth, den = _smooth_masked(step, w, radius)
    _, den_all = _smooth_masked(step, ring.astype(np.float32), radius)
    # A local median rather than a mean (iteratively reweighted, Weiszfeld): a border that is
    # mostly matched with a few small steps (a mask's anti-aliased edges) gets no correction.
    for _ in range(4):
        dev = np.linalg.norm((step - smooth)[ring], axis=1)
        wm = np.zeros_like(w)
        wm[ring] = w[ring] / np.maximum(dev, 0.01 * tau)
        smooth, _ = _smooth_masked(step, wm, radius)
    # Share of small steps along the nearby border: none below a quarter, full above three.
    share = den / np.maximum(den_all, 1e-12)
    smooth *= np.clip((share - 0.25) * 2.0, 0.0, 1.0)[..., None]
    dst = canvas.copy()
    dst[ring] = src[ring] + smooth[ring]
    out = seamless(src, dst, hole, (0, 0), tol=1e-4, threads=threads)
    res: F32 = canvas.copy()
    _paste(res, _clip_channels(out, lo, hi), hole)
    return res


def _in_order(boxes: NDArray[np.int64], work: Callable[[int], None], *, workers: int, progress: Progress) -> None:
    """Run ``work(j)`` for every fragment ``j`` with the result of running them in order.

    ``work(j)`` reads and writes only inside ``boxes[j]`` (``y0, y1, x0, x1``, half-open), so
    it need only wait for the earlier fragments whose boxes meet its own; fragments that do not
    overlap (far apart on one branch, or on different branches) are painted at the same time
    on ``workers`` threads. The seam, Poisson and remap calls release the GIL.
    ``progress(done, n + 1)`` is called after each fragment, from the calling thread.
    """
    n = len(boxes)
    if workers <= 1 or n < 2:
        for j in range(n):
            work(j)
            if progress is not None:
                progress(j + 1, n + 1)
        return
    y0, y1, x0, x1 = boxes.T
    waiting = np.zeros(n, np.int64)
    after: list[list[int]] = [[] for _ in range(n)]
    for j in range(1, n):
        (before,) = np.nonzero((y0[:j] < y1[j]) & (y0[j] < y1[:j]) & (x0[:j] < x1[j]) & (x0[j] < x1[:j]))
        waiting[j] = len(before)
        for i in before.tolist():
            after[i].append(j)
    ready = [j for j in range(n) if waiting[j] == 0]  # ascending: already a heap
    running: dict[Future[None], int] = {}
    done = 0
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="phloem-render") as pool:
        while ready or running:
            # Lowest index first: the chain along a branch is the critical path.
            while ready and len(running) < workers:
                j = heapq.heappop(ready)
                running[pool.submit(work, j)] = j
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for fut in sorted(finished, key=running.__getitem__):
                j = running.pop(fut)
                fut.result()  # re-raises; the executor waits for the other running fragment
                done += 1
                if progress is not None:
                    progress(done, n + 1)
                for k in after[j]:
                    waiting[k] -= 1
                    if waiting[k] == 0:
                        heapq.heappush(ready, k)


def _foreign(skeleton: Skeleton, frs: list[Fragment], *, keep: int) -> NDArray[np.bool_]:
    """Branch fragments whose disk holds part of another branch (the start of a sub-branch,
    or the parent next to a child's first fragment). Pasted along a plain target branch they
    leave a stub of a branch that is not there, so they are left out, unless fewer than
    ``keep`` branch fragments would remain; furcations have their own fragments."""
    dense = [_dense(b, 1.0) for b in skeleton.branches]
    out = np.zeros(len(frs), bool)
    for i, f in enumerate(frs):
        if f.furcation:
            continue
        for bi, (_, pts, th) in enumerate(dense):
            if bi != f.branch and (np.linalg.norm(pts - f.center, axis=1) - th < f.radius).any():
                out[i] = True
                break
    plain = sum(1 for f in frs if not f.furcation)
    if plain - int(out.sum()) < keep:
        out[:] = False
    return out


def _homography(homography: Any) -> F64:
    try:
        Hm = np.asarray(homography, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError("homography: expected a 3x3 matrix") from None
    if Hm.shape != (3, 3) or not np.isfinite(Hm).all():
        raise ValueError(f"homography: expected a finite 3x3 matrix, got shape {Hm.shape}")
    if abs(np.linalg.det(Hm)) < 1e-12:
        raise ValueError("homography: the matrix is singular")
    return Hm


def _apply(Hm: F64, pts: F64) -> F64:
    q = np.c_[pts, np.ones(len(pts))] @ Hm.T
    if (q[:, 2] <= 0).any():
        raise ValueError("homography: maps part of the image behind the camera (w <= 0)")
    return np.asarray(q[:, :2] / q[:, 2:], dtype=np.float64)


def rectify(image: Any, skeleton: Skeleton, homography: Any) -> tuple[F32, Skeleton, F64, NDArray[np.bool_]]:
    """Warp an image and its skeleton to a frontal view (Fig. 8 b) for :func:`render`.

    The output frame is the bounding box of the warped image. Skeleton points are mapped by
    the homography; thicknesses are scaled by the local linear scale ``sqrt |det J|`` of the
    map at each point.

    Parameters
    ----------
    image : (H, W[, C]) array_like
        The photo.
    skeleton : Skeleton
        Its structure, in the photo's pixels.
    homography : (3, 3) array_like
        Maps photo pixels ``(x, y, 1)`` to rectified ones.

    Returns
    -------
    rectified : (H', W', C) ndarray of float32
        The warped photo (0 outside the photo).
    skeleton : Skeleton
        The warped skeleton, with ``shape = (H', W')``.
    homography : (3, 3) ndarray
        The homography actually used (the given one followed by the shift into the frame);
        pass it to :func:`unrectify`.
    valid : (H', W') ndarray of bool
        Where the frame shows the photo; pass it as ``valid`` to :func:`render` so that the
        gap completion does not copy the empty corners.

    Examples
    --------
    >>> import numpy as np
    >>> from phloem.branching import Branch, Skeleton, rectify, unrectify
    >>> yy, xx = np.mgrid[:40, :60]
    >>> img = (0.5 + 0.4 * np.sin(xx / 7.0) * np.cos(yy / 5.0)).astype(np.float32)
    >>> sk = Skeleton([Branch([[5, 20], [55, 20]], 2.0)], (40, 60))
    >>> rect, rsk, Hm, valid = rectify(img, sk, [[2, 0, 0], [0, 2, 0], [0, 0, 1]])   # a 2x zoom
    >>> rect.shape, rsk.branches[0].thickness.tolist()
    ((80, 120, 1), [4.0, 4.0])
    >>> back = unrectify(rect, Hm, (40, 60))
    >>> bool(np.abs(back[2:-2, 2:-2, 0] - img[2:-2, 2:-2]).max() < 0.02)
    True
    """
    img = as_image(image, "image")
    sk = _check_skeleton(skeleton, "skeleton", img.shape[:2])
    Hm = _homography(homography)
    h, w = img.shape[:2]
    corners = _apply(Hm, np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]]))
    # Pixel j of the frame is centred at lo + j and the frame covers the warped image exactly.
    lo = corners.min(axis=0) + 0.5
    size = np.maximum(np.round(corners.max(axis=0) - corners.min(axis=0)), 1).astype(int)
    if size.max() > 32768:
        raise ValueError(f"homography: the rectified image would be {size[0]}x{size[1]} pixels")
    Hs = np.array([[1.0, 0.0, -lo[0]], [0.0, 1.0, -lo[1]], [0.0, 0.0, 1.0]]) @ Hm
    out = cv2.warpPerspective(
        img, Hs, (int(size[0]), int(size[1])), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT
    )
    rect: F32 = np.ascontiguousarray(out.reshape(int(size[1]), int(size[0]), img.shape[2]), dtype=np.float32)
    ones = np.ones(img.shape[:2], np.uint8)
    valid = cv2.warpPerspective(ones, Hs, (int(size[0]), int(size[1])), flags=cv2.INTER_NEAREST) > 0
    branches = []
    for b in sk.branches:
        pts = _apply(Hs, b.points)
        # Local scale: the Jacobian of the projective map at each point, by central differences.
        e = 0.5
        dx = (_apply(Hs, b.points + [e, 0]) - _apply(Hs, b.points - [e, 0])) / (2 * e)
        dy = (_apply(Hs, b.points + [0, e]) - _apply(Hs, b.points - [0, e])) / (2 * e)
        scale = np.sqrt(np.abs(dx[:, 0] * dy[:, 1] - dx[:, 1] * dy[:, 0]))
        pts = np.clip(pts, -0.5, [size[0] - 0.5, size[1] - 0.5])
        branches.append(Branch(pts, b.thickness * scale, b.parent))
    return rect, Skeleton(branches, (int(size[1]), int(size[0]))), Hs, np.asarray(valid)


def unrectify(image: Any, homography: Any, shape: tuple[int, int]) -> F32:
    """Distort a result synthesised in the rectified frame back to the photo's view (Fig. 8 e).

    Parameters
    ----------
    image : (H', W'[, C]) array_like
        An image in the rectified frame (e.g. the output of :func:`render`).
    homography : (3, 3) array_like
        The homography returned by :func:`rectify`.
    shape : (int, int)
        ``(H, W)`` of the output, in the photo's view.

    Returns
    -------
    (H, W, C) ndarray of float32
    """
    img = as_image(image, "image")
    Hm = _homography(homography)
    h, w = (check_int(shape[0], "shape[0]", 1), check_int(shape[1], "shape[1]", 1))
    out = cv2.warpPerspective(
        img, Hm, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_CONSTANT
    )
    return np.ascontiguousarray(out.reshape(h, w, img.shape[2]), dtype=np.float32)


def _background(skeleton: Skeleton, shape: tuple[int, int], factor: float) -> NDArray[np.bool_]:
    """Pixels farther from the structure than ``factor ×`` its thickness (at least 2 px)."""
    zone = np.zeros(shape, np.uint8)
    for b in skeleton.branches:
        for (a, bb), (r0, r1) in zip(zip(b.points[:-1], b.points[1:]), zip(b.thickness[:-1], b.thickness[1:])):
            rr = max(factor * 0.5 * (r0 + r1), MIN_RADIUS)
            cv2.line(zone, _pt(a), _pt(bb), 1, thickness=max(1, round(2 * rr)), lineType=cv2.LINE_8, shift=4)
    return np.asarray(zone == 0)


def _branch_map(skeleton: Skeleton, shape: tuple[int, int]) -> NDArray[np.int32]:
    """Index of the branch whose structure (thickness plus 2 px) covers each pixel, else -1;
    children are drawn over their parents."""
    out = np.full(shape, -1, np.int32)
    for i, b in enumerate(skeleton.branches):
        m = np.zeros(shape, np.uint8)
        for (a, bb), (r0, r1) in zip(zip(b.points[:-1], b.points[1:]), zip(b.thickness[:-1], b.thickness[1:])):
            r = max(0.5 * (r0 + r1), 0.5) + 2.0
            cv2.line(m, _pt(a), _pt(bb), 1, thickness=max(1, round(2 * r)), lineType=cv2.LINE_8, shift=4)
        out[m > 0] = i
    return out


def _pt(p: F64) -> tuple[int, int]:
    return round(p[0] * 16), round(p[1] * 16)
