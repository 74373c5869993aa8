"""The user's layers from scribbles (lazy-snapping expansion) through the Python API.

The workload: leaf 0 of the shared scan ``leaves/leafarea_A300-1.jpeg`` with the committed
scribbles ``tests/data/leaves/leafarea_A300-1_scribbles.png`` (veins, spots, blade), both
scaled by 1.75 to a 2 Mpx canvas (1692 × 1192; the leaf about 1 Mpx of it). The scribbles are
expanded once per model, on the training leaf only; the whole analysis of 4 leaves of 2 Mpx must
fit 20 s on 2 cores. Skips when the shared data is absent.

Run for figures:   pytest benches/python/bench_leaves_scribbles.py --benchmark-enable --benchmark-only
Quick timing:      python benches/python/bench_leaves_scribbles.py   (best of 3)
In the default test run the benchmark executes once (``--benchmark-disable``).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

import phloem
from phloem.leaves import layers_from_scribbles, read_scribbles
from phloem.testing import shared_path

pytestmark = pytest.mark.filterwarnings("ignore::pytest_benchmark.logger.PytestBenchmarkWarning")

SCALE = 1.75
SCRIBBLES = Path(__file__).resolve().parents[2] / "tests" / "data" / "leaves" / "leafarea_A300-1_scribbles.png"


def workload() -> tuple[np.ndarray, np.ndarray]:
    scan = shared_path("leaves", "leafarea_A300-1.jpeg")
    if not scan.exists():
        pytest.skip(f"{scan} is not available")
    leaf = phloem.leaves.extract(phloem.io.read_image(scan))[0]
    labels, _ = read_scribbles(SCRIBBLES, leaf.shape)
    size = (round(leaf.shape[1] * SCALE), round(leaf.shape[0] * SCALE))
    big = cv2.resize(leaf, size, interpolation=cv2.INTER_LINEAR)
    return np.ascontiguousarray(big), cv2.resize(labels, size, interpolation=cv2.INTER_NEAREST)


def test_layers_from_scribbles_2mpx(benchmark: Any) -> None:
    leaf, scribbles = workload()
    got = benchmark(layers_from_scribbles, leaf, scribbles)
    assert got.shape == scribbles.shape and set(np.unique(got)) == {0, 1, 2, 3}


if __name__ == "__main__":
    leaf, scribbles = workload()
    best = min(
        (lambda t0: (layers_from_scribbles(leaf, scribbles), time.perf_counter() - t0)[1])(time.perf_counter())
        for _ in range(3)
    )
    h, w = scribbles.shape
    print(f"{best:.3f} s per {h}×{w} canvas ({int((leaf[..., 3] > 0.5).sum()) / 1e6:.2f} Mpx of leaf)")
