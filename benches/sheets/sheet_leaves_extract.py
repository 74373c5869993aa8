"""Contact sheet of leaf extraction: each input scan or photo beside the leaves cut from it.

    python -m benches.sheets.sheet_leaves_extract OUT.png [--tile 256] [--per-image 6] [--zoom]

Each row is one image of ../shared/data/leaves (skipped when absent; a synthetic scan is used
then): the input, then its extracted leaves (in the order ``extract`` returns them) composited
over a grey checkerboard, so transparent holes, soft edges and lost petioles show. ``--zoom`` adds
a tile per leaf with a 4x close-up of its alpha edge at the petiole end (the lowest opaque pixel).
Images that ``extract`` refuses (a photo that is all leaf) show the error text instead.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

import phloem
from benches.sheets._sheet import _fit, _label, write_sheet
from phloem.testing import shared_path

SHARED = shared_path("leaves")


def checker(h: int, w: int, cell: int = 8) -> np.ndarray:
    """A grey checkerboard of ``h × w`` pixels, RGB."""
    yy, xx = np.mgrid[:h, :w]
    return np.where(((yy // cell + xx // cell) % 2 == 0)[..., None], 0.55, 0.75).astype(np.float32) * np.ones(
        3, np.float32
    )


def over_checker(rgba: np.ndarray, cell: int = 8) -> np.ndarray:
    a = rgba[..., 3:4]
    return rgba[..., :3] * a + checker(*rgba.shape[:2], cell) * (1 - a)


def close_up(rgba: np.ndarray, tile: int) -> np.ndarray:
    """4x nearest-neighbour close-up around the lowest opaque pixel (where a petiole usually ends)."""
    ys, xs = np.nonzero(rgba[..., 3] > 0.5)
    i = int(np.argmax(ys))
    r = tile // 8
    y, x = int(ys[i]), int(xs[i])
    pad = np.pad(rgba, ((r, r), (r, r), (0, 0)))
    crop = pad[y : y + 2 * r, x : x + 2 * r]
    return cv2.resize(over_checker(crop, 2), (tile, tile), interpolation=cv2.INTER_NEAREST)


def synthetic_scan() -> np.ndarray:
    scan = np.full((300, 400, 3), 0.95, np.float32)
    cv2.ellipse(scan, (120, 140), (70, 35), 60, 0, 360, (0.2, 0.45, 0.15), -1)
    cv2.line(scan, (160, 205), (185, 260), (0.35, 0.3, 0.1), 2)
    cv2.ellipse(scan, (290, 140), (45, 90), 0, 0, 360, (0.25, 0.5, 0.2), -1)
    return scan


def rows(tile: int, per_image: int, zoom: bool) -> list[list[np.ndarray]]:
    images = sorted(SHARED.glob("*")) if SHARED.is_dir() else []
    inputs = [(p.name, phloem.io.read_image(p)[..., :3]) for p in images] or [("synthetic", synthetic_scan())]
    out = []
    for name, img in inputs:
        row = [_label(_fit(img, tile, cv2.INTER_AREA), name[:40])]
        try:
            leaves = phloem.leaves.extract(img)
        except ValueError as e:
            t = np.full((tile, tile, 3), 255, np.uint8)  # OpenCV 5 draws text on 8-bit only
            words, line, lines = str(e).split(), "", []
            for wd in words:
                if len(line) + len(wd) > 38:
                    lines.append(line)
                    line = ""
                line += wd + " "
            lines.append(line)
            for j, ln in enumerate(lines):
                cv2.putText(t, ln, (4, 30 + 14 * j), cv2.FONT_HERSHEY_SIMPLEX, 0.38, (150, 0, 0), 1, cv2.LINE_AA)
            row.append(t.astype(np.float32) / 255)
            leaves = []
        for k, leaf in enumerate(leaves[:per_image]):
            area = int((leaf[..., 3] > 0.5).sum())
            row.append(_label(_fit(over_checker(leaf), tile, cv2.INTER_AREA), f"#{k} {area} px"))
            if zoom:
                row.append(_label(close_up(leaf, tile), f"#{k} edge 4x"))
        width = 1 + per_image * (2 if zoom else 1)
        row += [np.ones((tile, tile, 3), np.float32)] * (width - len(row))
        out.append(row)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--tile", type=int, default=256)
    ap.add_argument("--per-image", type=int, default=6)
    ap.add_argument("--zoom", action="store_true")
    args = ap.parse_args(argv)
    write_sheet(rows(args.tile, args.per_image, args.zoom), args.out)
    print(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
