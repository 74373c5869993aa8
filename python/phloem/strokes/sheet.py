"""Pictures of stroke sets and edits: strokes drawn over an image (:func:`draw`) and a contact
sheet of an edit (:func:`contact_sheet`): source with strokes, target strokes, pieces and seams,
result."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .._sheet import PAPER, caption, fit_tile
from .._validate import as_image, check_int
from .stroke_set import StrokeSet
from .synthesis import EditResult

__all__ = ["contact_sheet", "draw"]

F32 = NDArray[np.float32]
#: Stroke colours, cycled (RGB).
_COLORS = np.array(
    [[0.95, 0.15, 0.1], [0.1, 0.45, 1.0], [1.0, 0.8, 0.0], [0.8, 0.1, 0.9], [0.0, 0.9, 0.9], [1.0, 0.5, 0.0]],
    np.float32,
)


def _rgb(image: Any) -> F32:
    img = as_image(image, "image")
    c = img.shape[2]
    rgb = np.repeat(img[..., :1], 3, axis=2) if c in (1, 2) else img[..., :3]
    if c in (2, 4):
        a = img[..., -1:]
        rgb = rgb * a + PAPER * (1 - a)
    return np.ascontiguousarray(rgb, dtype=np.float32)


def draw(image: Any, strokes: StrokeSet, *, side: str = "source", width: int | None = None) -> F32:
    """``image`` (RGB, alpha over grey) with the ``side`` ("source" or "target") strokes of
    ``strokes`` drawn on it: each stroke in its colour, numbered at its start, its control
    points as dots.

    Returns
    -------
    (H, W, 3) ndarray of float32
    """
    if side not in ("source", "target"):
        raise ValueError(f"side: expected 'source' or 'target', got {side!r}")
    if not isinstance(strokes, StrokeSet):
        raise TypeError(f"strokes: expected a StrokeSet, got {type(strokes).__name__}")
    out = np.ascontiguousarray((np.clip(_rgb(image), 0, 1) * 255).astype(np.uint8))
    h, w = out.shape[:2]
    lw = check_int(width, "width", 1) if width is not None else max(1, round(max(h, w) / 300))
    for i, pair in enumerate(strokes.pairs):
        s = getattr(pair, side)
        col = tuple(int(v) for v in (_COLORS[i % len(_COLORS)] * 255))
        pts = np.rint(s.points).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(out, [pts], False, col, lw, cv2.LINE_AA)
        for u in pair.controls[:, 0 if side == "source" else 1]:
            x, y = np.rint(s.at(u)).astype(int)
            cv2.circle(out, (int(x), int(y)), 2 * lw + 1, col, -1, cv2.LINE_AA)
        x, y = np.rint(s.points[0]).astype(int)
        cv2.putText(
            out, str(i), (int(x) + 4, int(y) - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.4 * lw + 0.1, col, lw, cv2.LINE_AA
        )
    drawn: F32 = np.asarray(out, np.float32) / np.float32(255.0)
    return drawn


def _pieces(result: EditResult) -> F32:
    """The piece map: each piece a colour from its index, seams black, nothing grey."""
    lab = result.pieces
    rng = np.random.default_rng(0)
    colours = rng.uniform(0.25, 1.0, size=(int(lab.max()) + 2, 3)).astype(np.float32)
    out = np.where((lab >= 0)[..., None], colours[np.maximum(lab, 0)], np.float32(PAPER))
    out[result.seams] = 0.0
    return np.asarray(out, np.float32)


def contact_sheet(image: Any, strokes: StrokeSet, result: EditResult, *, tile: int = 320) -> F32:
    """One row of ``tile``-pixel squares: the source with its strokes and object mask, the
    target strokes, the pieces with their seams, the result over grey, and the result with
    the target strokes over it.

    Returns
    -------
    (tile, 5 · tile, 3) ndarray of float32
    """
    t = check_int(tile, "tile", 64)
    src = _rgb(image)
    src = np.where(result.mask[..., None], src, 0.35 * src + 0.65 * np.float32(PAPER))
    size = result.image.shape[:2]
    blank = np.full((*size, 3), 0.95, np.float32)
    out = _rgb(result.image)
    tiles = [
        (draw(src, strokes, side="source"), "source, object, strokes"),
        (draw(blank, strokes, side="target"), "target strokes"),
        (_pieces(result), f"pieces ({int(result.pieces.max()) + 1}) and seams"),
        (out, "result"),
        (draw(out, strokes, side="target"), "result with target strokes"),
    ]
    return np.concatenate([caption(fit_tile(img, t), text) for img, text in tiles], axis=1)
