"""The input's layout of directions: which way its structure runs at each place (the ``layout``
growth term, beyond Sibbing et al. 2010).

The paper's models are the same everywhere in the picture: a candidate is judged by the
branch's history and the histograms of the whole structure, never by where it is. Some
structures are laid out: a fundus's vessels leave the optic disc and arc round the macula, a
delta's channels fan out from its apex, roots sweep one way down the soil. Grown without that,
their pieces run every way. :class:`DirectionLayout` holds, on a coarse grid over the input,
a von Mises distribution of the edges' axes (an edge and its reverse alike) fitted to the
*different branches* near each place, so that a single branch, however straight, says nothing
about its surroundings, and crossing or forking branches cancel: a crack network or bark has
no layout, and the term vanishes there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ._elements import F64, _edge_headings
from .skeleton import Skeleton

__all__ = ["LAYOUT_MIN_BRANCHES", "LAYOUT_SCALE", "DirectionLayout"]

#: Width of the window (a Gaussian's σ) over which the layout is fitted, as a fraction of the
#: input picture's shorter side.
LAYOUT_SCALE = 1.0 / 16.0
#: Fewer branches than this in the window (Kish's effective count) fit no layout there.
LAYOUT_MIN_BRANCHES = 2.0
#: Grid cells per σ of the window.
_CELLS_PER_SIGMA = 4.0
#: The largest mean resultant length fitted (κ ≈ 5.3): a few parallel branches are no certainty.
_MAX_RESULTANT = 0.9


def _kappa(r: F64) -> F64:
    """The von Mises concentration whose mean resultant length is ``r`` (Best and Fisher's
    approximation of the inverse of ``I1(κ) / I0(κ)``)."""
    r = np.clip(np.asarray(r, np.float64), 0.0, _MAX_RESULTANT)
    low = 2 * r + r**3 + 5 * r**5 / 6
    mid = -0.4 + 1.39 * r + 0.43 / (1 - r)
    high = 1 / np.maximum(r**3 - 4 * r**2 + 3 * r, 1e-12)
    return np.asarray(np.where(r < 0.53, low, np.where(r < 0.85, mid, high)), np.float64)


@dataclass(frozen=True)
class DirectionLayout:
    """Where the input's structure runs which way: a von Mises distribution of axes on a grid.

    At grid cell ``(i, j)`` an axis ``θ`` (radians, counter-clockwise on screen) has the
    log-density ``kappa[i, j] cos(2 (θ − phi[i, j]))`` up to a constant.

    Attributes
    ----------
    kappa : ndarray, shape (gh, gw)
        Concentration: 0 where the branches near the cell do not agree on a way (or fewer
        than :data:`LAYOUT_MIN_BRANCHES` are near).
    phi : ndarray, shape (gh, gw)
        The mean axis (radians, counter-clockwise on screen, in ``(−π/2, π/2]``).
    cell : float
        Input pixels per grid cell.
    shape : (int, int)
        The input picture's ``(height, width)``.
    """

    kappa: F64
    phi: F64
    cell: float
    shape: tuple[int, int]

    @classmethod
    def fit(cls, skeleton: Skeleton, *, scale: float = LAYOUT_SCALE) -> DirectionLayout:
        """Fit the layout of ``skeleton``'s edges over a window of ``scale`` × its picture's shorter side.

        Each branch contributes its edges' doubled angles, weighted by length and smoothed by
        the window: ``v_b = Σ l (cos 2θ, sin 2θ) * G``, ``w_b = Σ l * G``. The squared mean
        resultant over pairs of *different* branches,
        ``R² = (|Σ v_b|² − Σ |v_b|²) / ((Σ w_b)² − Σ w_b²)``, is an unbiased estimate that
        counts each branch as one sample (a branch's own edges are not independent); ``κ`` is
        the von Mises concentration of that ``R``.
        """
        if skeleton.shape is not None:
            h, w = skeleton.shape
        else:
            _, _, x1, y1 = skeleton.bounds()
            h, w = math.ceil(y1) + 1, math.ceil(x1) + 1
        sigma = max(scale * min(h, w), 1.0)
        cell = max(1.0, sigma / _CELLS_PER_SIGMA)
        gh, gw = int(h / cell) + 1, int(w / cell) + 1
        s = sigma / cell
        total = np.zeros((3, gh, gw))  # Σ v_b (2) and Σ w_b
        own = np.zeros((2, gh, gw))  # Σ |v_b|² and Σ w_b²
        for b in skeleton.branches:
            p = np.asarray(b.points, np.float64)
            if len(p) < 2:
                continue
            d = np.diff(p, axis=0)
            length = np.hypot(d[:, 0], d[:, 1])
            mid = 0.5 * (p[1:] + p[:-1])
            two = 2.0 * _edge_headings(p)
            rows = np.clip(np.rint(mid[:, 1] / cell).astype(np.int64), 0, gh - 1)
            cols = np.clip(np.rint(mid[:, 0] / cell).astype(np.int64), 0, gw - 1)
            # only the branch's own box (window included) is smoothed: thousands of branches stay cheap
            pad = math.ceil(4 * s) + 1
            r0, r1 = max(int(rows.min()) - pad, 0), min(int(rows.max()) + pad + 1, gh)
            c0, c1 = max(int(cols.min()) - pad, 0), min(int(cols.max()) + pad + 1, gw)
            mine = np.zeros((3, r1 - r0, c1 - c0))
            for k, vals in enumerate((length * np.cos(two), length * np.sin(two), length)):
                np.add.at(mine[k], (rows - r0, cols - c0), vals)
                mine[k] = cv2.GaussianBlur(mine[k], (0, 0), s, borderType=cv2.BORDER_CONSTANT)
            total[:, r0:r1, c0:c1] += mine
            own[0, r0:r1, c0:c1] += mine[0] ** 2 + mine[1] ** 2
            own[1, r0:r1, c0:c1] += mine[2] ** 2
        c, sn, wt = total
        pairs = wt * wt - own[1]
        r2 = np.where(pairs > 1e-12, (c * c + sn * sn - own[0]) / np.maximum(pairs, 1e-12), 0.0)
        branches = wt * wt / np.maximum(own[1], 1e-300)  # Kish's effective number of branches
        r2 = np.where(branches >= LAYOUT_MIN_BRANCHES, np.clip(r2, 0.0, 1.0), 0.0)
        return cls(_kappa(np.sqrt(r2)), 0.5 * np.arctan2(sn, c), cell, (h, w))

    def sample(self, points: F64, shape: tuple[int, int]) -> tuple[F64, F64]:
        """``(kappa, phi)`` at every ``(x, y)`` row of ``points`` of a picture of ``shape``."""
        h, w = self.shape
        pts = np.asarray(points, np.float64).reshape(-1, 2)
        sx = pts[:, 0] / max(shape[1] - 1, 1) * (w - 1)
        sy = pts[:, 1] / max(shape[0] - 1, 1) * (h - 1)
        i = np.clip(np.rint(sy / self.cell).astype(np.int64), 0, self.kappa.shape[0] - 1)
        j = np.clip(np.rint(sx / self.cell).astype(np.int64), 0, self.kappa.shape[1] - 1)
        return self.kappa[i, j], self.phi[i, j]

    def at(self, x: float, y: float, shape: tuple[int, int]) -> tuple[float, float]:
        """``(kappa, phi)`` at ``(x, y)`` of a picture of ``shape``, laid over the input's frame."""
        kappa, phi = self.sample(np.array([x, y], np.float64), shape)
        return float(kappa[0]), float(phi[0])
