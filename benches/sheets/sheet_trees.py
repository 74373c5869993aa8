"""Contact sheet of the tree preprocessing: atlas -> split trees -> normalised trees with overlays.

    python -m benches.sheets.sheet_trees OUT.png [--per-atlas 5] [--tile 256]

Each row is one FlightGear atlas of ../shared/data/trees (skipped when absent; the CC0 VisiTrees
fir is used then): first the atlas over magenta with the boxes of the split trees, then a few of
its trees normalised to 1024 and shown at ``--tile`` px over grey, with the trunk mask tinted red,
the crown baseline in orange, the resampled contour C_r in cyan (crown) and yellow (trunk sides),
the simplified contour C_s in red and the pin points B, L, R as black dots with white rims.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

import phloem
from phloem import trees
from phloem.testing import shared_path

SHARED = shared_path("trees")
ATLASES = (
    "cerrado-trees",
    "coniferous",
    "deciduous-alt",
    "tropical-alt",
    "savanna-trees",
    "evergreen-mediterranean",
    "mojave-shrub",
)


def _over(rgba: np.ndarray, bg: tuple[float, float, float]) -> np.ndarray:
    a = rgba[..., 3:4]
    return rgba[..., :3] * a + np.asarray(bg, np.float32) * (1 - a)


def atlas_tile(atlas: np.ndarray, tile: int) -> np.ndarray:
    """The atlas over magenta with a green box around each split tree (boxes found again by matching crops)."""
    img = (_over(atlas, (1.0, 0.0, 1.0)) * 255).astype(np.uint8)[..., ::-1].copy()
    opaque = (atlas[..., 3] >= 0.5).astype(np.uint8)
    pieces = trees.split_atlas(atlas)
    # Re-run the X-Y cut's boxes cheaply: bounding boxes of the pieces are found by template position.
    for p in pieces:
        m = (p[..., 3] >= 0.5).astype(np.float32)
        res = cv2.matchTemplate(opaque.astype(np.float32), m, cv2.TM_SQDIFF)
        _, _, (x, y), _ = cv2.minMaxLoc(res)
        cv2.rectangle(img, (x, y), (x + p.shape[1] - 1, y + p.shape[0] - 1), (0, 200, 0), 1)
    s = tile / max(img.shape[:2])
    img = cv2.resize(img, (round(img.shape[1] * s), round(img.shape[0] * s)), interpolation=cv2.INTER_AREA)
    out = np.full((tile, tile, 3), 255, np.uint8)
    out[: img.shape[0], : img.shape[1]] = img
    cv2.putText(out, f"{len(pieces)} trees", (4, tile - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1)
    return out


def tree_tile(rgba: np.ndarray, tile: int) -> np.ndarray:
    """A tree normalised to 1024, preprocessed, drawn at ``tile`` px with its overlays."""
    t = trees.prepare(rgba)
    s = tile / t.image.shape[0]
    base = _over(t.image, (0.75, 0.75, 0.75))
    base[t.trunk] = 0.5 * base[t.trunk] + 0.5 * np.array([1.0, 0.0, 0.0], np.float32)
    img = cv2.resize((base * 255).astype(np.uint8)[..., ::-1], (tile, tile), interpolation=cv2.INTER_AREA).copy()
    rows = np.flatnonzero(t.trunk.any(axis=1))
    if rows.size:
        y = round((rows[0] - 0.5) * s)
        cv2.line(img, (0, y), (tile - 1, y), (0, 140, 255), 1)
    sh = 4
    k = 1 << sh

    def poly(pts: np.ndarray, colour: tuple[int, int, int], closed: bool) -> None:
        q = np.round((pts + 0.5) * s * k).astype(np.int32)
        cv2.polylines(img, [q], closed, colour, 1, cv2.LINE_AA, sh)

    cr, n0 = t.resampled, t.split[0]
    poly(cr[: n0 + 1], (255, 255, 0), False)
    poly(np.vstack([cr[n0:], cr[:1]]), (0, 255, 255), False)
    poly(t.simplified, (0, 0, 255), True)
    for i in t.pins:
        x, y = ((t.contour[i] + 0.5) * s).round().astype(int)
        cv2.circle(img, (int(x), int(y)), 4, (255, 255, 255), -1)
        cv2.circle(img, (int(x), int(y)), 3, (0, 0, 0), -1)
    return img


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--per-atlas", type=int, default=5)
    ap.add_argument("--tile", type=int, default=256)
    args = ap.parse_args(argv)
    rows = []
    if SHARED.exists():
        for name in ATLASES:
            atlas = phloem.io.read_image(SHARED / f"flightgear_atlas_{name}.png")
            pieces = trees.split_atlas(atlas)
            # FlightGear atlases hold 4 variants (rows) of each species (column): walk a diagonal
            # so that the picks show different species.
            n, cols = len(pieces), max(1, len(pieces) // 4)
            picks = [((j % 4) * cols + j * max(1, cols // args.per_atlas)) % n for j in range(args.per_atlas)]
            row = [atlas_tile(atlas, args.tile)] + [tree_tile(pieces[i], args.tile) for i in picks]
            rows.append(np.hstack(row))
            print(f"{name}: {len(pieces)} trees", file=sys.stderr)
    else:
        print(f"{SHARED} not found; no atlases on the sheet", file=sys.stderr)
    sheet = np.vstack(rows) if rows else np.zeros((args.tile, args.tile, 3), np.uint8)
    cv2.imwrite(str(args.out), sheet)
    print(f"wrote {args.out} ({sheet.shape[1]}x{sheet.shape[0]})", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
