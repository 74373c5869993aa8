"""Structure synthesis for branching structures (Sibbing et al. 2010 §4): SVM training and growth.

The workload: a synthetic example structure (``phloem.branching.synthetic_skeleton``, several
random-walk trees side by side, step h = 2 px); fit the bending model and the furcation
model (linear SVM; the paper reports "about one minute" of training), then grow a structure of
about 500 nodes in a 512x512 image with space colonisation, three generations.

Run for figures:   pytest benches/bench_branching_structure.py --benchmark-enable --benchmark-only
Table:             python benches/bench_branching_structure.py [--runs N] [--trees T] [--nodes N]
In the default test run the benchmark executes once (``--benchmark-disable``).
"""

from __future__ import annotations

import argparse
import time

import pytest
from phloem.branching import BendingModel, Branch, FurcationModel, Skeleton, grow, synthetic_skeleton

pytestmark = pytest.mark.filterwarnings("ignore::pytest_benchmark.logger.PytestBenchmarkWarning")

H = 2.0


def example(trees: int = 4, seed: int = 0) -> Skeleton:
    """``trees`` synthetic structures stacked vertically in one skeleton."""
    out: list[Branch] = []
    y0 = 0.0
    width = 0
    for i in range(trees):
        part = synthetic_skeleton(seed + i, length=260.0, h=H)
        base = len(out)
        for b in part.branches:
            parent = None if b.parent is None else (b.parent[0] + base, b.parent[1])
            out.append(Branch(b.points + [0.0, y0], b.thickness, parent))
        assert part.shape is not None
        y0 += part.shape[0]
        width = max(width, part.shape[1])
    return Skeleton(out, (int(y0) + 1, width))


def grow_nodes(bending: BendingModel, furcation: FurcationModel, nodes: int, seed: int = 0) -> Skeleton:
    # total length (nodes - 1) h gives about ``nodes`` vertices in all branches
    return grow(bending, furcation, shape=(512, 512), seed=seed, generations=3, children=4, max_length=nodes * H, start=(10, 256, 0.0))


def test_bench_grow_500(benchmark):
    src = example()
    bend, fur = BendingModel.fit(src, h=H), FurcationModel.fit(src, h=H)
    out = benchmark(lambda: grow_nodes(bend, fur, 500))
    assert sum(len(b) for b in out.branches) > 100


def times(trees: int, nodes: int) -> dict[str, float]:
    src = example(trees)
    t: dict[str, float] = {}
    t0 = time.perf_counter()
    bend = BendingModel.fit(src, h=H)
    t["fit bending"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    fur = FurcationModel.fit(src, h=H)
    t["fit furcation"] = time.perf_counter() - t0
    t["svm train"] = fur.train_seconds
    t0 = time.perf_counter()
    out = grow_nodes(bend, fur, nodes)
    t[f"grow {nodes}"] = time.perf_counter() - t0
    t["nodes"] = float(sum(len(b) for b in out.branches))
    t["branches"] = float(len(out.branches))
    return t


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--trees", type=int, default=4, help="synthetic trees in the example (SVM training size)")
    ap.add_argument("--nodes", type=int, default=500)
    args = ap.parse_args()
    src = example(args.trees)
    samples = sum(len(b) for b in src.resample(H).branches)
    runs = [times(args.trees, args.nodes) for _ in range(args.runs)]
    best = {k: min(r[k] for r in runs) for k in runs[0]}
    print(f"example: {args.trees} trees, {len(src.branches)} branches, {samples} SVM samples (h = {H:g} px)")
    print(" ".join(f"{k:>14}" for k in best) + f"   (seconds, best of {args.runs})")
    print(" ".join(f"{v:>14.3f}" if v < 100 else f"{v:>14.0f}" for v in best.values()))


if __name__ == "__main__":
    main()
