"""Texture correction (Assa & Cohen-Or §3, after Fang & Hart 2007) through the Python API.

The workload: a 2 Mpx RGBA leaf (the embedded bark photo tiled over a 1414 × 1414 canvas, cut
to an ellipse), warped by a smooth horizontal stretch (slope 0.6, i.e. texture ×1.67) over the
middle fifth of the canvas, which leaves about 14 % of the canvas (290 000 leaf pixels) to
correct; 2 threads. Synthesis must make each new 2 Mpx leaf in under 2 s, correction included.

Run for figures:   pytest benches/python/bench_leaves_correction.py --benchmark-enable --benchmark-only
Quick timing:      python benches/python/bench_leaves_correction.py   (best of 3, 1 and 2 threads)
In the default test run the benchmark executes once (``--benchmark-disable``).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pytest

import phloem
from phloem import _core
from phloem.leaves import correct_texture, distortion

pytestmark = pytest.mark.filterwarnings("ignore::pytest_benchmark.logger.PytestBenchmarkWarning")

N, THREADS = 1414, 2


def _stretch(n: int, a: int, b: int, slope: float, ramp: int) -> np.ndarray:
    """Displacement whose map ``x ↦ x + d(x)`` has ``slope`` on [a, b] and 1 away from it."""
    x = np.arange(n, dtype=np.float64)
    t = np.clip((x - a) / ramp, 0, 1) * np.clip((b - x) / ramp, 0, 1)
    s = 1 - (1 - slope) * t
    phi = np.concatenate([[0.0], np.cumsum(0.5 * (s[1:] + s[:-1]))])
    return phi + (n / 2 - phi[n // 2]) - x


def workload() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    bark = phloem.data.bark()[..., :3]
    reps = N // bark.shape[0] + 1
    source = np.zeros((N, N, 4), np.float32)
    source[..., :3] = np.tile(bark, (reps, reps, 1))[:N, :N]
    yy, xx = np.mgrid[:N, :N]
    source[..., 3] = ((yy - N / 2) / (0.48 * N)) ** 2 + ((xx - N / 2) / (0.3 * N)) ** 2 <= 1
    field = np.zeros((N, N, 2), np.float32)
    field[..., 0] = _stretch(N, int(0.4 * N), int(0.6 * N), 0.6, N // 20)[None]
    return _core.tps_sample(source, field, threads=None), source, field


def test_correct_texture_2mpx(benchmark: Any) -> None:
    warped, source, field = workload()
    out = benchmark(correct_texture, warped, source, field, threads=THREADS)
    moved = distortion(field) & (warped[..., 3] > 0.5)
    assert moved.mean() > 0.1 and np.array_equal(out[~moved], warped[~moved])


if __name__ == "__main__":
    warped, source, field = workload()
    moved = distortion(field) & (warped[..., 3] > 0.5)
    print(f"{int(moved.sum())} pixels to correct ({moved.mean():.1%} of {N}×{N})")
    for threads in (1, 2):
        best = min(
            (lambda t0: (correct_texture(warped, source, field, threads=threads), time.perf_counter() - t0)[1])(
                time.perf_counter()
            )
            for _ in range(3)
        )
        print(f"{threads} thread(s): {best:.3f} s per {N}×{N} leaf, {moved.sum() / best / 1e6:.2f} Mpx corrected/s")
