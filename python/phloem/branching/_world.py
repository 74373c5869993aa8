"""The state a growth runs in (:func:`~phloem.branching.grow`, :func:`~phloem.branching.extend`).

The structure grown so far, as segments for the crossing tests and as the density map
``D(p) = exp(-d(p, B)² / ρ²)`` of space colonisation (Sibbing et al. 2010, §4.4), which
starts from the region outside the growth's domain where one is given; the
counts of the histogram matching; the guidance map ``G`` of guided synthesis (§4.5).
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .. import _core
from ._elements import F64, _axis_bins, _bin, _direction
from .bending import BendingModel, arc_window_turns


class _World:
    """The structure grown so far: segments, density map, histograms, guidance."""

    def __init__(
        self,
        model: BendingModel,
        shape: tuple[int, int],
        *,
        colonize: bool,
        rho: float,
        guide: F64 | None,
        rng: np.random.Generator,
        repel_border: bool = False,
        domain: NDArray[np.bool_] | None = None,
    ) -> None:
        self.model = model
        self.shape = shape
        self.colonize = colonize
        self.repel_border = repel_border
        self.rho = rho
        self.guide = None if guide is None else np.ascontiguousarray(guide, np.float64)
        self.rng = rng
        # the density map D = exp(-d²/ρ²) itself (float32), so that lookups are plain indexing
        self.dens = np.zeros(shape, np.float32) if colonize else None
        self._dsum = 0.0  # sum of D over the image, kept up to date by stamp()
        # which branch vertex each pixel's distance comes from, to ignore where a child starts
        self.owner_branch = np.full(shape, -1, np.int32) if colonize else None
        self.owner_vertex = np.full(shape, -1, np.int32) if colonize else None
        # outside the domain (a photo's frame) is structure of no branch: D as at a branch's surface
        self.domain = domain
        if domain is not None and self.dens is not None:
            d = cv2.distanceTransform(domain.astype(np.uint8), cv2.DIST_L2, 5)
            self.dens[:] = np.where(d <= 3.0 * rho, np.exp(-((d / rho) ** 2)), 0.0)
        # segments in a growable array; the crossing tests cut it down to those near the paths
        self._seg = np.zeros((256, 4))
        self._nseg = 0
        # histogram matching starts from the model's warm start: pseudo-elements distributed
        # like the input (see BendingModel.warm_start)
        self.counts_alpha = model.warm_start * model.hist_alpha
        self.counts_r = model.warm_start * model.hist_r
        self.counts_arc = model.warm_start * model.hist_arc  # the heading-change histogram's
        self.counts_dir = model.warm_start * model.hist_dir  # the direction histogram's
        self.total_length = 0.0

    # -- bookkeeping ----------------------------------------------------------------------
    @property
    def segment_rows(self) -> F64:
        """All segments so far as ``(s, 4)`` rows ``x0, y0, x1, y1``."""
        return self._seg[: self._nseg]

    def add_segments(self, pts: F64) -> None:
        n = len(pts) - 1
        if n < 1:
            return
        if self._nseg + n > len(self._seg):
            grown = np.zeros((max(2 * len(self._seg), self._nseg + n), 4))
            grown[: self._nseg] = self._seg[: self._nseg]
            self._seg = grown
        self._seg[self._nseg : self._nseg + n, :2] = pts[:-1]
        self._seg[self._nseg : self._nseg + n, 2:] = pts[1:]
        self._nseg += n
        self.total_length += float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())

    def add_elements(self, alpha: F64, r: F64, windows: F64 | None, headings: F64 | None = None) -> None:
        """Count new elements in the histograms; ``windows``: the branch's angles from
        ``arc_edges - 1`` before the first new one, for the heading-change histogram;
        ``headings``: the new edges' headings on the image, for the direction histogram."""
        m = self.model
        if headings is not None and m.direction_histogram > 0:
            np.add.at(self.counts_dir, _axis_bins(headings, m.bins), 1.0)
        np.add.at(self.counts_alpha, _bin(alpha, *m.range_alpha, m.bins), 1.0)
        np.add.at(self.counts_r, _bin(r, *m.range_r, m.bins), 1.0)
        if windows is not None and m.turn_histogram > 0:
            turns = arc_window_turns(windows, m.arc_edges)
            np.add.at(self.counts_arc, _bin(turns, 0.0, math.pi, m.bins), 1.0)

    def recount_r(self, before: F64, after: F64) -> None:
        """Move counted elements' thicknesses from ``before`` to ``after`` in the thickness histogram."""
        m = self.model
        np.add.at(self.counts_r, _bin(before, *m.range_r, m.bins), -1.0)
        np.add.at(self.counts_r, _bin(after, *m.range_r, m.bins), 1.0)

    def stamp(self, pts: F64, thick: F64, branch: int, first: int) -> None:
        """Write segments into the density map, only within ``3ρ`` of them (§4.4 local update).

        ``pts`` are vertices ``first, first + 1, ...`` of branch ``branch``; every pixel with
        ``d ≤ 3ρ`` takes ``exp(-d²/ρ²)`` where that is larger than its density, ``d`` being
        its distance to the branch's surface (per segment, the distance to its nearest point
        minus the thickness there), and remembers the branch vertex nearest to that point.
        """
        if self.dens is None or self.owner_branch is None or self.owner_vertex is None or len(pts) < 2:
            return
        self._dsum += _core.density_stamp(
            self.dens,
            self.owner_branch,
            self.owner_vertex,
            np.ascontiguousarray(pts, np.float64),
            np.ascontiguousarray(thick, np.float64),
            int(branch),
            int(first),
            float(self.rho),
        )

    def surface_density(self, point: F64, pts: F64, thick: F64) -> float:
        """``exp(-d²/ρ²)`` at ``point``, ``d`` its distance to the surface of the polyline ``pts``
        with thickness ``thick`` (zero inside), and 0 beyond ``3ρ``: what :meth:`stamp` would
        write there for those vertices alone."""
        p = np.asarray(point, np.float64)
        a, th = np.asarray(pts, np.float64), np.asarray(thick, np.float64)
        if len(a) == 1:
            d = float(np.linalg.norm(p - a[0]) - th[0])
        else:
            seg = a[1:] - a[:-1]
            ll = np.einsum("ij,ij->i", seg, seg)
            t = np.clip(np.einsum("ij,ij->i", p - a[:-1], seg) / np.maximum(ll, 1e-300), 0.0, 1.0)
            near = a[:-1] + t[:, None] * seg
            d = float(np.min(np.linalg.norm(p - near, axis=1) - ((1.0 - t) * th[:-1] + t * th[1:])))
        d = max(d, 0.0)
        return math.exp(-(d * d) / (self.rho * self.rho)) if d <= 3.0 * self.rho else 0.0

    def density_mean(self) -> float:
        if self.dens is None:
            return 0.0
        return self._dsum / float(self.shape[0] * self.shape[1])

    # -- candidate evaluation --------------------------------------------------------------
    def _lookup(self, grid: Any, pts: F64) -> F64:
        H, W = self.shape
        ix = np.rint(pts[..., 0]).astype(np.int64)
        iy = np.rint(pts[..., 1]).astype(np.int64)
        inside = (ix >= 0) & (ix < W) & (iy >= 0) & (iy < H)
        out = np.zeros(ix.shape)
        out[inside] = grid[iy[inside], ix[inside]]
        return out

    def ray_density(
        self,
        starts: F64,
        headings: F64,
        length: float,
        samples: int,
        parent: tuple[int, int] | None = None,
        near: int = 0,
        *,
        include_start: bool = True,
    ) -> F64:
        """The largest density along each ray from ``starts`` (``(n, 2)``) along ``headings``
        (``(n,)``), ``length`` px long and read every ``length / samples`` px from the start
        (``include_start``) or from the first step: how crowded a new branch's first stretch
        would be. With ``parent = (branch, vertex)`` the parent's vertices within ``near`` of the
        vertex read as empty (a child starts on them)."""
        assert self.dens is not None
        s = length * np.arange(0 if include_start else 1, samples + 1) / samples
        pts = np.asarray(starts)[:, None, :] + _direction(np.asarray(headings))[:, None, :] * s[None, :, None]
        return np.asarray(self._lookup(_DensityView(self, parent, near), pts).max(axis=1), np.float64)

    def inside(self, pts: F64) -> NDArray[np.bool_]:
        """For each polyline ``(..., n, 2)``: do all its points lie in the image (and the domain)?"""
        H, W = self.shape
        ok = (pts[..., 0] >= 0) & (pts[..., 0] <= W - 1) & (pts[..., 1] >= 0) & (pts[..., 1] <= H - 1)
        if self.domain is not None:
            x = np.clip(np.rint(pts[..., 0]), 0, W - 1).astype(np.intp)
            y = np.clip(np.rint(pts[..., 1]), 0, H - 1).astype(np.intp)
            ok &= self.domain[y, x]
        return np.asarray(ok.all(axis=-1))

    def crossings(self, tip: F64, ext: F64) -> NDArray[np.bool_]:
        """For each candidate extension ``(C, m, 2)`` from ``tip``: does it cross a segment?"""
        C = len(ext)
        if self._nseg == 0 or C == 0:
            return np.zeros(C, bool)
        path = np.ascontiguousarray(np.concatenate([np.broadcast_to(tip, (C, 1, 2)), ext], axis=1), np.float64)
        # proper crossings only: a child starting on its parent or consecutive edges touch
        return _core.polylines_crossing(path, self.segment_rows)


def _guide_map(guide: Any, shape: tuple[int, int], width: float) -> tuple[F64, F64 | None]:
    """The guidance map ``G`` (§4.5) and, for a polyline guide, the polyline.

    A boolean ``(H, W)`` mask marks the path; an ``(n, 2)`` array is an ``(x, y)`` polyline;
    both become ``G = 1 - exp(-d² / width²)`` with ``d`` the distance to the path. Any other
    real ``(H, W)`` array is ``G`` itself (integers scaled by their dtype's maximum).
    """
    arr = np.asarray(guide)
    if arr.ndim == 2 and arr.shape == tuple(shape):
        if arr.dtype == np.bool_:
            if not arr.any():
                raise ValueError("guide: the path mask is empty")
            d = cv2.distanceTransform(np.where(arr, 0, 255).astype(np.uint8), cv2.DIST_L2, 5).astype(np.float64)
            return 1.0 - np.exp(-(d**2) / width**2), None
        if not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
            raise TypeError(f"guide: expected a real-valued or boolean map, got dtype {arr.dtype}")
        g = arr.astype(np.float64)
        if np.issubdtype(arr.dtype, np.integer):
            g /= float(np.iinfo(arr.dtype).max)
        if not np.isfinite(g).all():
            raise ValueError("guide: the guidance map contains NaN or infinity")
        return np.clip(g, 0.0, 1.0), None
    if arr.ndim != 2 or arr.shape[1] != 2 or len(arr) < 2:
        raise ValueError(
            f"guide: expected an (H, W) = {tuple(shape)} map or mask, or an (n, 2) polyline of (x, y), got shape {arr.shape}"
        )
    line = arr.astype(np.float64)
    if not np.isfinite(line).all():
        raise ValueError("guide: the polyline contains NaN or infinity")
    mask = np.full(shape, 255, np.uint8)
    cv2.polylines(mask, [np.round(line * 16).astype(np.int32)], False, 0, thickness=1, lineType=cv2.LINE_8, shift=4)
    d = cv2.distanceTransform(mask, cv2.DIST_L2, 5).astype(np.float64)
    return 1.0 - np.exp(-(d**2) / width**2), line


class _DensityView:
    """``D = exp(-d²/ρ²)`` read lazily from the distance map (indexing only, no full-map copy).

    A child starts on its parent, so every direction would see ``D = 1`` there and the
    density could not tell directions apart; pixels whose nearest structure is the parent
    within ``near`` vertices of the attachment read as empty (the child's own last ``3ρ``
    are held back from the map for the same reason).
    """

    def __init__(self, world: _World, parent: tuple[int, int] | None = None, near: int = 0) -> None:
        self.world = world
        self.parent = parent
        self.near = near

    def __getitem__(self, key: Any) -> Any:
        w = self.world
        assert w.dens is not None and w.owner_branch is not None and w.owner_vertex is not None
        out = w.dens[key].astype(np.float64)
        if self.parent is not None:
            pb, pv = self.parent
            skip = (w.owner_branch[key] == pb) & (np.abs(w.owner_vertex[key] - pv) <= self.near)
            out[skip] = 0.0
        return out
