"""Layer induction (Assa & Cohen-Or §4, Eqs. 2–6) through the Python API.

The workload: a synthetic leaf on an ``N × N`` canvas (an ellipse with a midrib, side veins and
pale blotches of the veins' colour, mild noise), the veins as the user's layer, and one exemplar
(the same leaf under a smooth 1 % warp); ε, the vein width and the blotches scale with N. Each
call computes S on the training leaf and on the exemplar (two EMD maps) and then F, λ, δ, D; the
quick timing prints how much of it is the EMD maps.

Run for figures:   pytest benches/python/bench_leaves_induction.py --benchmark-enable --benchmark-only
Quick timing:      python benches/python/bench_leaves_induction.py [N]   (default 1448: 2 Mpx)
In the default test run the benchmark executes once (``--benchmark-disable``), at N = 512.
"""

from __future__ import annotations

import sys
import time
from typing import Any
from unittest import mock

import cv2
import numpy as np
import pytest

from phloem.leaves import color_distance, induce, induction

pytestmark = pytest.mark.filterwarnings("ignore::pytest_benchmark.logger.PytestBenchmarkWarning")

THREADS = 2


def workload(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    rng = np.random.default_rng(0)
    s = n / 160.0
    yy, xx = np.mgrid[:n, :n]
    leaf = ((yy - n / 2) / (n / 3.0)) ** 2 + ((xx - n / 2) / (n / 2.2)) ** 2 <= 1
    veins = np.zeros((n, n), np.uint8)
    cv2.line(veins, (int(12 * s), n // 2), (int(n - 12 * s), n // 2), 1, max(2, int(10 * s)))
    for x0 in (45, 80, 115):
        for sign in (-1, 1):
            end = (int((x0 + 22) * s), int(n // 2 + sign * 35 * s))
            cv2.line(veins, (int(x0 * s), n // 2), end, 1, max(2, int(8 * s)))
    blotches = np.zeros((n, n), np.uint8)
    for _ in range(10):
        centre = (int(rng.integers(n // 5, 4 * n // 5)), int(rng.integers(n // 4, 3 * n // 4)))
        cv2.circle(blotches, centre, int(7 * s), 1, -1)
    vein = veins.astype(bool) & leaf

    def render(v: np.ndarray) -> np.ndarray:
        img = np.zeros((n, n, 4), np.float32)
        img[leaf] = (0.25, 0.55, 0.15, 1.0)
        img[blotches.astype(bool) & leaf] = (0.80, 0.82, 0.45, 1.0)
        img[v] = (0.80, 0.82, 0.45, 1.0)
        img[..., :3] = np.clip(img[..., :3] + rng.normal(0, 0.02, (n, n, 3)), 0, 1)
        img[~leaf] = 0
        return img

    f = np.float32(0.01 * n)
    gx, gy = np.meshgrid(np.arange(n, dtype=np.float32), np.arange(n, dtype=np.float32))
    moved = cv2.remap(
        vein.astype(np.float32),
        gx + f * np.sin(2 * np.pi * gy / n),
        gy + f * np.cos(2 * np.pi * gx / n),
        cv2.INTER_LINEAR,
    )
    return render(vein), render((moved > 0.5) & leaf), vein, 10.0 * s


def test_induce_512(benchmark: Any) -> None:
    training, exemplar, vein, eps = workload(512)
    result = benchmark(induce, training, vein, [exemplar], epsilon=eps, threads=THREADS)
    assert result.masks[0].any() and 0.0 < result.objective <= 1.0


def overhead(
    training: np.ndarray, exemplar: np.ndarray, vein: np.ndarray, eps: float, threads: int
) -> tuple[float, float]:
    """(seconds of the two S maps, seconds of the rest of induce: F, λ, δ, D and the checks)."""
    t0 = time.perf_counter()
    maps = [
        color_distance(training, vein, threads=threads),
        color_distance(exemplar, vein, reference=training, threads=threads),
    ]
    emd = time.perf_counter() - t0

    def cached(image: np.ndarray, *args: Any, **kwargs: Any) -> np.ndarray:
        return maps[0] if np.array_equal(image, training) else maps[1]

    with mock.patch.object(induction, "color_distance", cached):
        t0 = time.perf_counter()
        induce(training, vein, [exemplar], epsilon=eps, threads=threads)
        rest = time.perf_counter() - t0
    return emd, rest


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 1448
    training, exemplar, vein, eps = workload(n)
    for threads in (1, 2):
        emd, rest = overhead(training, exemplar, vein, eps, threads)
        print(f"{threads} thread(s), {n}×{n}: the two S maps {emd:.2f} s, the rest of induce (F, λ, δ, D) {rest:.2f} s")
