"""Speed of the whole leaves pipeline: analysis of 4 leaves of 2 Mpx, then new 2 Mpx leaves.

Figures:  python benches/python/bench_leaves_pipeline.py [--megapixels 2] [--leaves 4] [--count 3] [--threads N]

The leaves are phloem.testing.layered_leaf (veins, spots, blade) drawn at the size asked for,
each variant a different leaf, one of them on its side; the scribbles are a few strokes per
layer. The issue's budgets: analysis under 20 s, each new leaf under 2 s, on 2 cores.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

import phloem
from phloem.testing import layered_leaf, scribbles_from


def leaf_set(megapixels: float, n: int) -> tuple[list[np.ndarray], np.ndarray]:
    w = int(math.sqrt(megapixels * 1e6 / 1.6))
    size = (int(1.6 * w), w)
    made = [layered_leaf(size, variant=v, seed=v) for v in range(n)]
    imgs = [m[0] for m in made]
    imgs[-1] = np.ascontiguousarray(np.rot90(imgs[-1]))
    return imgs, scribbles_from(made[0][1], strokes=12, seed=1)


def test_pipeline_once() -> None:
    imgs, sc = leaf_set(0.02, 2)
    model = phloem.leaves.analyze(imgs, sc, points=40, epsilon=10.0)
    assert len(phloem.leaves.synthesize(model, count=1)) == 1


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--megapixels", type=float, default=2.0)
    ap.add_argument("--leaves", type=int, default=4)
    ap.add_argument("--count", type=int, default=3)
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args()
    imgs, sc = leaf_set(args.megapixels, args.leaves)
    t0 = time.perf_counter()
    model = phloem.leaves.analyze(imgs, sc, threads=args.threads)
    t_an = time.perf_counter() - t0
    h, w = model.size
    print(f"analyze {args.leaves} leaves of {imgs[0].shape[0]}x{imgs[0].shape[1]} ({args.megapixels:g} Mpx), "
          f"canvas {w}x{h}: {t_an:.1f} s")  # fmt: skip
    times = []
    for i in range(args.count):
        t = time.perf_counter()
        new = phloem.leaves.synthesize(model, count=1, seed=i, threads=args.threads)[0]
        times.append(time.perf_counter() - t)
    print(f"synthesize: {np.median(times):.2f} s per leaf (median of {args.count}; "
          f"last {new.shape[1]}x{new.shape[0]})")  # fmt: skip


if __name__ == "__main__":
    main()
