"""Disk-shaped fragments on a skeleton and the library render draws them from (Sibbing, Pavić,
Kobbelt 2010, §5.1 and the shape distance of §5.2).

:func:`fragments` covers every branch with disks of radius ``3 × thickness`` whose centres are
``λ (s_i + s_(i+1))`` apart (``λ = 0.75``), plus one disk at every furcation. Each fragment
carries its *shape*: the skeleton segment through its centre resampled to ``k`` samples
(positions and thicknesses); a furcation fragment has the parent segment and the child segment,
``2k`` samples. :func:`rigid_align` is the closed-form alignment under which two shapes are
compared. :class:`FragmentLibrary`, :func:`cover`, :func:`check_params` and
:func:`foreign_fragments` serve :func:`~phloem.branching.render` and are not re-exported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._validate import as_image, check_float, check_int
from ._elements import _arc_lengths, _dense
from ._pixels import F64, _check_skeleton, _rot
from .skeleton import Branch, Skeleton

__all__ = ["DEFAULT_SAMPLES", "MIN_RADIUS", "Fragment", "fragments", "rigid_align"]

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


def _at(branch: Branch, cum: F64, arcs: F64) -> tuple[F64, F64]:
    a = np.clip(arcs, 0.0, cum[-1])
    pts = np.stack([np.interp(a, cum, branch.points[:, 0]), np.interp(a, cum, branch.points[:, 1])], axis=1)
    return pts, np.interp(a, cum, branch.thickness)


def _radius_cap(skeleton: Skeleton, rf: float) -> float:
    """Largest fragment radius: ``rf`` times twice the 90th percentile of the thickness.

    A traced mask can hold a few blob-like parts (a lake, the sea) whose "thickness" is ten
    times a channel's; uncapped, their fragments would be disks hundreds of pixels wide.
    """
    th = np.concatenate([b.thickness for b in skeleton.branches])
    return max(rf * 2.0 * float(np.quantile(th, 0.9)), MIN_RADIUS)


def _centres(branch: Branch, lam: float, rf: float, rmax: float = np.inf) -> list[float]:
    """Arc lengths of the fragment centres: consecutive Euclidean distance ``λ (s_i + s_(i+1))``."""
    pts, th, s = _dense(branch, 0.5)
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


def check_params(lam: Any, radius_factor: Any, samples: Any) -> tuple[float, float, int]:
    lam_f = check_float(lam, "lam", 0.0, inclusive=False)
    if lam_f > 1.0:
        raise ValueError(f"lam: expected a value in (0, 1] so that neighbouring fragments overlap, got {lam}")
    return lam_f, check_float(radius_factor, "radius_factor", 0.0, inclusive=False), check_int(samples, "samples", 2)


def cover(skeleton: Skeleton, lam: float, rf: float, k: int, *, order: bool, furcations: bool = True) -> list[Fragment]:
    """Fragments of every branch; with ``order``, in synthesis order (a furcation fragment
    replaces the first fragment of its child branch and follows the parent's fragments).
    Without ``furcations`` no furcation fragments are made."""
    out: list[Fragment] = []
    cums = [_arc_lengths(b) for b in skeleton.branches]
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
    lam_f, rf, k = check_params(lam, radius_factor, samples)
    shape = None if image is None else as_image(image, "image").shape[:2]
    sk = _check_skeleton(skeleton, "skeleton", shape)
    return cover(sk, lam_f, rf, k, order=False)


class FragmentLibrary:
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
        for m in {len(frs[i].points) for i in frag}:  # shapes with no usable fragment have no group
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


def foreign_fragments(skeleton: Skeleton, frs: list[Fragment], *, keep: int) -> NDArray[np.bool_]:
    """Branch fragments whose disk holds part of another branch (the start of a sub-branch,
    or the parent next to a child's first fragment). Pasted along a plain target branch they
    leave a stub of a branch that is not there, so they are left out, unless fewer than
    ``keep`` branch fragments would remain; furcations have their own fragments."""
    from scipy.spatial import cKDTree  # type: ignore[import-untyped]

    dense = [_dense(b, 1.0) for b in skeleton.branches]
    pts = np.concatenate([d[0] for d in dense])
    th = np.concatenate([d[1] for d in dense])
    owner = np.concatenate([np.full(len(d[0]), bi) for bi, d in enumerate(dense)])
    out = np.zeros(len(frs), bool)
    plain_ids = [i for i, f in enumerate(frs) if not f.furcation]
    if plain_ids:
        # Only points within the radius plus the thickest branch's can be inside a disk: one
        # tree query per fragment instead of every branch against every fragment.
        centres = np.array([frs[i].center for i in plain_ids], np.float64)
        reach = np.array([frs[i].radius for i in plain_ids]) + float(th.max())
        for i, near in zip(plain_ids, cKDTree(pts).query_ball_point(centres, reach), strict=True):
            f = frs[i]
            idx = np.asarray(near, np.int64)
            idx = idx[owner[idx] != f.branch]
            out[i] = bool((np.linalg.norm(pts[idx] - f.center, axis=1) - th[idx] < f.radius).any())
    if len(plain_ids) - int(out.sum()) < keep:
        out[:] = False
    return out
