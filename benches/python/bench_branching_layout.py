"""The gaps' layout (``phloem.branching.gaps._layout``): the input background's large-scale
brightness with its regions' edges, at a fundus photo's size.

The workload: a 1411² three-channel background with 30 % of it structure (left out), its
Gaussian layout at the relight's scale (an eighth of the side, 176 px) and the guided filter
that keeps its edges (``_with_edges``). ``render`` computes it once per photo for the relight,
and twice more with the spread fill.

Run for figures:   pytest benches/python/bench_branching_layout.py --benchmark-enable --benchmark-only
In the default test run the benchmark executes once (``--benchmark-disable``).

Measured on the 2-core box: 0.39 s for the layout (mean of 5), of which 0.27 s keeps the edges.
"""

from __future__ import annotations

import numpy as np
import pytest

from phloem.branching.gaps import _layout, _with_edges

pytestmark = pytest.mark.filterwarnings("ignore::pytest_benchmark.logger.PytestBenchmarkWarning")


def _background() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    source = rng.random((1411, 1411, 3)).astype(np.float32)
    allowed = rng.random((1411, 1411)) > 0.3
    return source, allowed


def test_bench_layout_fundus_size(benchmark):
    source, allowed = _background()
    out = benchmark(_layout, source, allowed, 176.0, (1411, 1411))
    assert out.shape == (1411, 1411, 3) and np.isfinite(out).all()


def test_bench_layout_edges_fundus_size(benchmark):
    source, allowed = _background()
    flat = np.full_like(source, 0.5)
    out = benchmark(_with_edges, flat, source, allowed, 176.0)
    # uniform noise has no edges: the layout stays within a few hundredths of flat
    assert out.shape == source.shape and float(np.abs(out - 0.5).max()) < 0.05
