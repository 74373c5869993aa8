"""Structure synthesis for branching structures (Sibbing et al. 2010 §4): SVM training and growth.

The workload: a synthetic example structure (``phloem.branching.synthetic_skeleton``, several
random-walk trees side by side, step h = 2 px); fit the bending model and the furcation
model (linear SVM; the paper reports "about one minute" of training), then grow a structure of
about 500 nodes in a 512x512 image with space colonisation, three generations, and carry its
branch ends on to structure ahead (``join_ends``, beyond the paper) until half of them end on it.

When ``../shared/data/branching`` is present the table also grows input-sized structures
(``grow(..., max_length="input")``, seed 1) from the traced retina, Colville delta mask and
Jacksboro DEM, with their nodes, seconds and the L1 distances of the angle and thickness
histograms to the input's.

Run for figures:   pytest benches/python/bench_branching_structure.py --benchmark-enable --benchmark-only
Table:             python benches/python/bench_branching_structure.py [--runs N] [--trees T] [--nodes N] [--no-real]
                   [--direction-histogram W] [--layout W]
In the default test run the benchmark executes once (``--benchmark-disable``).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pytest

from phloem.branching import (
    BendingModel,
    Branch,
    FurcationModel,
    Skeleton,
    angle_histogram,
    grow,
    histogram_distance,
    join_ends,
    synthetic_skeleton,
    thickness_histogram,
)
from phloem.testing import shared_path

pytestmark = pytest.mark.filterwarnings("ignore::pytest_benchmark.logger.PytestBenchmarkWarning")

H = 2.0


def example(trees: int = 4, seed: int = 0) -> Skeleton:
    """``trees`` synthetic structures stacked vertically in one skeleton."""
    return Skeleton.stack([synthetic_skeleton(seed + i, length=260.0, h=H) for i in range(trees)])


def grow_nodes(bending: BendingModel, furcation: FurcationModel, nodes: int, seed: int = 0) -> Skeleton:
    # total length (nodes - 1) h gives about ``nodes`` vertices in all branches
    return grow(
        bending,
        furcation,
        size=(512, 512),
        seed=seed,
        generations=3,
        children=4,
        max_length=nodes * H,
        start=(10, 256, 0.0),
    )


def test_bench_grow_500(benchmark):
    src = example()
    bend, fur = BendingModel.fit(src, h=H), FurcationModel.fit(src, h=H)
    out = benchmark(lambda: grow_nodes(bend, fur, 500))
    assert sum(len(b) for b in out.branches) > 100


def test_bench_join_ends_500(benchmark):
    src = example()
    bend, fur = BendingModel.fit(src, h=H), FurcationModel.fit(src, h=H)
    grown = grow_nodes(bend, fur, 500)
    out = benchmark(lambda: join_ends(grown, 0.5, reach=3 * bend.m * H, step=H))
    assert len(out.branches) == len(grown.branches)


def test_bench_resample_staircase(benchmark):
    # a traced centre line of 4000 pixels at the measures' step (benches/resample.rs in Rust)
    rng = np.random.default_rng(0)
    steps = np.array([[1, 0], [1, 1], [0, 1], [1, -1]], np.float64)[rng.integers(0, 4, 4000)]
    b = Branch(np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)]), 2.0)
    out = benchmark(lambda: b.resample(1.0))
    assert len(out) > 3000


def times(trees: int, nodes: int, direction_histogram: float = 0.0, layout: float = 0.0) -> dict[str, float]:
    src = example(trees)
    t: dict[str, float] = {}
    t0 = time.perf_counter()
    bend = BendingModel.fit(src, h=H, direction_histogram=direction_histogram, layout=layout)
    t["fit bending"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    fur = FurcationModel.fit(src, h=H)
    t["fit furcation"] = time.perf_counter() - t0
    t["svm train"] = fur.train_seconds
    t0 = time.perf_counter()
    out = grow_nodes(bend, fur, nodes)
    t[f"grow {nodes}"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    join_ends(out, 0.5, reach=3 * bend.m * H, step=H)
    t["join ends"] = time.perf_counter() - t0
    t["nodes"] = float(sum(len(b) for b in out.branches))
    t["branches"] = float(len(out.branches))
    return t


SHARED = shared_path("branching")
#: traced inputs of the issue: file, trace() settings
REAL = {
    "retina": ("skimage_retina.jpg", {"kind": "dark", "channel": 1, "sigmas": (1.5, 3, 5)}),
    "colville": ("rivgraph_colville_delta_mask.png", {"kind": "mask"}),
    "dem": ("mpl_jacksboro_fault_dem_u16.png", {"kind": "bright", "sigmas": (3, 6)}),
}


def real_rows(layout: float = 0.0) -> list[str]:
    """Input-sized growth from the traced real inputs (empty without ../shared)."""
    from phloem import io
    from phloem.branching import trace

    rows = []
    for name, (file, kw) in REAL.items():
        path = SHARED / file
        if not path.exists():
            continue
        img = io.read_image(path)
        src = trace(img, **kw)  # type: ignore[arg-type]
        bend = BendingModel.fit(src, layout=layout)
        fur = FurcationModel.fit(src, h=bend.h)
        t0 = time.perf_counter()
        out = grow(bend, fur, size=img.shape[:2], seed=1, max_length="input")
        dt = time.perf_counter() - t0
        ha, e = angle_histogram(src, h=bend.h)
        hb, _ = angle_histogram(out, h=bend.h, range=(e[0], e[-1]))
        ta, e = thickness_histogram(src, h=bend.h)
        tb, _ = thickness_histogram(out, h=bend.h, range=(e[0], e[-1]))
        rows.append(
            f"{name:>10} {len(src.branches):>8} {sum(b.parent is None for b in out.branches):>6} {len(out.branches):>8} "
            f"{sum(len(b) for b in out.branches):>6} {out.total_length() / src.total_length():>8.2f} {dt:>8.2f} "
            f"{histogram_distance(ha, hb):>8.3f} {histogram_distance(ta, tb):>8.3f}"
        )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--trees", type=int, default=4, help="synthetic trees in the example (SVM training size)")
    ap.add_argument("--nodes", type=int, default=500)
    ap.add_argument("--no-real", action="store_true", help="skip the traced inputs of ../shared")
    ap.add_argument(
        "--direction-histogram", type=float, default=0.0, help="the bending model's direction histogram weight"
    )
    ap.add_argument("--layout", type=float, default=0.0, help="the bending model's layout weight")
    args = ap.parse_args()
    src = example(args.trees)
    samples = sum(len(b) for b in src.resample(H).branches)
    runs = [times(args.trees, args.nodes, args.direction_histogram, args.layout) for _ in range(args.runs)]
    best = {k: min(r[k] for r in runs) for k in runs[0]}
    print(
        f"example: {args.trees} trees, {len(src.branches)} branches, {samples} SVM samples (h = {H:g} px), "
        f"direction histogram {args.direction_histogram:g}, layout {args.layout:g}"
    )
    print(" ".join(f"{k:>14}" for k in best) + f"   (seconds, best of {args.runs})")
    print(" ".join(f"{v:>14.3f}" if v < 100 else f"{v:>14.0f}" for v in best.values()))
    rows = [] if args.no_real else real_rows(args.layout)
    if rows:
        print('\ninput-sized structures (max_length="input", seed 1; L1 of normalised histograms vs the input)')
        head = ("input", "in br", "roots", "branches", "nodes", "length/L", "seconds", "angle L1", "thick L1")
        print(" ".join(f"{h:>{w}}" for h, w in zip(head, (10, 8, 6, 8, 6, 8, 8, 8, 8))))
        print("\n".join(rows))


if __name__ == "__main__":
    main()
