"""The whole bark pipeline, photo to texture, stage by stage (pytest-benchmark), and a table.

The issue's workload: from a bark photo to a 512×512 bark texture (goal: under 5 s on 2 cores),
with the embedded Douglas-fir photo (256²) and, when ``../shared/data`` exists, the thesis'
``bark1`` photo (263×324).

Run for figures:   pytest benches/python/bench_bark.py --benchmark-enable --benchmark-only
Stage table:       python benches/python/bench_bark.py [--runs N] [--size 512]
In the default test run the benchmarks execute once each (``--benchmark-disable``).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pytest

import phloem
from phloem import bark
from phloem.testing import shared_path

pytestmark = pytest.mark.filterwarnings("ignore::pytest_benchmark.logger.PytestBenchmarkWarning")

SHARED = shared_path("bark")


def photos() -> dict[str, np.ndarray]:
    out = {"douglas_fir": phloem.data.bark()[..., :3].copy()}
    p = SHARED / "thesis_runs" / "bark1" / "ai.png"
    if p.exists():
        out["bark1"] = phloem.io.read_image(p)[..., :3].copy()
    return out


@pytest.mark.parametrize("name", ["douglas_fir"])
def test_bench_generate_512(benchmark, name):
    photo = photos()[name]
    out = benchmark(lambda: bark.generate(photo, 512, seed=1))
    assert out.shape == (512, 512, 3)


def stage_times(photo: np.ndarray, size: int, seed: int) -> dict[str, float]:
    t = {}
    t0 = time.perf_counter()
    lab_in = bark.input_labels(photo, 2, seed=seed)
    t["input labels"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    lab_out = bark.synthesize_labels(lab_in, size, seed=seed)
    t["label map"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    phloem.texture.by_numbers(photo, lab_in, lab_out, seed=seed)
    t["by numbers"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    bark.generate(photo, size, seed=seed)
    t["whole pipeline"] = time.perf_counter() - t0
    return t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--size", type=int, default=512)
    args = ap.parse_args()
    print(f"photo -> {args.size}x{args.size} bark, best of {args.runs}, threads {phloem._core.default_threads()}")
    for name, photo in photos().items():
        best: dict[str, float] = {}
        for r in range(args.runs):
            for k, v in stage_times(photo, args.size, seed=r).items():
                best[k] = min(best.get(k, np.inf), v)
        px = args.size * args.size
        cells = ", ".join(f"{k} {v:.2f} s" for k, v in best.items())
        print(f"{name} {photo.shape[1]}x{photo.shape[0]}: {cells}; {px / best['whole pipeline'] / 1e3:.0f} kpx/s")


if __name__ == "__main__":
    main()
