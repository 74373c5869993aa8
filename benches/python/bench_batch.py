"""Batches on a 2-worker LocalCluster against a plain sequential loop in one process (issue 21).

Workloads, each run both ways with the very same ``phloem`` command lines (``Item.argv``):
- tree variations: ``phloem trees LIB --n-variations 1 --size S`` per seed, the library
  prepared once into a ``--library-cache`` beforehand (not timed) and loaded once per process;
- textures: ``phloem synthesize`` of the embedded Douglas-fir bark at 512², one per seed;
- no-op-sized tasks (8×8 syntheses) on an already running cluster, for the scheduling overhead
  per task: the extra worker-seconds a task costs over the same command in the loop.

The sequential loop gives each command all cores (``--threads`` default), the batch gives each
of its 2 workers one core. The machine's capacity for the work is measured beside them: 2 plain
loops at one thread in fresh processes side by side, each with half the items (no Dask). The library is ``../shared/data/trees`` when present (the FlightGear
atlases), else four synthetic trees.

Table:   python benches/python/bench_batch.py [--trees 200] [--textures 50] [--size 256] [--workers 2]
In the default test run a tiny batch executes once (``--benchmark-disable``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import pytest

import phloem
from phloem import trees
from phloem.testing import shared_path

pytest.importorskip("distributed")

from phloem import batch
from phloem.cli import main as cli

pytestmark = pytest.mark.filterwarnings("ignore::pytest_benchmark.logger.PytestBenchmarkWarning")


def _sequential(spec: batch.Spec, out: Path, extra: list[str]) -> float:
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    for item in spec.items:
        if cli([*item.argv(out, extra=extra), "--quiet"]) != 0:
            raise RuntimeError(f"{item.name} failed")
    return time.perf_counter() - t0


def _side_by_side(spec: batch.Spec, out: Path, workers: int, extra: list[str]) -> float:
    """The machine's capacity for the same work: ``workers`` plain loops at one thread each, in
    fresh processes side by side (every ``workers``-th item each), no Dask; the time until the
    last one is done, its imports and first library read included, as a worker's are."""
    out.mkdir(parents=True, exist_ok=True)
    shares = [[[*it.argv(out, extra=extra), "--quiet", "--threads", "1"] for it in spec.items[k::workers]]
              for k in range(workers)]  # fmt: skip
    code = (
        "import json, sys\nfrom phloem.cli import main\n"
        "for argv in json.load(sys.stdin):\n    assert main(argv) == 0, argv\n"
    )
    t0 = time.perf_counter()
    procs = [subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE) for _ in shares]
    for proc, share in zip(procs, shares):
        assert proc.stdin is not None
        proc.stdin.write(json.dumps(share).encode())
        proc.stdin.close()
    if any(proc.wait() != 0 for proc in procs):
        raise RuntimeError("a side-by-side loop failed")
    return time.perf_counter() - t0


def _batch(spec: batch.Spec, out: Path, workers: int, client: Any = None) -> tuple[float, batch.Summary]:
    t0 = time.perf_counter()
    summary = batch.run(spec, out_dir=out, workers=None if client is not None else workers, client=client)
    if not summary.ok:
        raise RuntimeError(summary.line())
    return time.perf_counter() - t0, summary


def _library(folder: Path) -> Path:
    shared = shared_path("trees")
    if shared.is_dir() and any(shared.glob("*.png")):
        return shared
    import sys

    sys.path.insert(0, str(Path(__file__).parent))
    from bench_tree_variations import synthetic_tree

    folder.mkdir(parents=True, exist_ok=True)
    for s in range(4):
        phloem.io.write_image(folder / f"synthetic{s}.png", synthetic_tree(s), overwrite=True)
    return folder


def _row(name: str, n: int, seq: float, par: float, cap: float) -> str:
    return (
        f"| {name} | {n} | {seq:.1f} s ({n / seq:.2f}/s) | {cap:.1f} s ({n / cap:.2f}/s) | {par:.1f} s ({n / par:.2f}/s) "
        f"| {seq / par:.2f}× | {cap / par:.0%} |"
    )


def test_bench_batch_tiny(benchmark: Any, tmp_path: Path) -> None:
    spec = batch.load_spec({"job": "synthesize", "inputs": [phloem.data.path("brick.png")],
                            "params": {"size": "8x8", "iterations": 1}, "seeds": "0..3"})  # fmt: skip
    runs = iter(range(10**6))
    summary = benchmark(lambda: batch.run(spec, out_dir=tmp_path / str(next(runs)), workers=2))
    assert summary.ok and summary.made == 4


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trees", type=int, default=200, help="tree variations (default 200)")
    ap.add_argument("--textures", type=int, default=50, help="512² textures (default 50)")
    ap.add_argument("--noop", type=int, default=100, help="no-op-sized tasks for the overhead (default 100)")
    ap.add_argument("--size", type=int, default=256, help="tree billboard side (default 256)")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    print(f"machine: {os.cpu_count()} cores; load before: {os.getloadavg()[0]:.2f} (1 min)")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        lib = _library(root / "lib")
        cache = root / "cache"
        t0 = time.perf_counter()
        n_trees = len(trees.Library.load(lib, size=args.size, cache=cache))
        print(f"library {lib}: {n_trees} trees prepared at {args.size}² in {time.perf_counter() - t0:.1f} s (cached)")
        tspec = batch.load_spec({"job": "trees", "inputs": [str(lib)], "seeds": f"0..{args.trees - 1}",
                                 "params": {"n-variations": 1, "size": args.size, "library-cache": str(cache)}})  # fmt: skip
        seq = _sequential(tspec, root / "trees-seq", [])
        cap = _side_by_side(tspec, root / "trees-cap", args.workers, [])
        par, _ = _batch(tspec, root / "trees-batch", args.workers)
        rows.append(_row(f"tree variations, {args.size}², library of {n_trees}", args.trees, seq, par, cap))
        print(rows[-1], flush=True)

        xspec = batch.load_spec({"job": "synthesize", "inputs": [phloem.data.path("bark_douglas_fir.png")],
                                 "params": {"size": "512x512"}, "seeds": f"0..{args.textures - 1}"})  # fmt: skip
        seq = _sequential(xspec, root / "tex-seq", [])
        cap = _side_by_side(xspec, root / "tex-cap", args.workers, [])
        par, _ = _batch(xspec, root / "tex-batch", args.workers)
        rows.append(_row("synthesize 512² (Douglas-fir bark)", args.textures, seq, par, cap))
        print(rows[-1], flush=True)

        nspec = batch.load_spec({"job": "synthesize", "inputs": [phloem.data.path("brick.png")],
                                 "params": {"size": "8x8", "iterations": 1}, "seeds": f"0..{args.noop - 1}"})  # fmt: skip
        seq = _sequential(nspec, root / "noop-seq", [])
        from distributed import Client

        t0 = time.perf_counter()
        with batch.local_cluster(args.workers) as cluster, Client(cluster) as client:
            start = time.perf_counter() - t0
            par, _ = _batch(nspec, root / "noop-batch", args.workers, client)
        overhead = (par * args.workers - seq) / args.noop
        print(
            f"no-op-sized tasks (8×8 synthesis), {args.noop}: loop {seq / args.noop * 1e3:.1f} ms each, batch "
            f"{par / args.noop * 1e3:.1f} ms each on {args.workers} workers; scheduling overhead "
            f"{overhead * 1e3:.1f} worker-ms per task; cluster start {start:.1f} s"
        )
    print(f"load after: {os.getloadavg()[0]:.2f} (1 min)")
    print(f"| workload | items | sequential loop | {args.workers} loops side by side | batch, {args.workers} workers "
          "| speed-up over the loop | of the side-by-side rate |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(r)


if __name__ == "__main__":
    main()
