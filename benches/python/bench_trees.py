"""Tree exemplar preprocessing at 1024 (Argudo et al. 2017 §4), stage by stage (pytest-benchmark), and a table.

The workload: one exemplar from RGBA cut-out to a :class:`phloem.trees.Tree` (normalise to
1024², segment, contour, pins, 2000-point resampling, 100-point simplified contour). A synthetic
tree with a ragged crown always runs; with ``../shared/data`` the table adds FlightGear trees.

Run for figures:   pytest benches/python/bench_trees.py --benchmark-enable --benchmark-only
Stage table:       python benches/python/bench_trees.py [--runs N] [--size 1024]
In the default test run the benchmark executes once (``--benchmark-disable``).
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np
import pytest

import phloem
from phloem import trees
from phloem.testing import shared_path

pytestmark = pytest.mark.filterwarnings("ignore::pytest_benchmark.logger.PytestBenchmarkWarning")

SHARED = shared_path("trees")


def synthetic_tree(seed: int = 0) -> np.ndarray:
    """A 400x300 RGBA tree: a ragged crown of random disks over a tapering trunk."""
    rng = np.random.default_rng(seed)
    img = np.zeros((400, 300, 4), np.float32)
    cv2.fillPoly(img, [np.array([[140, 395], [160, 395], [156, 180], [144, 180]], np.int32)], (0.4, 0.3, 0.2, 1.0))
    for _ in range(300):
        x, y = rng.normal((150, 130), (45, 40))
        cv2.circle(img, (int(x), int(y)), int(rng.integers(3, 12)), (0.1, float(rng.uniform(0.4, 0.7)), 0.1, 1.0), -1)
    return img


def exemplars() -> dict[str, np.ndarray]:
    out = {"synthetic": synthetic_tree()}
    for name, i in (("cerrado-trees", 3), ("caatinga-trees", 2), ("coniferous", 0)):
        p = SHARED / f"flightgear_atlas_{name}.png"
        if p.exists():
            out[f"{name}[{i}]"] = trees.split_atlas(phloem.io.read_image(p))[i]
    return out


def test_bench_prepare_1024(benchmark):
    img = synthetic_tree()
    tree = benchmark(lambda: trees.prepare(img))
    assert tree.resampled.shape == (2000, 2)


def stage_times(img: np.ndarray, size: int) -> dict[str, float]:
    t: dict[str, float] = {}
    t0 = time.perf_counter()
    norm = trees.normalize(img, size=size)
    t["normalize"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    trunk = trees.segment(norm)
    t["segment"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    c = trees.contour(norm)
    pins = trees.pin_points(c, trunk)
    t["contour+pins"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    cr = trees.resample(c, pins)
    t["resample"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    interior = np.zeros(norm.shape[:2], np.uint8)
    cv2.fillPoly(interior, [np.round(cr).astype(np.int32)], 1)
    trees.simplify(interior > 0)
    t["simplify"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    trees.prepare(img, size=size)
    t["prepare (all)"] = time.perf_counter() - t0
    return t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--size", type=int, default=1024)
    args = ap.parse_args()
    rows = []
    for name, img in exemplars().items():
        runs = [stage_times(img, args.size) for _ in range(args.runs)]
        best = {k: min(r[k] for r in runs) for k in runs[0]}
        rows.append((name, best, len(trees.contour(trees.normalize(img, size=args.size)))))
    keys = list(rows[0][1])
    print(
        f"{'exemplar':<20} {'contour pts':>11} "
        + " ".join(f"{k:>13}" for k in keys)
        + f"   (seconds, best of {args.runs})"
    )
    for name, best, n in rows:
        print(f"{name:<20} {n:>11} " + " ".join(f"{best[k]:>13.3f}" for k in keys))


if __name__ == "__main__":
    main()
