"""Contact sheet of ``phloem.branching.synthesize`` with its defaults on real inputs (issue 19).

    PYTHONPATH=python python -m benches.sheets.sheet_branching_real --out OUT.png [--inputs DIR] [--seed 0]
        [--max-side N] [--tuned-trace] [--sigmas S ...] [--gap G] [--subpixel] [--threshold-scale F] [--gap-diversity L] [--layout W] [--only NAME ...]

One row per image of ``--inputs`` (default: ``branching`` of the real-image collection):
input | input with its traced skeleton | grown skeleton | output image | output with its own
re-traced skeleton. Skeletons are drawn as sheet_branching_trace draws them (roots red,
children yellow, deeper cyan, the traced radii as a green outline). The captions carry the
measures of benches/quality/branching_quality.py: largest-tree share of input and output,
median heading change over 60 px and the drift L1, re-trace F1, two-level fraction (masks),
the share of the length along the frame, the input's direction concentration ("one way"), the
output's direction-histogram distance to it ("dirs", beside the re-trace), and the shares of the
input's structure contrast and background grain the output kept, and the repetition of the
output's fine grain in the gaps as a multiple of the input background's ("gaps' rep"; over the
whole image and the gaps on the printed line, with what stands out past the branches' free
ends, ``past_end_share``, the share of branches that end on other structure,
``joined_end_share``, how far the ends thin, the last ratio of ``end_taper``, and the share
of children wider than their parent, ``wider_children``).
``--tuned-trace``, ``--sigmas``, ``--gap``, ``--subpixel``, ``--threshold-scale``,
``--gap-diversity`` and ``--layout`` are those of the quality script.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import cv2
import numpy as np

from benches.quality.branching_quality import (
    add_run_arguments,
    inputs,
    load,
    measure,
    render_options_of,
    retrace_options,
    run,
    trace_options_of,
)
from phloem.branching import trace
from phloem.testing import shared_path

from ._sheet import TILE, _fit, _label, write_sheet
from .sheet_branching_trace import overlay


def _show(img: np.ndarray) -> np.ndarray:
    """Gray or colour in [0, 1] for display: a low-contrast field (an elevation model) is stretched."""
    lo, hi = float(img.min()), float(img.max())
    return (img - lo) / (hi - lo) if hi - lo < 0.25 and hi > lo else np.clip(img, 0, 1)


def row(path: Path, seed: int, max_side: int, args: argparse.Namespace) -> list[np.ndarray]:
    img, mask = load(path, max_side)
    opts = trace_options_of(args, path.name, mask)
    name = path.stem[:22]
    res, seconds, error = run(
        img, seed, trace_options=opts, threads=2, render_options=render_options_of(args), layout=args.layout
    )
    if res is None:
        print(f"{path.name}: {error}")
        blank = np.ones((TILE, TILE, 3), np.float32)
        return [_label(_fit(_show(img), interpolation=cv2.INTER_AREA), f"{name}: {error[:30]}")] + [blank] * 4
    r = measure(path.name, img, mask, seed, res, seconds, trace_options=opts)
    w = max(1, round(max(img.shape[:2]) / TILE))
    try:
        retraced = overlay(_show(res.image), trace(res.image, **retrace_options(img, res.image, opts)), w)
    except ValueError:  # nothing to trace
        retraced = _show(res.image)
    two = "" if r.two_level is None else f", 2-level {100 * r.two_level:.1f}%"
    # the measure needs three branches of 16 vertices; say so only where it could not be taken
    short = " (nan: too few long branches)" if math.isnan(r.taper_in) or math.isnan(r.taper_out) else ""
    print(
        f"{path.name}: F1 {r.f1:.2f}, share {r.share_in:.2f}->{r.share_out:.2f}, drift {r.drift:.2f}{two}, "
        f"grain repetition {r.repetition_in:.3f}->{r.repetition_out:.3f} (gaps {r.gap_repetition_in:.3f}->"
        f"{r.gap_repetition_out:.3f}), empty space {r.empty_in:.0f}->{r.empty_out:.0f} px, "
        f"layout {r.layout_in:.2f}->{r.layout_out:.2f}, past ends {r.past_end_in:.3f}->{r.past_end_out:.3f}, "
        f"joined ends {r.joined_in:.2f}->{r.joined_out:.2f}, ends' taper {r.taper_in:.2f}->{r.taper_out:.2f}{short}, "
        f"wider children {r.wider_in:.2f}->{r.wider_out:.2f}"
    )
    return [
        _label(_fit(_show(img), interpolation=cv2.INTER_AREA), f"{name} seed {seed}, {seconds:.0f} s"),
        _label(_fit(overlay(_show(img), res.source, w), interpolation=cv2.INTER_AREA),
               f"traced: tree {r.share_in:.2f}, turn {r.heading_in:.2f} rad, frame {r.border_in:.2f}, one way {r.concentration:.2f}"),
        _label(_fit(overlay(np.zeros(img.shape[:2], np.float32), res.target, w), interpolation=cv2.INTER_AREA),
               f"grown: tree {r.share_out:.2f}, turn {r.heading_out:.2f}, drift {r.drift:.2f} (noise {r.drift_noise:.2f}), frame {r.border_out:.2f}"),
        _label(_fit(_show(res.image), interpolation=cv2.INTER_AREA),
               f"output{two}, kept: contrast {r.contrast_out / r.contrast_in if r.contrast_in else float('nan'):.2f}"
               + (f", grain {r.grain_out / r.grain_in:.2f}" if r.grain_in > 0 else "")
               + (f", gaps' rep ×{r.gap_repetition_out / r.gap_repetition_in:.1f}" if r.gap_repetition_in > 0 else "")),
        _label(_fit(retraced, interpolation=cv2.INTER_AREA),
               f"re-traced: F1 {r.f1:.2f} (P {r.precision:.2f} R {r.recall:.2f}), dirs {r.directions:.2f}"),
    ]  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="out/branching_real_sheet.png")
    ap.add_argument("--inputs", type=Path, default=None, help="folder of images (default: shared branching set)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-side", type=int, default=0, help="scale inputs down to this long side first (0: no)")
    add_run_arguments(ap)
    ap.add_argument("--only", nargs="*", default=None, help="file names to show (default: all)")
    args = ap.parse_args(argv)
    folder = args.inputs if args.inputs is not None else shared_path("branching")
    paths = [p for p in inputs(folder) if not args.only or p.name in args.only] if folder.is_dir() else []
    if not paths:
        print(f"no images in {folder}", file=sys.stderr)
        return 1
    write_sheet([row(p, args.seed, args.max_side, args) for p in paths], args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
