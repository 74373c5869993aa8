"""A contact sheet of a leaf model and new leaves: exemplars, layers, backgrounds, new leaves."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._sheet import PAPER, caption, fit_tile
from .._validate import as_image, check_int
from .model import LeafModel

__all__ = ["contact_sheet"]

F32 = NDArray[np.float32]

#: Grey the leaves are composited over, and the overlay colours of layers 1, 2, ... (RGB).
_LAYER_COLORS = np.array(
    [[0.95, 0.15, 0.1], [0.1, 0.45, 1.0], [1.0, 0.8, 0.0], [0.8, 0.1, 0.9], [0.0, 0.9, 0.9], [1.0, 0.5, 0.0]],
    np.float32,
)


def _overlay(model: LeafModel, i: int) -> F32:
    """Exemplar ``i`` aligned, its layers tinted in their colours (the background untinted)."""
    img: F32 = np.array(model.aligned[i], np.float32)
    for k, m in enumerate(model.masks[i]):
        c = _LAYER_COLORS[k % len(_LAYER_COLORS)]
        img[m, :3] = 0.35 * img[m, :3] + 0.65 * c
    return img


def contact_sheet(model: LeafModel, new_leaves: Sequence[Any] = (), *, tile: int = 200) -> F32:
    """Rows of ``tile``-pixel squares: the exemplars as posed, aligned to the training leaf,
    their induced layers tinted (layer 1 red, 2 blue, 3 yellow, ...), the peeled backgrounds,
    then the new leaves, as many per row as there are exemplars (at least four).

    Returns
    -------
    sheet : (H, W, 3) ndarray of float32
    """
    t = check_int(tile, "tile", 32)
    n = model.n_exemplars
    per_row = max(4, n)
    width = per_row * t

    def row(images: Sequence[F32], title: str) -> F32:
        r = np.full((t, width, 3), PAPER, np.float32)
        for j, img in enumerate(images[:per_row]):
            r[:, j * t : (j + 1) * t] = fit_tile(img, t)
        return caption(r, title)

    rows = [
        row(model.leaves, f"exemplars (training: {model.training})"),
        row(model.aligned, "aligned to the training leaf"),
        row([_overlay(model, i) for i in range(n)], "induced layers (removal order: red, blue, yellow...)"),
        row(model.background, "backgrounds (layers peeled)"),
    ]
    new = [as_image(x, f"new_leaves[{j}]") for j, x in enumerate(new_leaves)]
    for start in range(0, len(new), per_row):
        rows.append(row(new[start : start + per_row], "new leaves" if start == 0 else ""))
    return np.concatenate(rows, axis=0)
