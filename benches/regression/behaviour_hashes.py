"""SHA-256 of the outputs of fixed calls to every public job: a guard for behaviour-preserving moves.

Run it before and after a refactor and compare the two tables; every hash must match except
the changes the refactor intends (say which in the commit message). Each call is small, seeded
and run with 1 and 2 threads, which must agree.

    python benches/regression/behaviour_hashes.py > before.tsv
    ... refactor ...
    python benches/regression/behaviour_hashes.py --compare before.tsv

Only the spellings of the API as it stood before issue 15 are used, so the script runs on both
sides of an API change (the old spellings keep working, with a DeprecationWarning).
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

import phloem
from phloem import bark, blend, branching, metrics, patch, seams, shapes, texture, trees, warp


def _digest(value: Any) -> str:
    h = hashlib.sha256()

    def feed(v: Any) -> None:
        if v is None:
            h.update(b"None")
        elif isinstance(v, np.ndarray):
            a = np.ascontiguousarray(v)
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(a.tobytes())
        elif isinstance(v, (list, tuple)):
            h.update(f"[{len(v)}".encode())
            for x in v:
                feed(x)
        elif isinstance(v, dict):
            for k in sorted(v):
                h.update(str(k).encode())
                feed(v[k])
        elif isinstance(v, (float, np.floating)):
            h.update(np.float64(v).tobytes())
        else:
            h.update(repr(v).encode())

    feed(value)
    return h.hexdigest()[:16]


def _tree_rgba(seed: int) -> np.ndarray:
    import cv2

    rng = np.random.default_rng(seed)
    h, w = 220, 160
    img = np.zeros((h, w, 4), np.float32)
    cx, bottom = w // 2, h - 5
    top = bottom - 60
    img[top:bottom, cx - 7 : cx + 7] = (0.45, 0.3, 0.15, 1.0)
    crown = np.zeros((h, w), np.uint8)
    cv2.ellipse(crown, (cx, top - 30), (50 + 5 * seed, 45), 0, 0, 360, 1, -1)
    leaf = rng.uniform(0.3, 0.8, (h, w)).astype(np.float32)
    on = crown > 0
    img[on, 0], img[on, 1], img[on, 2], img[on, 3] = 0.1 * leaf[on], leaf[on], 0.2 * leaf[on], 1.0
    return img


def calls() -> dict[str, Callable[[int], Any]]:
    """Name -> function of the thread count returning the output to hash."""
    photo = phloem.data.bark()[:96, :96, :3].copy()
    brick = phloem.data.brick()[:80, :80].copy()
    rng = np.random.default_rng(0)
    other = np.clip(photo[::-1] + 0.02 * rng.normal(size=photo.shape), 0, 1).astype(np.float32)
    hole = np.zeros(brick.shape[:2], bool)
    hole[30:46, 28:44] = True
    labels = bark.input_labels(photo, 2, seed=0)
    new_labels = np.zeros((64, 64), np.int32)
    new_labels[:, 32:] = 1
    disk = np.zeros((48, 48), bool)
    yy, xx = np.mgrid[:48, :48]
    disk[(yy - 24) ** 2 + (xx - 24) ** 2 < 18**2] = True
    sk = branching.synthetic_skeleton(0, length=120.0)
    sk_img = np.where(sk.mask(), 0.2, 0.8).astype(np.float32)
    sk_img = np.clip(sk_img + 0.05 * np.random.default_rng(1).normal(size=sk_img.shape), 0, 1).astype(np.float32)
    square = np.array([[10.0, 10.0], [60.0, 10.0], [60.0, 60.0], [10.0, 60.0]])
    moved = square + np.array([[0.0, 0.0], [5.0, 3.0], [0.0, 6.0], [-4.0, 0.0]])

    lib = trees.Library.from_images([_tree_rgba(s) for s in range(3)], names=["a", "b", "c"], size=192)

    def seam_region() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        a = photo[:48, :48]
        b = other[:48, :48]
        region = np.ones((48, 48), bool)
        return a, b, region

    out: dict[str, Callable[[int], Any]] = {
        "patch.nnf": lambda t: patch.nnf(photo, other, seed=0, threads=t),
        "patch.nnf.kdtree": lambda t: patch.nnf(photo, other, method="kdtree", seed=0, threads=t),
        "patch.knn": lambda t: patch.knn(photo[:48, :48], 3, seed=0, threads=t),
        "patch.vote": lambda t: patch.vote(photo, patch.nnf(other, photo, seed=0, threads=t)[0], threads=t),
        "seams.seam": lambda t: seams.seam(*seam_region(), seeds=None, threads=t),
        "blend.seamless": lambda t: blend.seamless(
            photo[:40, :40, 0], brick, np.ones((40, 40), bool), (20, 20), threads=t
        ),
        "blend.interpolate_field": lambda t: blend.interpolate_field(
            disk, np.array([[24, 10], [24, 38]]), np.array([[1.0, 0.0], [0.0, 1.0]]), threads=t
        ),
        "texture.synthesize": lambda t: texture.synthesize(photo[:48, :48], (64, 64), seed=0, threads=t),
        "texture.quilt": lambda t: texture.quilt(photo, (96, 96), seed=0, threads=t),
        "texture.complete": lambda t: texture.complete(brick, hole, seed=0, threads=t),
        "texture.by_numbers": lambda t: texture.by_numbers(photo, labels, new_labels, seed=0, threads=t),
        "texture.feature_distance_map": lambda t: texture.feature_distance_map(photo),
        "shapes.synthesize": lambda t: shapes.synthesize(disk, (64, 64), seed=0, threads=t),
        "shapes.synthesize_labels": lambda t: shapes.synthesize_labels(labels, (48, 48), seed=0, threads=t),
        "bark.input_labels": lambda t: bark.input_labels(photo, 3, seed=0),
        "bark.generate": lambda t: bark.generate(photo, (64, 64), seed=0, threads=t),
        "warp.mvc": lambda t: warp.mvc(photo[:70, :70], square, moved, threads=t),
        "trees.variation": lambda t: trees.variation(lib, seed=0, threads=t).image,
        "branching.grow": lambda t: branching.grow(*branching.fit_models(sk), shape=(96, 96), seed=0).to_dict(),
        "branching.render": lambda t: branching.render(sk_img, sk, sk, seed=0, threads=t),
        "branching.render.grown": lambda t: branching.render(
            sk_img, sk, branching.grow(*branching.fit_models(sk), shape=sk.shape, seed=1), seed=0, threads=t
        ),
        "branching.synthesize": lambda t: branching.synthesize(sk_img, sk, seed=0).image,
        "seams.grid_maxflow": lambda t: seams.grid_maxflow(
            np.clip(photo[:32, :32, 0] - 0.5, 0, None),
            np.clip(0.5 - photo[:32, :32, 1], 0, None),
            np.full((32, 32, 2), 0.1, np.float32),
            threads=t,
        ),
        "trees.prepare": lambda t: trees.prepare(_tree_rgba(4), size=192).vector,
        "branching.trace": lambda t: branching.trace(sk_img).to_dict(),
        "metrics.patch_coherence": lambda t: metrics.patch_coherence(other, photo, threads=t),
        "metrics.shape_similarity": lambda t: metrics.shape_similarity(disk, disk[::-1, :]),
    }
    return out


def table() -> dict[str, str]:
    rows: dict[str, str] = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, f in calls().items():
            hashes = []
            for t in (1, 2):
                try:
                    hashes.append(_digest(f(t)))
                except Exception as e:
                    hashes.append(f"error: {type(e).__name__}: {e}"[:80])
            rows[name] = hashes[0] if hashes[0] == hashes[1] else f"THREADS DIFFER {hashes[0]} {hashes[1]}"
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--compare", metavar="TSV", help="a table written earlier; print the rows that differ")
    args = ap.parse_args()
    rows = table()
    if args.compare is None:
        for k, v in rows.items():
            print(f"{k}\t{v}")
        return 0
    with open(args.compare) as f:
        old = dict(line.rstrip("\n").split("\t", 1) for line in f if "\t" in line)
    changed = 0
    for k in sorted(set(old) | set(rows)):
        a, b = old.get(k, "-"), rows.get(k, "-")
        mark = "same" if a == b else "CHANGED"
        changed += a != b
        print(f"{mark}\t{k}\t{a}\t{b}")
    print(f"{changed} of {len(rows)} changed", file=sys.stderr)
    return 1 if changed else 0


if __name__ == "__main__":
    raise SystemExit(main())
