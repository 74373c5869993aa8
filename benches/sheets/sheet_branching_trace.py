"""Contact sheet of automatic skeleton tracing on the real branching images.

    python -m benches.sheets.sheet_branching_trace --out OUT.png [--tile 640]

Each tile is one image of ../shared/data/branching (skipped when absent) with the traced skeleton
drawn over it: root branches in red, children in yellow, grandchildren and deeper in cyan, and
the outline of the structure as the traced radii describe it in green. The
tile caption gives the image name, branch count, total length and the trace time.
"""

from __future__ import annotations

import argparse
import sys
import time

import cv2
import numpy as np

import phloem
from phloem.branching import Branch, Skeleton, trace
from phloem.testing import TRACE_SETTINGS as CASES
from phloem.testing import shared_path

SHARED = shared_path("branching")


def depth(sk: Skeleton) -> list[int]:
    d: list[int] = []
    for b in sk.branches:
        d.append(0 if b.parent is None else d[b.parent[0]] + 1)
    return d


def overlay(img: np.ndarray, sk: Skeleton, width: int) -> np.ndarray:
    gray = img[..., :3].mean(axis=2) if img.ndim == 3 else img
    gray = (gray - gray.min()) / max(float(gray.max() - gray.min()), 1e-9)
    canvas = np.repeat((0.25 + 0.6 * gray)[..., None], 3, axis=2).astype(np.float32)
    # the thickness: outline of the skeleton drawn with its radii, in green
    cnt, _ = cv2.findContours(sk.mask().astype(np.uint8), cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(canvas, cnt, -1, (0.1, 0.8, 0.2), width)
    colors = [(1.0, 0.1, 0.1), (1.0, 0.9, 0.0), (0.0, 0.9, 1.0)]
    d = depth(sk)
    for level in range(3):
        sel = [Branch(b.points, b.thickness) for b, k in zip(sk.branches, d) if min(k, 2) == level]
        if sel:
            canvas = Skeleton(sel).draw(canvas, color=colors[level], width=width)
    return canvas


def tile(img: np.ndarray, size: int, caption: str) -> np.ndarray:
    s = size / max(img.shape[:2])
    small = cv2.resize(
        img, (max(1, round(img.shape[1] * s)), max(1, round(img.shape[0] * s))), interpolation=cv2.INTER_AREA
    )
    out = np.zeros((size + 24, size, 3), np.uint8)
    out[24 : 24 + small.shape[0], : small.shape[1]] = (np.clip(small, 0, 1) * 255).astype(np.uint8)
    cv2.putText(out, caption, (4, 17), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="PNG to write")
    ap.add_argument("--tile", type=int, default=640, help="tile size in px")
    ap.add_argument("--only", default=None, help="trace only images whose name contains this")
    args = ap.parse_args(argv)
    tiles = []
    for name, kw in CASES.items():
        p = SHARED / name
        if not p.exists() or (args.only and args.only not in name):
            continue
        img = phloem.io.read_image(p)
        t0 = time.perf_counter()
        sk = trace(img, **kw)
        dt = time.perf_counter() - t0
        width = max(1, round(max(img.shape[:2]) / args.tile))
        cap = f"{name[:28]}: {len(sk.branches)} br, {sk.total_length():.0f} px, {dt:.2f} s"
        print(cap)
        tiles.append(tile(overlay(img, sk, width), args.tile, cap))
    if not tiles:
        print(f"no images in {SHARED}", file=sys.stderr)
        return 1
    cols = min(3, len(tiles))
    rows = [
        np.hstack(tiles[i : i + cols] + [np.zeros_like(tiles[0])] * (cols - len(tiles[i : i + cols])))
        for i in range(0, len(tiles), cols)
    ]
    sheet = np.vstack(rows)
    cv2.imwrite(args.out, sheet[..., ::-1])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
