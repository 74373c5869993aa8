"""Synthesis (Assa & Cohen-Or §5) through the Python API.

The issue's workload: a model of 4 exemplars on a 2 Mpx canvas (1448 × 1448) with a vein and
a spot layer besides the background (the exemplars the embedded bark photo cut to ellipses of
different sizes, the registration fields the exact scalings between them), 2 threads. Each
new leaf must take under 2 s.

Run for figures:   pytest benches/python/bench_leaves_synthesis.py --benchmark-enable --benchmark-only
Quick timing:      python benches/python/bench_leaves_synthesis.py   (best of 3, 1 and 2 threads)
In the default test run the benchmark executes once (``--benchmark-disable``).
"""

from __future__ import annotations

import time
from typing import Any

import cv2
import numpy as np
import pytest
from scipy import ndimage

import phloem
from phloem.leaves import LeafModel, synthesize

pytestmark = pytest.mark.filterwarnings("ignore::pytest_benchmark.logger.PytestBenchmarkWarning")

N, THREADS, SCALES = 1448, 2, (1.0, 0.9, 1.1, 0.95)


def workload() -> LeafModel:
    photo = cv2.resize(phloem.data.bark()[..., :3], (N, N), interpolation=cv2.INTER_LINEAR).astype(np.float32)
    yy, xx = np.mgrid[0:N, 0:N].astype(np.float32)
    c = N / 2
    rel = np.stack([xx - c, yy - c], axis=2)

    def rgba(alpha: np.ndarray, shift: int) -> np.ndarray:
        return np.concatenate([np.roll(photo, shift, axis=1), alpha[..., None]], axis=2).astype(np.float32)

    def ellipse(s: float) -> np.ndarray:
        return (np.hypot((xx - c) / (0.4 * N * s), (yy - c) / (0.25 * N * s)) < 1).astype(np.float32)

    train = ellipse(1.0)
    layers, diss, masks = [], [], []
    for i in range(len(SCALES)):
        vein = (np.abs(yy - c - 3 * i) < 6) | (np.abs(xx - c - 40 * np.sin(yy / 200 + i)) < 5)
        rng = np.random.default_rng(i)
        spots = np.zeros((N, N), bool)
        for cy, cx in rng.integers(int(0.3 * N), int(0.7 * N), (40, 2)):
            spots[max(cy - 12, 0) : cy + 12, max(cx - 12, 0) : cx + 12] = True
        per_mask = [vein & (train > 0), spots & (train > 0)]
        masks.append(per_mask)
        layers.append([rgba(m.astype(np.float32), 5 * i) for m in per_mask])
        diss.append([(ndimage.distance_transform_edt(~m) / 40).astype(np.float32) for m in per_mask])
    return LeafModel(
        training=0,
        order=[1, 2, 3],
        leaves=[rgba(ellipse(s), 5 * i) for i, s in enumerate(SCALES)],
        forward=[((s - 1) * rel).astype(np.float32) for s in SCALES],
        inverse=[((1 / s - 1) * rel).astype(np.float32) for s in SCALES],
        residual=[0.0, 6.0, 8.0, 5.0],
        aligned=[rgba(train, 5 * i) for i in range(len(SCALES))],
        masks=masks,
        dissimilarity=diss,
        layers=layers,
        background=[rgba(train, 7 * i) for i in range(len(SCALES))],
        lam=[1.2, 0.2],
        delta=[0.3, 0.3],
        objective=[0.8, 0.7],
    )


def test_synthesize_2mpx(benchmark: Any) -> None:
    model = workload()
    leaves = benchmark(synthesize, model, count=1, threads=THREADS)
    assert len(leaves) == 1 and leaves[0].shape[2] == 4


if __name__ == "__main__":
    model = workload()
    for threads in (1, 2):
        best = min(
            (lambda t0: (synthesize(model, count=1, seed=k, threads=threads), time.perf_counter() - t0)[1])(
                time.perf_counter()
            )
            for k in range(3)
        )
        print(f"{threads} thread(s): {best:.3f} s per new leaf on a {N}×{N} canvas")
