"""Contact sheet of the texture jobs: look at it before trusting any number.

    python benches/sheet_texture.py out/texture_sheet.png

Rows of synthesis (exemplar | output | field | coherence) on the embedded bark and brick and
the test water photo (with each image's repetition score, phloem.metrics.repetition: ~0.9
means tiled), then completion (image with hole | output | field in the hole | filled
crop). The field panel colours each output pixel by the exemplar position it copies (red =
row, green = column): large smooth patches of one colour are coherent copies, speckle is
pixel-wise mixing. The coherence panel shows each patch's distance to its nearest exemplar
patch (dark = copied faithfully, bright = invented).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import cv2
import numpy as np

import phloem

ROOT = Path(__file__).resolve().parents[1]
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


def _heat(d: np.ndarray) -> np.ndarray:
    d = np.nan_to_num(d, nan=0.0)
    v = np.clip(d / max(float(np.percentile(d, 99)), 1e-8), 0, 1)
    return cv2.applyColorMap((v * 255).astype(np.uint8), cv2.COLORMAP_INFERNO)[..., ::-1].astype(np.float32) / 255


def write_sheet(rows: list[np.ndarray] | list[list[np.ndarray]], out: str | Path) -> np.ndarray:
    """Stack ``rows`` (each an image or a list of tiles) top to bottom and write the sheet to ``out``."""
    sheet = np.concatenate([r if isinstance(r, np.ndarray) else np.concatenate(r, axis=1) for r in rows], axis=0)
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    phloem.io.write_image(out, sheet, overwrite=True)
    return sheet


def synthesis_row(name: str, ex: np.ndarray) -> tuple[np.ndarray, str]:
    t0 = time.perf_counter()
    out = phloem.texture.synthesize(ex, (384, 384), seed=0)
    dt = time.perf_counter() - t0
    field, _ = phloem.patch.nnf(ex, out, iterations=8, levels=3, seed=0)
    coh = phloem.metrics.coherence_map(out, ex)
    rep_out, rep_ex = phloem.metrics.repetition(out), phloem.metrics.repetition(ex)
    line = (
        f"{name}: synthesize {ex.shape[1]}x{ex.shape[0]} -> 384x384 in {dt:.2f} s, coherence {np.nanmean(coh):.4g}, "
        f"repetition {rep_out:.3f} (exemplar {rep_ex:.3f})"
    )
    tiles = [
        _label(_fit(ex), f"{name} exemplar {ex.shape[1]}x{ex.shape[0]}, rep {rep_ex:.2f}"),
        _label(_fit(out), f"output 384x384, {dt:.2f} s, rep {rep_out:.2f}"),
        _label(_fit(_field_colour(field, ex.shape)), "field: source row/col as R/G"),
        _label(_fit(_heat(coh)), f"coherence map, mean {np.nanmean(coh):.4f}"),
    ]
    return np.concatenate(tiles, axis=1), line


def completion_row(name: str, img: np.ndarray, hole: np.ndarray) -> tuple[np.ndarray, str]:
    t0 = time.perf_counter()
    out = phloem.texture.complete(img, hole, seed=0)
    dt = time.perf_counter() - t0
    src = img.copy()
    src[hole] = 0
    known = ~cv2.dilate(hole.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
    field, _ = phloem.patch.nnf(out, out, source_mask=known, target_mask=hole, iterations=8, seed=0)
    holed = _rgb(img).copy()
    holed[hole] = (1.0, 0.0, 1.0)
    ys, xs = np.nonzero(hole)
    y0, y1, x0, x1 = max(ys.min() - 32, 0), ys.max() + 32, max(xs.min() - 32, 0), xs.max() + 32
    line = f"{name}: complete {hole.sum()} px hole in {img.shape[1]}x{img.shape[0]} in {dt:.2f} s"
    tiles = [
        _label(_fit(holed), f"{name} with hole (magenta)"),
        _label(_fit(out), f"completed, {dt:.2f} s"),
        _label(_fit(_field_colour(field, img.shape, hole)), "field inside the hole"),
        _label(_fit(out[y0:y1, x0:x1]), "filled region, zoomed"),
    ]
    return np.concatenate(tiles, axis=1), line


def main(out_path: str) -> None:
    water = phloem.io.read_image(ROOT / "tests" / "data" / "water.jpg")
    bark = phloem.data.bark()[..., :3]
    rows, lines = [], []
    for name, ex in [
        ("bark", bark[:128, :128]),
        ("brick", phloem.data.brick()[:160, :160]),
        ("water", water[:150, :150]),
    ]:
        r, line = synthesis_row(name, np.ascontiguousarray(ex))
        rows.append(r)
        lines.append(line)
    for name, img, (cy, cx, s) in [("bark", bark, (128, 128, 48)), ("water", water, (150, 150, 60))]:
        hole = np.zeros(img.shape[:2], bool)
        hole[cy - s // 2 : cy + s // 2, cx - s // 2 : cx + s // 2] = True
        r, line = completion_row(name, np.ascontiguousarray(img), hole)
        rows.append(r)
        lines.append(line)
    write_sheet(rows, out_path)
    print("\n".join(lines))
    print(f"wrote {out_path}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "out/texture_sheet.png")
