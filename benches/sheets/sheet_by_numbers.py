"""Contact sheet of texture-by-numbers: look at it before trusting any number.

    python -m benches.sheets.sheet_by_numbers out/by_numbers_sheet.png

One row per thesis run in ``../shared/data/bark/thesis_runs`` (Laitoch 2018; skipped when the
folder is absent): the photo ``ai``, its label map ``a``, the output label map ``b``, the
thesis' result ``bi``, phloem's with every piece's labels enforced (``stand_in_weight=None``)
and phloem's default (pieces run across label boundaries on stand-ins), with patch coherence
to ``ai`` (lower is better), the per-label histogram distance (lower is better) and the label
agreement (higher is better) of each; then a row on the embedded bark with a two-label map.
The last panel of every row shows phloem's sources (red = exemplar row, green = column):
smooth patches are coherent copies, speckle is pixel-wise mixing.
"""

from __future__ import annotations

import sys
import time
from dataclasses import astuple

import cv2
import numpy as np

import phloem
from phloem.metrics import label_agreement, label_histogram_distance, patch_coherence
from phloem.testing import shared_path

from ..python.bench_tbn import _labels as _gray_labels
from ._sheet import TILE, _fit, _label, write_sheet
from ._sheet import _field_colour as _sources

RUNS = shared_path("bark", "thesis_runs")


def row(name: str, ai: np.ndarray, a: np.ndarray, b: np.ndarray, bi: np.ndarray | None) -> tuple[np.ndarray, str]:
    t0 = time.perf_counter()
    out, src = astuple(phloem.texture.by_numbers(ai, a, b, seed=0, full_output=True))
    dt = time.perf_counter() - t0
    strict = phloem.texture.by_numbers(ai, a, b, seed=0, stand_in_weight=None)
    coh, hist, agree = patch_coherence(out, ai), label_histogram_distance(out, b, ai, a), label_agreement(out, b, ai, a)
    tiles = [
        _label(_fit(ai), f"{name} ai {ai.shape[1]}x{ai.shape[0]}"),
        _label(_fit(phloem.bark.encode_labels(a)), f"a: {np.unique(a).size} labels"),
        _label(_fit(phloem.bark.encode_labels(b)), f"b {b.shape[1]}x{b.shape[0]}"),
    ]
    line = f"{name}: phloem {dt:.2f} s, coherence {coh:.5f}, hist {hist:.3f}, agreement {agree:.3f}"
    if bi is not None:
        bi = bi[: b.shape[0], : b.shape[1]]
        cb, hb = patch_coherence(bi, ai), label_histogram_distance(bi, b, ai, a)
        ab = label_agreement(bi, b, ai, a)
        tiles.append(_label(_fit(bi), f"thesis bi: coh {cb * 1e3:.3f}e-3 hist {hb:.3f} agr {ab:.3f}"))
        line += f"; thesis bi coherence {cb:.5f}, hist {hb:.3f}, agreement {ab:.3f}"
        line += f"; ratios {coh / cb:.2f}, {hist / hb:.2f}"
    else:
        tiles.append(_label(np.ones((TILE, TILE, 3), np.float32), "(no thesis result)"))
    cs, hs = patch_coherence(strict, ai), label_histogram_distance(strict, b, ai, a)
    as_ = label_agreement(strict, b, ai, a)
    tiles.append(_label(_fit(strict), f"no stand-ins: coh {cs * 1e3:.3f}e-3 hist {hs:.3f} agr {as_:.3f}"))
    tiles.append(_label(_fit(out), f"phloem {dt:.2f}s: coh {coh * 1e3:.3f}e-3 hist {hist:.3f} agr {agree:.3f}"))
    tiles.append(_label(_fit(_sources(src, ai.shape)), "phloem sources (R row, G col)"))
    return np.concatenate(tiles, axis=1), line


def main(out_path: str) -> None:
    rows, lines = [], []
    if RUNS.exists():
        for name in ["bark1", "bark2", "eucalyptus", "eucap5"]:
            d = RUNS / name
            ai = phloem.io.read_image(next(d.glob("ai.*")))[..., :3]
            bi = phloem.io.read_image(d / "bi.png")[..., :3]
            r, line = row(name, ai, _gray_labels(d / "a.png"), _gray_labels(d / "b.png"), bi)
            rows.append(r)
            lines.append(line)
    bark = phloem.data.bark()[..., :3]
    ex = np.ascontiguousarray(bark[:, :128])

    def two(img: np.ndarray) -> np.ndarray:
        g = cv2.GaussianBlur(img.mean(axis=2), (0, 0), 2.0)
        return (g > np.median(g)).astype(np.int32)

    r, line = row("embedded bark", ex, two(ex), two(bark[:, 128:]), None)
    rows.append(r)
    lines.append(line)
    write_sheet(rows, out_path)
    print("\n".join(lines))
    print(f"wrote {out_path}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "out/by_numbers_sheet.png")
