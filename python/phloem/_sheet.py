"""Tiles and captions of the contact sheets that the pipelines draw (``leaves``, ``strokes``)."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]

#: The grey that tiles are laid on and transparent pixels shown over.
PAPER = 0.85


def fit_tile(img: F32, tile: int) -> F32:
    """An RGB or RGBA image (over the paper grey) fitted into the middle of a tile × tile square."""
    h, w = img.shape[:2]
    k = tile / max(h, w)
    small = cv2.resize(img, (max(1, round(w * k)), max(1, round(h * k))), interpolation=cv2.INTER_AREA)
    if small.shape[2] == 4:
        a = small[..., 3:4]
        small = small[..., :3] * a + PAPER * (1 - a)
    out = np.full((tile, tile, 3), PAPER, np.float32)
    y0, x0 = (tile - small.shape[0]) // 2, (tile - small.shape[1]) // 2
    out[y0 : y0 + small.shape[0], x0 : x0 + small.shape[1]] = small
    return out


def caption(img: F32, text: str) -> F32:
    """``img`` with ``text`` written in dark grey at its top left."""
    u8 = np.ascontiguousarray((np.clip(img, 0, 1) * 255).astype(np.uint8))
    cv2.putText(u8, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (30, 30, 30), 1, cv2.LINE_AA)
    out: F32 = np.asarray(u8, np.float32) / np.float32(255.0)
    return out
