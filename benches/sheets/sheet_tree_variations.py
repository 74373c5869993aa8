"""Contact sheet of tree variations (Argudo et al. 2017 §5) from the FlightGear library.

    python -m benches.sheets.sheet_tree_variations OUT.png [--size 512] [--tile 160] [--count 16]

Top: the paper's combination tables for six exemplars from different atlases: Fig. 13 (the
combined contours as silhouettes, weights 2/3 row + 1/3 column below the diagonal and 1/3 + 2/3
above it) beside Fig. 14 (the row tree's colours warped into that contour). Then ``--count``
random two-source variations (Fig. 16), then variations of one tree (weight 0.6-0.9 on it, §3),
then the first variations again with histogram transfer to another exemplar (§5.3).
Needs ../shared/data/trees (the atlases are GPL and stay there).
"""

from __future__ import annotations

import argparse
import sys

import cv2
import numpy as np

import phloem
from phloem import trees
from phloem.testing import shared_path

SHARED = shared_path("trees")
PICKS = [
    ("deciduous-alt", 2),
    ("coniferous", 0),
    ("cerrado-trees", 0),
    ("tropical", 1),
    ("evergreen-mediterranean", 2),
    ("savanna-trees", 1),
]
MORE = ["mixed", "deciduous", "caatinga-trees"]


def row(images: list[np.ndarray], tile: int, width: int) -> np.ndarray:
    out = np.full((tile, width, 3), 0.8, np.float32)
    for c, im in enumerate(images[: width // tile]):
        small = cv2.resize(im, (tile, tile), interpolation=cv2.INTER_AREA)
        a = small[..., 3:4]
        out[:, c * tile : (c + 1) * tile] = small[..., :3] * a + 0.8 * (1 - a)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--tile", type=int, default=160)
    ap.add_argument("--count", type=int, default=14)
    args = ap.parse_args()
    if not SHARED.exists():
        print(f"{SHARED} is missing: this sheet needs the FlightGear atlases", file=sys.stderr)
        return 1
    atlases = {}

    def pieces(name: str) -> list[np.ndarray]:
        if name not in atlases:
            atlases[name] = trees.split_atlas(phloem.io.read_image(SHARED / f"flightgear_atlas_{name}.png"))
        return atlases[name]

    imgs = [pieces(a)[i] for a, i in PICKS]
    names = [f"{a}[{i}]" for a, i in PICKS]
    for a in MORE:
        for i, p in enumerate(pieces(a)[:4]):
            imgs.append(p)
            names.append(f"{a}[{i}]")
    lib = trees.Library.from_images(imgs, names=names, size=args.size)
    tables = np.concatenate(
        [
            trees.morph_table(lib.trees[:6], tile=args.tile, colors=False),
            trees.morph_table(lib.trees[:6], tile=args.tile),
        ],
        axis=1,
    )
    width = tables.shape[1]
    per = width // args.tile
    variations = [trees.variation(lib, seed=s) for s in range(args.count)]
    for s, v in enumerate(variations):
        print(f"variation {s}: {v.describe(lib)}")
    mine = lib.trees[2]
    others = trees.Library(lib.trees[:2] + lib.trees[3:], lib.names[:2] + lib.names[3:])
    like = trees.vary(mine, others, n_variations=per - 1, seed=3)
    hist = [trees.variation(lib, seed=s, histogram=True) for s in range(per)]
    rows = [tables]
    for r in range(0, len(variations), per):
        rows.append(row([v.image for v in variations[r : r + per]], args.tile, width))
    rows.append(row([mine.image] + [v.image for v in like], args.tile, width))
    rows.append(row([v.image for v in hist], args.tile, width))
    phloem.io.write_image(args.out, np.concatenate(rows, axis=0), overwrite=True)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
