"""What the contact sheets share: tiles fitted to a square, captions, and writing the sheet.

The sheets run as modules from the repository root: ``python -m benches.sheets.sheet_texture OUT.png``.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

import phloem

ROOT = Path(__file__).resolve().parents[2]
TILE = 256


def _rgb(img: np.ndarray) -> np.ndarray:
    """Gray (2-D or one channel), RGB or RGBA as RGB."""
    img = img[..., :3] if img.ndim == 3 else img[..., None]
    return np.repeat(img, 3, axis=2) if img.shape[2] == 1 else img


def _fit(img: np.ndarray, tile: int = TILE, interpolation: int = cv2.INTER_NEAREST) -> np.ndarray:
    """``img`` scaled into a white ``tile × tile`` square (nearest neighbour shows pixels;
    pass ``cv2.INTER_AREA`` for photos shrunk a lot)."""
    img = _rgb(img).astype(np.float32)
    s = tile / max(img.shape[:2])
    size = (max(1, round(img.shape[1] * s)), max(1, round(img.shape[0] * s)))
    out = cv2.resize(img, size, interpolation=interpolation).reshape(size[1], size[0], 3)
    square = np.ones((tile, tile, 3), np.float32)
    square[: out.shape[0], : out.shape[1]] = out
    return square


def _label(tile: np.ndarray, text: str) -> np.ndarray:
    t8 = (np.clip(tile, 0, 1) * 255).astype(np.uint8)  # OpenCV 5 draws text on 8-bit only
    cv2.rectangle(t8, (0, 0), (t8.shape[1], 16), (255, 255, 255), -1)
    cv2.putText(t8, text, (3, 12), cv2.FONT_HERSHEY_SIMPLEX, 0.38, (0, 0, 0), 1, cv2.LINE_AA)
    return t8.astype(np.float32) / 255


def _field_colour(field: np.ndarray, src_shape: tuple[int, ...], mask: np.ndarray | None = None) -> np.ndarray:
    vis = np.zeros((*field.shape[:2], 3), np.float32)
    vis[..., 0] = field[..., 0] / src_shape[0]
    vis[..., 1] = field[..., 1] / src_shape[1]
    vis[..., 2] = 0.3
    if mask is not None:
        vis[~mask] = 0.15
    return vis


def write_sheet(rows: list[np.ndarray] | list[list[np.ndarray]], out: str | Path) -> np.ndarray:
    """Stack ``rows`` (each an image or a list of tiles) top to bottom and write the sheet to ``out``."""
    sheet = np.concatenate([r if isinstance(r, np.ndarray) else np.concatenate(r, axis=1) for r in rows], axis=0)
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    phloem.io.write_image(out, sheet, overwrite=True)
    return sheet
