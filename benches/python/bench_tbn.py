"""Texture-by-numbers benchmarks: phloem's k-coherence solver against a PatchMatch-based
texture-by-numbers assembled from ``phloem.patch.nnf`` and ``phloem.patch.vote``.

Workload: the thesis' bark1 run (263×324 exemplar ``ai.png``, 256×320 output from ``b.png``,
Laitoch 2018); the embedded bark with a threshold label map stands in when ``../shared`` is
absent.

Run for figures:   pytest benches/python/bench_tbn.py --benchmark-enable --benchmark-only
Same-run table:    python benches/python/bench_tbn.py [--runs 5] [--threads 2]
Pipeline scale:    python benches/python/bench_tbn.py --pipeline   (embedded bark, 2 labels, 512×512)
In the default test run the benchmarks execute once each (``--benchmark-disable``).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

import phloem
from phloem.metrics import label_histogram_distance, patch_coherence
from phloem.testing import shared_path

pytestmark = pytest.mark.filterwarnings("ignore::pytest_benchmark.logger.PytestBenchmarkWarning")

RUN = shared_path("bark", "thesis_runs", "bark1")


def _labels(path: Path) -> np.ndarray:
    g = phloem.io.read_image(path)
    g = g[..., :3].mean(axis=2) if g.ndim == 3 else g
    return np.round(g * 255).astype(np.int32)


def workload() -> tuple[str, np.ndarray, np.ndarray, np.ndarray]:
    """(name, exemplar, labels_in, labels_out)."""
    if (RUN / "ai.png").exists():
        return "bark1", phloem.io.read_image(RUN / "ai.png")[..., :3], _labels(RUN / "a.png"), _labels(RUN / "b.png")
    ex = np.ascontiguousarray(phloem.data.bark()[..., :3])
    a = (cv2.GaussianBlur(ex.mean(axis=2), (0, 0), 2.0) > 0.3).astype(np.int32)
    return "embedded bark", ex, a, np.ascontiguousarray(a[:, ::-1])


def patchmatch_by_numbers(
    exemplar: np.ndarray,
    labels_in: np.ndarray,
    labels_out: np.ndarray,
    *,
    patch_size: int = 5,
    label_weight: float = 3.0,
    levels: int = 3,
    iterations: int = 3,
    seed: int = 0,
    threads: int | None = None,
) -> np.ndarray:
    """Image-analogies-style texture-by-numbers on PatchMatch: labels are one-hot channels
    weighted by ``label_weight``; per level, ``iterations`` rounds of PatchMatch (warm-started)
    and voting; coarsest start from each label's mean colour. Voting averages, so the output
    is not made of exemplar pixels."""
    values = np.unique(labels_in)
    la, lb = np.searchsorted(values, labels_in), np.searchsorted(values, labels_out)
    onehot_a = (la[..., None] == np.arange(values.size)).astype(np.float32)
    onehot_b = (lb[..., None] == np.arange(values.size)).astype(np.float32)
    nc = exemplar.shape[2]
    weights = np.concatenate([np.ones(nc), np.full(values.size, label_weight / 2)]).astype(np.float32)
    field = None
    out = None
    for lv in range(levels - 1, -1, -1):
        f = 2**lv
        es = (exemplar.shape[1] // f, exemplar.shape[0] // f)
        os_ = (labels_out.shape[1] // f, labels_out.shape[0] // f)
        ex_l = cv2.resize(exemplar, es, interpolation=cv2.INTER_AREA)
        src = np.ascontiguousarray(
            np.concatenate(
                [ex_l, cv2.resize(onehot_a, es, interpolation=cv2.INTER_NEAREST).reshape(*ex_l.shape[:2], -1)], 2
            )
        )
        ob = cv2.resize(onehot_b, os_, interpolation=cv2.INTER_NEAREST).reshape(os_[1], os_[0], -1)
        if out is None:
            means = np.stack([exemplar[la == k].mean(axis=0) for k in range(values.size)])
            out = means[ob.argmax(axis=2)].astype(np.float32)
        else:
            out = cv2.resize(out, os_, interpolation=cv2.INTER_LINEAR).reshape(os_[1], os_[0], nc)
        for it in range(iterations):
            tgt = np.ascontiguousarray(np.concatenate([out, ob], 2))
            init = None
            if field is not None and field.shape[:2] == tgt.shape[:2]:
                init = field
            field, _ = phloem.patch.nnf(
                src,
                tgt,
                patch_size=patch_size,
                iterations=5,
                weights=weights,
                init=init,
                seed=seed + it,
                threads=threads,
            )
            out, _ = phloem.patch.vote(ex_l, field, patch_size=patch_size, threads=threads)
        field = None  # a fresh field per level (the sizes change)
    assert out is not None
    return out


def pipeline_workload() -> tuple[str, np.ndarray, np.ndarray, np.ndarray]:
    """The bark pipeline's scale: the embedded bark photo, a two-label map (dark furrows and
    plates: ``phloem.bark.input_labels`` where present, else a median split of the smoothed
    luminance) and a 512×512 output map made by mirroring it."""
    ex = np.ascontiguousarray(phloem.data.bark()[..., :3])
    try:
        from phloem.bark import input_labels  # type: ignore[import-not-found]

        a = np.asarray(input_labels(ex, 2), np.int32)
    except ImportError:
        g = cv2.GaussianBlur(ex.mean(axis=2), (0, 0), 2.0)
        a = (g > np.median(g)).astype(np.int32)
    b = np.concatenate([a, a[:, ::-1]], axis=1)
    b = np.ascontiguousarray(np.concatenate([b, b[::-1]], axis=0)[:512, :512])
    return "embedded bark → 512²", ex, a, b


@pytest.fixture(scope="module")
def scene() -> tuple[str, np.ndarray, np.ndarray, np.ndarray]:
    return workload()


@pytest.mark.parametrize("threads", [1, 2])
def test_by_numbers(benchmark, scene, threads):
    _, ex, a, b = scene
    benchmark.extra_info["pixels"] = b.size
    out = benchmark.pedantic(phloem.texture.by_numbers, args=(ex, a, b), kwargs={"threads": threads}, rounds=3)
    assert out.shape == (*b.shape, 3)


def test_patchmatch_by_numbers(benchmark, scene):
    _, ex, a, b = scene
    benchmark.extra_info["pixels"] = b.size
    out = benchmark.pedantic(patchmatch_by_numbers, args=(ex, a, b), kwargs={"threads": 2}, rounds=1)
    assert out.shape == (*b.shape, 3)


def _time(fn: Any, runs: int) -> tuple[float, float, Any]:
    ts, out = [], None
    for _ in range(runs):
        t = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t)
    return min(ts), float(np.median(ts)), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--pipeline", action="store_true", help="the bark pipeline's 512² scale (phloem only)")
    ap.add_argument("--selection", nargs="+", default=["average"], help="E-step selections (default: the library's)")
    ap.add_argument("--composite", type=int, default=1, help="graph-cut compositing rounds (default: the library's, 1)")
    ap.add_argument(
        "--stand-in-weight", type=float, nargs="+", default=[5.0], help="stand-in weights, 0 for none (default: 5)"
    )
    args = ap.parse_args()
    name, ex, a, b = pipeline_workload() if args.pipeline else workload()
    print(
        f"{name}: exemplar {ex.shape[0]}×{ex.shape[1]}, output {b.shape[0]}×{b.shape[1]}, {args.threads} threads, {args.runs} runs"
    )
    print(f"{'method':<32} {'best':>7} {'median':>7} {'px/s':>9} {'coherence':>10} {'hist':>6}")
    rows: dict = {
        f"phloem.by_numbers {sel}+c{args.composite}+s{siw:g}": lambda sel=sel, siw=siw: phloem.texture.by_numbers(
            ex, a, b, threads=args.threads, selection=sel, composite=args.composite, stand_in_weight=siw or None
        )
        for sel in args.selection
        for siw in args.stand_in_weight
    }
    rows |= {
        "patchmatch_by_numbers": lambda: patchmatch_by_numbers(ex, a, b, threads=args.threads),
    }
    if args.pipeline:
        del rows["patchmatch_by_numbers"]
    for label, fn in rows.items():
        best, med, out = _time(fn, args.runs)
        coh = patch_coherence(out, ex)
        hist = label_histogram_distance(np.clip(out, 0, 1), b, ex, a)
        print(f"{label:<32} {best:>6.2f}s {med:>6.2f}s {b.size / best:>9.0f} {coh:>10.5f} {hist:>6.3f}")


if __name__ == "__main__":
    main()
