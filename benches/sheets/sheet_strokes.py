"""Contact sheet and quality figures of stroke-based editing on the shared photos.

    python -m benches.sheets.sheet_strokes OUT.png [--only NAME ...]

Each case is a photo of ``../shared/data/strokes`` (the rocket, the horse silhouette, the
Broadway tower, the coffee table's wood), or the embedded bark cut to a tapering branch (the
speed benchmark's, ``benches/python/bench_strokes.py``; once more with its side branches given
tapering target widths), with source strokes drawn along the object here, a
mask made here from the photo (a colour rule inside a box: the shared photos have no alpha),
and target strokes that bend, stretch or branch it. One row per case: ``strokes.contact_sheet``
(source with object and strokes, target strokes, pieces and seams, result, result with strokes).
Printed per case: time, pieces, the programme's energy against the uniform mapping's, stroke
coverage, width agreement, and patch coherence of the result against the source (over the
result's opaque pixels) beside the uniform mapping's.
Needs ../shared/data (exits with a message when it is absent).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

import phloem
from benches.sheets._sheet import write_sheet
from phloem import metrics, strokes
from phloem.testing import shared_path

SHARED = shared_path("strokes")


def _arc(cx: float, cy: float, r: float, a0: float, a1: float, n: int = 40) -> list[list[float]]:
    """Points of a circular arc, angles in degrees (counter-clockwise on screen)."""
    a = np.radians(np.linspace(a0, a1, n))
    return np.c_[cx + r * np.cos(a), cy - r * np.sin(a)].tolist()


def _wave(x0: float, x1: float, y: float, amp: float, waves: float, n: int = 60) -> list[list[float]]:
    x = np.linspace(x0, x1, n)
    return np.c_[x, y + amp * np.sin(2 * math.pi * waves * (x - x0) / (x1 - x0))].tolist()


def _largest(mask: np.ndarray) -> np.ndarray:
    n, lab, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    if n <= 1:
        return mask
    k = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    return lab == k


def _rocket_mask(img: np.ndarray) -> np.ndarray:
    # The rocket is the pale, low-chroma column between the launch towers.
    m = np.zeros(img.shape[:2], bool)
    box = img[128:405, 306:340]
    lum, chroma = box.mean(axis=2), box.max(axis=2) - box.min(axis=2)
    m[128:405, 306:340] = (lum > 0.3) & (chroma < 0.3)
    return _largest(cv2.morphologyEx(m.astype(np.uint8), cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8)) > 0)


def _tower_mask(img: np.ndarray) -> np.ndarray:
    # The left turret: everything in its box that is not sky blue.
    m = np.zeros(img.shape[:2], bool)
    y0, y1, x0, x1 = 30, 560, 560, 668
    box = img[y0:y1, x0:x1]
    blue = (box[..., 2] > box[..., 0] + 0.12) & (box[..., 2] > 0.45)
    m[y0:y1, x0:x1] = ~blue
    return _largest(cv2.morphologyEx(m.astype(np.uint8), cv2.MORPH_OPEN, np.ones((5, 5), np.uint8)) > 0)


def _plank_mask(img: np.ndarray) -> np.ndarray:
    # A strip of the table along its grain, in the top right corner clear of the cup.
    m = np.zeros(img.shape[:2], np.uint8)
    strip = np.array([[390, 120], [560, 5], [598, 45], [430, 165]], np.int32)
    cv2.fillPoly(m, [strip], 1)
    return m > 0


@dataclass(frozen=True)
class Case:
    name: str
    file: str
    mask: Callable[[np.ndarray], np.ndarray] | None
    source: list[list[list[float]]]
    target: list[list[list[float]]]
    size: tuple[int, int]


CASES = [
    Case("rocket", "skimage_rocket.jpg", _rocket_mask, [[[323, 134], [323, 398]]],
         [_arc(250, 330, 200, 165, 15)], (360, 500)),
    Case("horse", "skimage_horse.png", None,
         [[[70, 125], [285, 110]], [[285, 110], [350, 45]], [[272, 185], [268, 230], [270, 292]],
          [[90, 190], [60, 240], [54, 262], [57, 292]]],
         [_wave(60, 420, 150, 15, 1.0), [[420, 150], [470, 70]], [[380, 170], [400, 300]], [[110, 165], [60, 290]]],
         (330, 520)),
    Case("tower", "Broadway_tower_edit.jpg", _tower_mask, [[[617, 75], [617, 540]]] * 2,
         [_wave(40, 660, 200, 60, 1.0), _arc(350, 380, 150, 200, -20)], (440, 700)),
    Case("branch", "", None, [], [], (512, 512)),  # drawn here: the embedded bark as a branch
    Case("tapered", "", None, [], [], (512, 512)),  # the same, side branches tapering (widths=)
    Case("plank", "skimage_coffee.png", _plank_mask, [[[410, 142], [578, 25]]] * 2,
         [_arc(300, 300, 220, 170, 10), [[300, 300], [300, 90]]], (340, 600)),
]  # fmt: skip


def _branch() -> tuple[np.ndarray, strokes.StrokeSet]:
    """The benchmark's bark branch and its three targets (``benches/python/bench_strokes.py``)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "python"))
    from bench_strokes import workload

    return workload()


def run(case: Case) -> tuple[np.ndarray, str]:
    if case.file == "":
        rgba, sset = _branch()
        if case.name == "tapered":
            # The side branches taper from 36 px at the main branch to 10 px at their tips.
            taper = [None, [[0, 36], [1, 10]], [[0, 36], [1, 10]]]
            pairs = tuple(strokes.StrokePair(p.source, p.target, p.controls, w) for p, w in zip(sset.pairs, taper))
            sset = strokes.StrokeSet(pairs, sset.source_shape, sset.target_size)
        img, mask = rgba[..., :3], rgba[..., 3] > 0.5
        return _measure(case.name, img, mask, sset)
    img = phloem.io.read_image(SHARED / case.file)[..., :3]
    mask = None if case.mask is None else case.mask(img)
    sset = strokes.StrokeSet.from_lists(case.source, case.target, target_size=case.size)
    return _measure(case.name, img, mask, sset)


def _measure(name: str, img: np.ndarray, mask: np.ndarray | None, sset: strokes.StrokeSet) -> tuple[np.ndarray, str]:
    t0 = time.perf_counter()
    res = strokes.edit(img, sset, mask=mask, full_output=True)
    dt = time.perf_counter() - t0
    uni = strokes.edit(img, sset, mask=mask, sampling="uniform")
    src = np.concatenate([img, res.mask[..., None].astype(np.float32)], axis=2)
    opaque = res.image[..., 3] > 0.5
    coh = metrics.patch_coherence(res.image[..., :3], img, mask=opaque)
    coh_u = metrics.patch_coherence(uni[..., :3], img, mask=uni[..., 3] > 0.5)
    e, eu = sum(s.energy for s in res.samplings), sum(s.uniform_energy for s in res.samplings)
    line = (
        f"| {name} | {dt:.2f} | {int(res.pieces.max()) + 1} | {e:.3g} / {eu:.3g} | "
        f"{metrics.stroke_coverage(res.image, sset):.3f} | {metrics.width_agreement(res.image, sset, src):.3f} | "
        f"{coh:.4f} / {coh_u:.4f} |"
    )
    return strokes.contact_sheet(img, sset, res, tile=320), line


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--only", nargs="*", default=None, help="case names (default all)")
    args = ap.parse_args(argv)
    if not SHARED.is_dir():
        print(f"no shared data at {SHARED}; set PHLOEM_SHARED_DATA", file=sys.stderr)
        return 1
    rows, lines = [], []
    for case in CASES:
        if args.only and case.name not in args.only:
            continue
        sheet, line = run(case)
        rows.append(sheet)
        lines.append(line)
    print("| case | time s | pieces | energy dp / uniform | coverage | width agreement | coherence dp / uniform |")
    print("|---|---|---|---|---|---|---|")
    print("\n".join(lines))
    write_sheet(rows, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
