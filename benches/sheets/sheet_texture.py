"""Contact sheet of the texture jobs: look at it before trusting any number.

    python -m benches.sheets.sheet_texture out/texture_sheet.png

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

import cv2
import numpy as np

import phloem

from ._sheet import ROOT, _field_colour, _fit, _label, _rgb, write_sheet


def _heat(d: np.ndarray) -> np.ndarray:
    d = np.nan_to_num(d, nan=0.0)
    v = np.clip(d / max(float(np.percentile(d, 99)), 1e-8), 0, 1)
    return cv2.applyColorMap((v * 255).astype(np.uint8), cv2.COLORMAP_INFERNO)[..., ::-1].astype(np.float32) / 255


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
