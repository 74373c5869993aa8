"""Graph-cut composition (Luo et al. §2, Eqs. 1–2): the fetched pieces joined into one image.

The pieces go onto the canvas one by one, along each stroke and stroke after stroke. Where a
new piece overlaps what is already there, every overlap pixel is given to the canvas or to the
piece by the minimum cut of :func:`phloem.seams.seam` with Luo's cost: ``min(d(x), d(y)) /
G(x, y)``, ``d`` the fourth power of the colour difference and ``G`` the summed gradient
magnitudes, with the data term of 10000 tying overlap pixels on the border of one side to that
side. Pieces of different strokes that meet at a junction are cut against each other the same
way. A pixel only ever takes a piece that covers it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage  # type: ignore[import-untyped]

from .. import seams
from .fetch import Piece

F32 = NDArray[np.float32]


@dataclass(frozen=True)
class Composite:
    """The composed pieces.

    Attributes
    ----------
    rgba : (H, W, 4) ndarray of float32
        The image: each pixel the colour and alpha of the piece it took.
    labels : (H, W) ndarray of int32
        The index of the piece each pixel took, -1 where none covers it.
    energy : float
        The summed energy of the cuts.
    """

    rgba: F32
    labels: NDArray[np.int32]
    energy: float


def compose(
    pieces: list[Piece],
    size: tuple[int, int],
    *,
    threads: int | None,
    check: Callable[[int], None] | None = None,
) -> Composite:
    """Compose ``pieces`` (in order) onto a transparent ``size`` = (H, W) canvas; ``check(k)``
    runs before piece ``k`` (progress, cancellation)."""
    h, w = size
    rgba = np.zeros((h, w, 4), np.float32)
    labels = np.full((h, w), -1, np.int32)
    energy = 0.0
    for k, p in enumerate(pieces):
        if check is not None:
            check(k)
        x0, y0 = p.offset
        ph, pw = p.support.shape
        # The piece's box on the canvas plus a ring of one pixel, so overlap pixels on the box's
        # edge see the canvas that goes on beyond it.
        cy0, cy1 = max(0, y0 - 1), min(h, y0 + ph + 1)
        cx0, cx1 = max(0, x0 - 1), min(w, x0 + pw + 1)
        if cy1 <= cy0 or cx1 <= cx0:
            continue
        b = np.zeros((cy1 - cy0, cx1 - cx0, 4), np.float32)
        b_mask = np.zeros(b.shape[:2], bool)
        sy0, sx0 = max(0, cy0 - y0), max(0, cx0 - x0)
        sy1, sx1 = min(ph, cy1 - y0), min(pw, cx1 - x0)
        dy0, dx0 = y0 + sy0 - cy0, x0 + sx0 - cx0
        b[dy0 : dy0 + sy1 - sy0, dx0 : dx0 + sx1 - sx0] = p.rgba[sy0:sy1, sx0:sx1]
        b_mask[dy0 : dy0 + sy1 - sy0, dx0 : dx0 + sx1 - sx0] = p.support[sy0:sy1, sx0:sx1]
        if not b_mask.any():
            continue
        view = rgba[cy0:cy1, cx0:cx1]
        lab = labels[cy0:cy1, cx0:cx1]
        a_mask = lab >= 0
        region = a_mask & b_mask
        if region.any():
            cut = seams.seam(
                view[..., :3],
                b[..., :3],
                region,
                cost="luo",
                a_mask=a_mask,
                b_mask=b_mask,
                threads=threads,
                full_output=True,
            )
            take = cut.take_b & b_mask
            energy += cut.energy
        else:
            take = b_mask
        view[take] = b[take]
        lab[take] = k
    return Composite(rgba, labels, energy)


def keep_on_strokes(comp: Composite, points: NDArray[np.float64]) -> Composite:
    """``comp`` without the pieces of it that touch no target stroke: the connected parts
    (8-connected, alpha above zero) that hold none of ``points`` ((N, 2) ``(x, y)`` along the
    target strokes). A piece at a stroke's end or junction can bring a sliver of the source
    from beyond it, apart from the object."""
    h, w = comp.labels.shape
    parts, n = ndimage.label(comp.rgba[..., 3] > 0, structure=np.ones((3, 3), bool))
    if n <= 1:
        return comp
    xi, yi = np.rint(points[:, 0]).astype(int), np.rint(points[:, 1]).astype(int)
    ok = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
    keep = np.zeros(n + 1, bool)
    keep[parts[yi[ok], xi[ok]]] = True
    keep[0] = False
    drop = ~keep[parts] & (parts > 0)
    if not drop.any():
        return comp
    rgba, labels = comp.rgba.copy(), comp.labels.copy()
    rgba[drop] = 0.0
    labels[drop] = -1
    return Composite(rgba, labels, comp.energy)


def seam_map(labels: NDArray[np.int32]) -> NDArray[np.bool_]:
    """Pixels where two different pieces meet (4-neighbours with different labels, both
    covered)."""
    out = np.zeros(labels.shape, bool)
    for a, b, oa, ob in (
        (labels[:, 1:], labels[:, :-1], (slice(None), slice(1, None)), (slice(None), slice(None, -1))),
        (labels[1:], labels[:-1], (slice(1, None), slice(None)), (slice(None, -1), slice(None))),
    ):
        edge = (a != b) & (a >= 0) & (b >= 0)
        out[oa] |= edge
        out[ob] |= edge
    return out
