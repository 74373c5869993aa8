"""Python-side benchmarks of the issue's workloads (pytest-benchmark).

Run for figures:   pytest benches/python/bench_patch.py --benchmark-enable --benchmark-only
In the default test run they execute once each (``--benchmark-disable``) as smoke tests.
Peer comparisons (PyPatchMatch, resynthesizer, texture-synthesis) live in ``peers.py``.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

import phloem

pytestmark = pytest.mark.filterwarnings("ignore::pytest_benchmark.logger.PytestBenchmarkWarning")


def _rgb512(img: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(cv2.resize(img[..., :3], (512, 512), interpolation=cv2.INTER_CUBIC).clip(0, 1))


@pytest.fixture(scope="module")
def pair() -> tuple[np.ndarray, np.ndarray]:
    from pathlib import Path

    water = phloem.io.read_image(Path(__file__).parents[2] / "tests" / "data" / "water.jpg")
    return _rgb512(phloem.data.bark()), _rgb512(water)


@pytest.mark.parametrize("threads", [1, 2])
def test_patchmatch_512(benchmark, pair, threads):
    src, tgt = pair
    benchmark.extra_info["pixels"] = 512 * 512
    field, _ = benchmark(phloem.patch.nnf, src, tgt, patch_size=7, iterations=5, threads=threads)
    assert field.shape == (512, 512, 2)


def test_kdtree_512(benchmark, pair):
    # The near-exact option (method="kdtree": PCA kd-tree seeding, then 5 PatchMatch passes).
    src, tgt = pair
    field, _ = benchmark(phloem.patch.nnf, src, tgt, patch_size=7, iterations=5, method="kdtree", threads=2)
    assert field.shape == (512, 512, 2)


@pytest.mark.parametrize("tileable", [False, True])
@pytest.mark.parametrize("job", ["synthesize", "quilt"])
def test_texture_512_from_256(benchmark, job, tileable):
    # tileable=True: the same job on a torus (wrapped search and votes, or blocks wrapping onto
    # the first ones); the row pair is its cost.
    ex = np.ascontiguousarray(phloem.data.bark()[..., :3])
    kwargs = {"threads": 2, "tileable": tileable}
    out = benchmark.pedantic(getattr(phloem.texture, job), args=(ex, (512, 512)), kwargs=kwargs, rounds=3)
    assert out.shape == (512, 512, 3)


@pytest.mark.parametrize("tileable", [False, True])
def test_complete_96_hole_in_512(benchmark, pair, tileable):
    img = pair[0]
    hole = np.zeros((512, 512), bool)
    hole[208:304, 208:304] = True
    kwargs = {"threads": 2, "tileable": tileable}
    out = benchmark.pedantic(phloem.texture.complete, args=(img, hole), kwargs=kwargs, rounds=3)
    assert np.array_equal(out[~hole], img[~hole])
