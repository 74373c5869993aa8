"""Speed of phloem.leaves.extract on a 2 Mpx synthetic scan (four leaves with petioles on paper).

Figures:  python benches/python/bench_leaves_extract.py [--runs 5]
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

import phloem


def scan(h: int = 1414, w: int = 1414, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = np.full((h, w, 3), 0.94, np.float32)
    for i in range(4):
        cx = 200 + 340 * i
        cv2.ellipse(img, (cx, 600), (120, 400), 0, 0, 360, (0.2, 0.45, 0.15), -1)
        cv2.line(img, (cx, 990), (cx + 20, 1200), (0.4, 0.3, 0.1), 3)
    img += rng.normal(0, 0.015, img.shape).astype(np.float32)
    return np.clip(img, 0, 1)


def test_extract_once() -> None:
    assert len(phloem.leaves.extract(scan(400, 400))) >= 1


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    img = scan()
    best = float("inf")
    for _ in range(args.runs):
        t = time.perf_counter()
        leaves = phloem.leaves.extract(img)
        best = min(best, time.perf_counter() - t)
    print(
        f"extract {img.shape[1]}x{img.shape[0]} ({img.shape[0] * img.shape[1] / 1e6:.1f} Mpx), {len(leaves)} leaves: {best * 1e3:.0f} ms (best of {args.runs})"
    )


if __name__ == "__main__":
    main()
