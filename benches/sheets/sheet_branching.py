"""Contact sheet of the whole branching pipeline (Sibbing et al. 2010) on real examples.

    python -m benches.sheets.sheet_branching OUT.png [--seed 1] [--tile 360]

One row per example, each: the input, its traced skeleton (red), the grown skeleton (white),
the new image, and the input (grey) / output (orange) angle and thickness histograms of Fig. 7.
Examples from ../shared/data/branching (they stay there): a retina (vessels; growth is kept
inside the fundus by a guidance map and the completion copies only fundus pixels), the Colville
delta mask (a river mask; the crop below the sea) and the Jacksboro fault elevation model
(ridges; min-max normalised). Timings per stage are printed.

The retina and the river use a resampling step h = 10 px instead of the default (the median
thickness, 2.5 px here): the bending model's history of k = 3 steps then spans 30 px, so long
branches keep their direction instead of curling (the paper clicked its skeletons by hand, with
far fewer vertices than a traced one).
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

import cv2
import numpy as np

import phloem
from phloem import branching as br
from phloem.testing import shared_path

from ._sheet import _fit, _label, _rgb, write_sheet

SHARED = shared_path("branching")


def examples() -> list[tuple[str, np.ndarray, dict[str, Any], dict[str, Any]]]:
    """(name, image, trace options, extra synthesis options)."""
    out = []
    retina = phloem.io.read_image(SHARED / "skimage_retina.jpg")
    retina = cv2.resize(retina, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)
    fundus = cv2.erode((retina.mean(axis=2) > 0.06).astype(np.uint8), np.ones((9, 9), np.uint8)) > 0
    out.append(("retina (vessels)", retina, {"kind": "dark", "channel": 1, "sigmas": (1.0, 2.0, 3.0)},
                {"h": 10.0, "guide": (~fundus).astype(np.float64), "render_options": {"valid": fundus}, "mask": fundus}))  # fmt: skip
    colville = phloem.io.read_image(SHARED / "rivgraph_colville_delta_mask.png")[450:1450, 200:1400]
    colville = cv2.resize(colville, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)
    out.append(("Colville delta (river mask)", colville, {"kind": "mask"}, {"h": 10.0}))
    dem = phloem.io.read_image(SHARED / "mpl_jacksboro_fault_dem_u16.png")
    dem = ((dem - dem.min()) / (dem.max() - dem.min())).astype(np.float32)
    out.append(("Jacksboro fault (elevation, ridges)", dem, {"kind": "bright", "sigmas": (3.0, 6.0)}, {}))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--tile", type=int, default=360)
    args = ap.parse_args()
    if not SHARED.exists():
        print(f"{SHARED} is missing: this sheet needs the branching examples", file=sys.stderr)
        return 1
    rows = []
    for name, img, topts, extra in examples():
        mask = extra.pop("mask", None)
        t0 = time.perf_counter()
        res = br.synthesize(img, trace_options=topts, seed=args.seed, **extra)
        dt = time.perf_counter() - t0
        out = _rgb(res.image)
        if mask is not None:  # keep the photo's black surround
            out = np.where(mask[..., None], out, _rgb(img))
        hfig = br.histogram_figure(res.source, res.target, h=res.bending.h, width=2 * args.tile, height=args.tile // 2)
        hist = np.full((args.tile, 2 * args.tile, 3), 1.0, np.float32)
        hist[args.tile // 4 : args.tile // 4 + hfig.shape[0]] = hfig
        n_src = sum(len(b) for b in res.source.branches)
        n_new = sum(len(b) for b in res.target.branches)
        print(f"{name}: {img.shape[1]}x{img.shape[0]}, source {len(res.source.branches)} branches, new {len(res.target.branches)} "
              f"branches ({n_new} vertices at h={res.bending.h:.2f}; source {n_src}), {len(res.render.targets)} fragments, {dt:.1f} s")  # fmt: skip
        traced = res.source.draw(_rgb(img), color=(1, 0.1, 0.1), width=2)
        grown = res.target.draw(size=res.target.shape, color=(1, 1, 1), width=2)
        tiles = [
            _label(_fit(img, args.tile, cv2.INTER_AREA), name),
            _label(_fit(traced, args.tile, cv2.INTER_AREA), "traced skeleton"),
            _label(_fit(grown, args.tile, cv2.INTER_AREA), "grown skeleton"),
            _label(_fit(out, args.tile, cv2.INTER_AREA), f"new image, {dt:.1f} s"),
            _label(hist, "angle / thickness histograms: input grey, output orange"),
        ]
        rows.append(np.concatenate(tiles, axis=1))
    write_sheet(rows, args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
