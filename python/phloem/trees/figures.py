"""The paper's combination tables (Argudo et al. 2017 §6.4–6.5, Fig. 13 and Fig. 14)."""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from .._validate import check_int
from ._checks import F32
from .contour_space import combine_contours, fill_contour
from .preprocessing import Tree
from .transfer import morph

__all__ = ["morph_table"]


def morph_table(
    trees: Sequence[Tree],
    *,
    tile: int = 192,
    colors: bool = True,
    background: tuple[float, float, float] = (0.8, 0.8, 0.8),
    threads: int | None = None,
) -> F32:
    """The paper's combination tables (Fig. 13 and Fig. 14) for a few exemplars, as one image.

    Row ``i``, column ``j`` (``i != j``) shows the contour ``w_i C_i + w_j C_j`` with weights
    2/3 and 1/3 in the lower triangle and 1/3 and 2/3 in the upper one, filled with the colours
    of the row's tree only (Fig. 14) or, with ``colors=False``, as a silhouette (Fig. 13). The
    diagonal shows the exemplars, and the first row and column repeat them as headers.

    Parameters
    ----------
    trees : sequence of Tree
        Two or more exemplars (the paper shows seven).
    tile : int, optional
        Side of each cell in pixels.
    colors : bool, optional
        Colour transfer (Fig. 14) or silhouettes of the combined contours (Fig. 13).
    background : (float, float, float), optional
        RGB shown behind transparent pixels.
    threads : int, optional
        Worker threads for the warps.

    Returns
    -------
    ((k + 1) * tile, (k + 1) * tile, 3) float32 ndarray

    Examples
    --------
    >>> import numpy as np, phloem
    >>> a = np.zeros((120, 80, 4), np.float32); a[10:70, 10:70] = 1.0; a[70:110, 35:45] = 1.0
    >>> ts = [phloem.trees.prepare(x, size=96, split=(160, 20, 20), m=30) for x in (a, a[:, ::-1])]
    >>> phloem.trees.morph_table(ts, tile=32).shape
    (96, 96, 3)
    """
    ts = list(trees)
    if len(ts) < 2:
        raise ValueError(f"trees: a combination table needs at least two exemplars, got {len(ts)}")
    tile = check_int(tile, "tile", 8)
    k = len(ts)
    bg = np.asarray(background, np.float32)
    out = np.empty(((k + 1) * tile, (k + 1) * tile, 3), np.float32)
    out[:] = bg

    def put(r: int, c: int, rgba: F32) -> None:
        small = cv2.resize(rgba, (tile, tile), interpolation=cv2.INTER_AREA)
        a = small[..., 3:4]
        out[r * tile : (r + 1) * tile, c * tile : (c + 1) * tile] = small[..., :3] * a + bg * (1 - a)

    m = len(ts[0].simplified)
    for i, t in enumerate(ts):
        put(0, i + 1, t.image)
        put(i + 1, 0, t.image)
        for j, u in enumerate(ts):
            if i == j:
                cell = t.image
            else:
                w = [2 / 3, 1 / 3] if i > j else [1 / 3, 2 / 3]
                if colors:
                    cell = morph([t, u], w, color_weights=[1.0, 0.0], m=m, threads=threads)
                else:
                    sil = fill_contour(combine_contours([t.resampled, u.resampled], w), t.image.shape[:2])
                    cell = np.zeros((*sil.shape, 4), np.float32)
                    cell[sil] = (0.15, 0.35, 0.15, 1.0)
            put(i + 1, j + 1, cell)
    return out
