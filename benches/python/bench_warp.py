"""Mean value coordinate warps (Argudo et al. 2017, §5.2) through the Python API (pytest-benchmark).

The issue's workload: a 1024² RGBA variation filled from one or two 1024² sources (the embedded
bark photo and tests/data/water.jpg, resized, opaque), contours of M = 100 points (the paper's
simplified contour; concave, tree-crown-like), 2 threads. The paper reports 8–12 s per variation;
the goal is under 0.1 s for two sources.

Run for figures:   pytest benches/python/bench_warp.py --benchmark-enable --benchmark-only
Quick timing:      python benches/python/bench_warp.py   (best of 7, 2 threads)
In the default test run the benchmarks execute once each (``--benchmark-disable``).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

import phloem

pytestmark = pytest.mark.filterwarnings("ignore::pytest_benchmark.logger.PytestBenchmarkWarning")

N, M, THREADS = 1024, 100, 2


def crown(phase: float) -> np.ndarray:
    a = 2 * np.pi * np.arange(M) / M
    r = N * (0.36 + 0.06 * np.sin(7 * a + phase) + 0.03 * np.cos(13 * a))
    return np.stack([N / 2 + r * np.cos(a), N / 2 + r * np.sin(a)], axis=1)


def workload() -> dict[str, Any]:
    water = phloem.io.read_image(Path(__file__).parents[2] / "tests" / "data" / "water.jpg")[..., :3]
    bark = phloem.data.bark()[..., :3]
    srcs = []
    for img in (bark, water):
        rgb = cv2.resize(img, (N, N), interpolation=cv2.INTER_CUBIC).clip(0, 1)
        srcs.append(np.ascontiguousarray(np.dstack([rgb, np.ones((N, N), np.float32)]), np.float32))
    return {"images": srcs, "contours": [crown(0.0), crown(1.3)], "target": crown(0.6)}


@pytest.fixture(scope="module")
def job() -> dict[str, Any]:
    return workload()


def one(j: dict[str, Any]) -> np.ndarray:
    return phloem.warp.mvc(j["images"][0], j["contours"][0], j["target"], threads=THREADS)


def two(j: dict[str, Any]) -> np.ndarray:
    return phloem.warp.mvc_combine(j["images"], j["contours"], j["target"], [0.4, 0.6], N, threads=THREADS)


def test_one_source(benchmark: Any, job: dict[str, Any]) -> None:
    out = benchmark(one, job)
    assert out.shape == (N, N, 4)


def test_two_sources_combined(benchmark: Any, job: dict[str, Any]) -> None:
    out = benchmark(two, job)
    assert out.shape == (N, N, 4)


if __name__ == "__main__":
    j = workload()
    for name, f in (("one source", one), ("two sources combined", two)):
        f(j)
        times = []
        for _ in range(7):
            t = time.perf_counter()
            f(j)
            times.append(time.perf_counter() - t)
        print(
            f"{name}: {N}x{N} RGBA, M={M}, {THREADS} threads: best {min(times) * 1e3:.1f} ms, median {np.median(times) * 1e3:.1f} ms"
        )
