"""Contact sheet and quality figures of the whole leaves pipeline on the leafarea scans.

    python -m benches.sheets.sheet_leaves OUT.png [--count 8] [--exemplars A300-1#0 A300-2#0 ...] [--seed 0]

The training leaf is the one the committed scribbles were drawn on
(``tests/data/leaves/leafarea_A300-1_scribbles.png``: leaf 0 of ``leafarea_A300-1.jpeg``); the
other exemplars are leaves of the other scans of the same species. The sheet is
``leaves.contact_sheet``: exemplars as posed, aligned, induced layers, peeled backgrounds, new
leaves. Printed: λ, δ and the Eq. 4 objective per layer, registration residuals, and for each
new leaf its alpha IoU with every exemplar (after posing it on that exemplar) and its patch
coherence against the exemplars beside each exemplar's own against the others.
Needs ../shared/data (exits with a message when it is absent).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np

import phloem
from benches.sheets._sheet import ROOT, write_sheet
from phloem import leaves
from phloem.testing import shared_path

SHARED = shared_path("leaves")
SCRIBBLES = ROOT / "tests" / "data" / "leaves" / "leafarea_A300-1_scribbles.png"
DEFAULT = ["A300-1#0", "A300-2#0", "A300-2#1", "A1-01#0"]
#: Leaves are compared at this longest side (patch coherence is slow at full size).
_SIDE = 320


def _leaf(spec: str) -> np.ndarray:
    name, j = spec.split("#")
    return leaves.extract(phloem.io.read_image(SHARED / f"leafarea_{name}.jpeg"))[int(j)]


def _small(rgba: np.ndarray) -> np.ndarray:
    k = _SIDE / max(rgba.shape[:2])
    return cv2.resize(rgba, None, fx=k, fy=k, interpolation=cv2.INTER_AREA)


def alpha_iou(a: np.ndarray, b: np.ndarray) -> float:
    """IoU of the alpha of ``a`` posed onto ``b`` (leaves.pose) with ``b``'s alpha."""
    m, _ = leaves.pose(a, b)
    wa = cv2.warpAffine(a[..., 3], m, (b.shape[1], b.shape[0])) > 0.5
    bb = b[..., 3] > 0.5
    return float((wa & bb).sum()) / float((wa | bb).sum())


def coherence(leaf: np.ndarray, others: list[np.ndarray]) -> float:
    """Mean patch distance of ``leaf``'s leaf pixels to their nearest patch in any of ``others``
    (all shrunk to 320 px and placed side by side over black)."""
    small = [_small(o) for o in others]
    h = max(s.shape[0] for s in small)
    strip = np.concatenate([np.pad(s, ((0, h - s.shape[0]), (0, 4), (0, 0))) for s in small], axis=1)
    q = _small(leaf)
    mask = cv2.erode((q[..., 3] > 0.99).astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    pre = lambda x: x[..., :3] * x[..., 3:]  # noqa: E731
    return phloem.metrics.patch_coherence(pre(q), pre(strip), mask=mask)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--count", type=int, default=8)
    ap.add_argument("--exemplars", nargs="+", default=DEFAULT, metavar="SCAN#J")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if not SHARED.is_dir():
        sys.exit(f"sheet_leaves: {SHARED} is absent; this sheet needs the shared leaf scans")
    exemplars = [_leaf(s) for s in args.exemplars]
    t0 = time.perf_counter()
    model = leaves.analyze(exemplars, SCRIBBLES, seed=args.seed)
    t_an = time.perf_counter() - t0
    t0 = time.perf_counter()
    new = leaves.synthesize(model, count=args.count, seed=args.seed)
    t_syn = (time.perf_counter() - t0) / args.count
    write_sheet([leaves.contact_sheet(model, new)], args.out)
    print(f"analysis {t_an:.1f} s, {t_syn:.2f} s per new leaf; canvas {model.size[1]}x{model.size[0]}")
    print(
        "residual px:",
        " ".join(f"{r:.1f}" for r in model.residual),
        " scale:",
        " ".join(f"{s:.2f}" for s in model.scale),
    )
    for k, label in enumerate(model.order[:-1]):
        print(f"layer {label}: lambda {model.lam[k]:.2f} delta {model.delta[k]:.3f} objective {model.objective[k]:.2f}")
    own = [coherence(e, [o for j, o in enumerate(exemplars) if j != i]) for i, e in enumerate(exemplars)]
    print("exemplar coherence against the others:", " ".join(f"{c:.4f}" for c in own), f"(mean {np.mean(own):.4f})")
    for i, leaf in enumerate(new):
        ious = [alpha_iou(leaf, e) for e in exemplars]
        print(f"new {i}: alpha IoU with exemplars {' '.join(f'{v:.3f}' for v in ious)} (max {max(ious):.3f}), "
              f"coherence {coherence(leaf, exemplars):.4f}, area {int((leaf[..., 3] > 0.5).sum())} px")  # fmt: skip
    areas = [int((e[..., 3] > 0.5).sum()) for e in exemplars]
    print("exemplar areas px:", areas)
    print(f"wrote {Path(args.out)}")


if __name__ == "__main__":
    main()
