"""The colour term S of layer induction (Assa & Cohen-Or, Eq. 1) through the Python API.

The issue's workload: a 2 Mpx leaf (the embedded bark photo resized to 1448 × 1448, a stand-in
with leaf-like colour variety), the layer a 200 × 300 block of it, 16-colour palette, 8 × 8
windows, 2 threads. The analysis of 4 leaves of 2 Mpx must take under 20 s on 2 cores, so one
map should take well under 2 s.

Run for figures:   pytest benches/python/bench_leaves_color.py --benchmark-enable --benchmark-only
Quick timing:      python benches/python/bench_leaves_color.py   (best of 3, 1 and 2 threads)
In the default test run the benchmark executes once (``--benchmark-disable``).
"""

from __future__ import annotations

import time
from typing import Any

import cv2
import numpy as np
import pytest

import phloem
from phloem.leaves import color_distance

pytestmark = pytest.mark.filterwarnings("ignore::pytest_benchmark.logger.PytestBenchmarkWarning")

N, THREADS = 1448, 2


def workload() -> tuple[np.ndarray, np.ndarray]:
    image = cv2.resize(phloem.data.bark()[..., :3], (N, N), interpolation=cv2.INTER_LINEAR)
    layer = np.zeros((N, N), bool)
    layer[600:800, 500:800] = True
    return np.ascontiguousarray(image, dtype=np.float32), layer


def test_color_distance_2mpx(benchmark: Any) -> None:
    image, layer = workload()
    s = benchmark(color_distance, image, layer, threads=THREADS)
    assert s.shape == (N, N) and np.isfinite(s).all()


if __name__ == "__main__":
    image, layer = workload()
    for threads in (1, 2):
        best = min(
            (lambda t0: (color_distance(image, layer, threads=threads), time.perf_counter() - t0)[1])(
                time.perf_counter()
            )
            for _ in range(3)
        )
        print(f"{threads} thread(s): {best:.3f} s per {N}×{N} map, {N * N / best / 1e6:.2f} Mpx/s")
