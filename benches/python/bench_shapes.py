"""Label-map synthesis (boundary-patch shape optimiser) on the embedded bark's label map.

Figures (best of N):  python benches/python/bench_shapes.py [--runs 3]
pytest-benchmark figures:  pytest benches/python/bench_shapes.py --benchmark-enable --benchmark-only
In the default test run every case executes once and checks each label keeps its area.

The exemplar is the embedded Douglas-fir bark (256²), blurred and clustered by k-means into
three labels, as the bark pipeline does; outputs are 256² and 512², layered and joint.
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np
import pytest

import phloem
from phloem import shapes

pytestmark = pytest.mark.filterwarnings("ignore::pytest_benchmark.logger.PytestBenchmarkWarning")

SIZES = [256, 512]


def bark_labels(k: int = 3) -> np.ndarray:
    """The embedded bark as a k-label map: Gaussian blur, k-means on RGB, labels by brightness."""
    img = phloem.data.bark()[..., :3]
    z = cv2.GaussianBlur(img, (0, 0), 2).reshape(-1, 3).astype(np.float32)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 20, 1e-3)
    cv2.setRNGSeed(0)
    _, lab, centres = cv2.kmeans(z, k, None, crit, 3, cv2.KMEANS_PP_CENTERS)
    rank = np.argsort(np.argsort(centres.sum(axis=1)))
    return rank[lab.reshape(img.shape[:2])].astype(np.int32)


@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("method", shapes.METHODS)
def test_label_map_synthesis(benchmark, method, size):
    lab = bark_labels()
    benchmark.extra_info["pixels"] = size * size
    out = benchmark(shapes.synthesize_labels, lab, size, method=method, seed=0)
    fa = np.bincount(lab.ravel()) / lab.size
    fo = np.bincount(out.ravel(), minlength=len(fa)) / out.size
    assert np.abs(fa - fo).max() < 0.03


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args()
    lab = bark_labels()
    print(f"{'size':>6} {'method':>8} {'best':>8} {'Mpx/s':>7} {'Eq. 3.9':>8}  (threads={args.threads or 'default'})")
    for size in SIZES:
        for method in shapes.METHODS:
            best, out = np.inf, None
            for _ in range(args.runs):
                t = time.perf_counter()
                out = shapes.synthesize_labels(lab, size, method=method, seed=0, threads=args.threads)
                best = min(best, time.perf_counter() - t)
            sim = shapes.shape_similarity(lab, out)
            print(f"{size:>5}² {method:>8} {best:>7.2f}s {size * size / best / 1e6:>7.3f} {sim:>8.3f}")


if __name__ == "__main__":
    main()
