"""Contact sheet of label-map synthesis: look at it before trusting any number.

    python -m benches.sheets.sheet_shapes out/shapes_sheet.png

Bark row: the embedded bark | its 3-label map (k-means, as in bench_shapes.py) | phloem layered
and joint outputs at 256² | joint at 512² (shown reduced) | joint at 256² without rotations
and with the half-turn only (both keep the furrows vertical). Each output tile also shows its
chord length (``c``, :func:`phloem.shapes.chord_length`) next to the input's. One row per thesis run when
../shared/data is present: the input label map a | the thesis' output b | phloem layered |
phloem joint, each output at b's size, with its Eq. 3.9 distance to a (lower is better) and
the seconds it took. Labels are drawn as evenly spaced grays (darkest = lowest label).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

import phloem
from phloem import shapes
from phloem.testing import shared_path

from ..python.bench_shapes import bark_labels
from ._sheet import _fit, _label, write_sheet

RUNS = ["bark1", "bark2", "eucalyptus", "eucap5"]
SHARED = shared_path("bark", "thesis_runs")


def _gray(labels: np.ndarray) -> np.ndarray:
    k = max(int(labels.max()), 1)
    return (labels.astype(np.float32) / k)[..., None].repeat(3, axis=2)


def thesis_map(run: str, name: str) -> np.ndarray:
    img = phloem.io.read_image(SHARED / run / f"{name}.png")
    flat = np.round(img.reshape(img.shape[0], img.shape[1], -1) * 255).astype(np.int32)
    _, inv = np.unique(flat.reshape(-1, flat.shape[2]), axis=0, return_inverse=True)
    return inv.reshape(flat.shape[:2]).astype(np.int32)


def _timed(fn, *args, **kw):  # type: ignore[no-untyped-def]
    t = time.perf_counter()
    out = fn(*args, **kw)
    return out, time.perf_counter() - t


def bark_row() -> list[np.ndarray]:
    lab = bark_labels()
    tiles = [
        _label(_fit(phloem.data.bark()), "embedded bark"),
        _label(_fit(_gray(lab)), f"k-means labels (3) c={shapes.chord_length(lab):.0f}"),
    ]
    for method, size, rot in [
        ("layered", 256, "all"),
        ("joint", 256, "all"),
        ("joint", 512, "all"),
        ("joint", 256, "none"),
        ("joint", 256, "half"),
    ]:
        out, dt = _timed(shapes.synthesize_labels, lab, size, method=method, rotations=rot, seed=0)
        sim = shapes.shape_similarity(lab, out)
        name = f"{method} {size}" + {"all": "", "none": " no rot.", "half": " half"}[rot]
        tiles.append(_label(_fit(_gray(out)), f"{name}: D={sim:.2f} c={shapes.chord_length(out):.0f} {dt:.1f}s"))
    return tiles


def thesis_row(run: str) -> list[np.ndarray]:
    a, b = thesis_map(run, "a"), thesis_map(run, "b")
    tiles = [_label(_fit(_gray(a)), f"{run} a ({a.max() + 1} labels) c={shapes.chord_length(a):.0f}")]
    tiles.append(
        _label(_fit(_gray(b)), f"thesis b: D={shapes.shape_similarity(a, b):.2f} c={shapes.chord_length(b):.0f}")
    )
    for method in shapes.METHODS:
        out, dt = _timed(shapes.synthesize_labels, a, b.shape, method=method, seed=0)
        d, c = shapes.shape_similarity(a, out), shapes.chord_length(out)
        tiles.append(_label(_fit(_gray(out)), f"{method}: D={d:.2f} c={c:.0f} {dt:.1f}s"))
    return tiles + [np.ones_like(tiles[0])] * 3


def main(out: Path) -> None:
    rows = [bark_row()]
    if SHARED.exists():
        rows += [thesis_row(r) for r in RUNS]
    sheet = write_sheet(rows, out)
    print(f"wrote {out} ({sheet.shape[1]}x{sheet.shape[0]})")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/shapes_sheet.png"))
