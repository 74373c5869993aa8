"""Automatic skeleton tracing (phloem.branching.trace) on a synthetic tree and the real branching images.

The workload: :func:`phloem.branching.trace` from image to skeleton (ridge filter or mask,
skeletonisation, spanning forest, longest-path decomposition). A synthetic 1024² binary tree
always runs; with ``../shared/data/branching`` the table adds the real images with the arguments
the contact sheet (``benches/sheets/sheet_branching_trace.py``) uses.

Run for figures:   pytest benches/python/bench_branching_trace.py --benchmark-enable --benchmark-only
Table:             python benches/python/bench_branching_trace.py [--runs N] [--subpixel]
In the default test run the benchmark executes once (``--benchmark-disable``).
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import cv2
import numpy as np
import pytest

import phloem
from phloem.branching import trace
from phloem.testing import TRACE_SETTINGS as CASES
from phloem.testing import shared_path

pytestmark = pytest.mark.filterwarnings("ignore::pytest_benchmark.logger.PytestBenchmarkWarning")

SHARED = shared_path("branching")


def synthetic_tree(size: int = 1024, depth: int = 7, seed: int = 0) -> np.ndarray:
    """A binary tree mask: every branch forks in two, thinner and shorter each level."""
    rng = np.random.default_rng(seed)
    m = np.zeros((size, size), np.uint8)

    def grow(x: float, y: float, ang: float, length: float, width: float, level: int) -> None:
        x2, y2 = x + length * np.cos(ang), y - length * np.sin(ang)
        cv2.line(m, (int(x), int(y)), (int(x2), int(y2)), 1, max(1, int(width)))
        if level < depth:
            for s in (-1, 1):
                grow(x2, y2, ang + s * rng.uniform(0.3, 0.6), length * 0.72, width * 0.75, level + 1)

    grow(size / 2, size - 10, np.pi / 2, size / 4.5, 18, 0)
    return m


def test_bench_trace_synthetic_1024(benchmark):
    m = synthetic_tree()
    sk = benchmark(lambda: trace(m, kind="mask"))
    assert len(sk.branches) > 50


def test_bench_threshold_climb_grain_1024(benchmark):
    # render's default gap_diversity asks this of every photo: one ridge filtering and the climb
    from phloem.branching import threshold_climb

    rng = np.random.default_rng(0)
    grain = cv2.GaussianBlur(rng.normal(0.5, 0.1, (1024, 1024)).astype(np.float32), (0, 0), 0.7)
    assert benchmark(lambda: threshold_climb(grain, kind="dark")) > 1.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--subpixel", action="store_true", help="trace the photos with subpixel=True")
    args = ap.parse_args()
    images: dict[str, tuple[np.ndarray, dict[str, Any]]] = {
        "synthetic tree 1024²": (synthetic_tree(), {"kind": "mask"})
    }
    for name, kw in CASES.items():
        p = SHARED / name
        if p.exists():
            extra = {"subpixel": True} if args.subpixel and kw.get("kind") != "mask" else {}
            images[name] = (phloem.io.read_image(p), {**kw, **extra})
    print(f"{'image':<40} {'size':>11} {'branches':>8} {'length px':>10} {'seconds':>8}   (best of {args.runs})")
    for name, (img, kw) in images.items():
        times = []
        for _ in range(args.runs):
            t0 = time.perf_counter()
            sk = trace(img, **kw)
            times.append(time.perf_counter() - t0)
        size = f"{img.shape[1]}x{img.shape[0]}"
        print(f"{name:<40} {size:>11} {len(sk.branches):>8} {sk.total_length():>10.0f} {min(times):>8.3f}")


if __name__ == "__main__":
    main()
