"""``phloem nnf``: a nearest-neighbour field of :func:`phloem.patch.nnf` between two image files."""

from __future__ import annotations

import argparse
import io as _pyio
import time
from pathlib import Path
from typing import Any

import numpy as np

from .. import io, patch
from ._common import common_options, positive, stage, transaction


def _cmd_nnf(args: argparse.Namespace) -> None:
    out = Path(args.out)
    if out.suffix.lower() != ".npz":
        raise ValueError(f"out: expected a .npz file for the field, got {out.name}")
    transaction().reserve(out)
    src = io.read_image(args.source, max_pixels=args.max_pixels)
    tgt = io.read_image(args.target, max_pixels=args.max_pixels)
    t0 = time.perf_counter()
    field, dist = patch.nnf(
        src, tgt, patch_size=args.patch_size, iterations=args.iterations, method=args.method, levels=args.levels,
        seed=args.seed, threads=args.threads, max_memory=args.max_memory,
    )  # fmt: skip
    buf = _pyio.BytesIO()
    np.savez_compressed(buf, field=field, distance=dist)
    note = f"nnf: {time.perf_counter() - t0:.2f} s, mean distance {float(dist.mean()):.4g}; wrote {out}"
    stage(out, buf.getvalue(), args, note=note)


def add_parsers(sub: Any) -> None:
    p = sub.add_parser("nnf", help="nearest-neighbour field between two images, saved as .npz",
                       description="PatchMatch (Barnes et al. 2009) or exact search; writes arrays 'field' (H, W, 2) and 'distance' (H, W).")  # fmt: skip
    p.add_argument("source", metavar="SOURCE", help="image the patches come from")
    p.add_argument("target", metavar="TARGET", help="image whose pixels get matches")
    p.add_argument("--out", required=True, metavar="OUT.npz", help="output .npz file")
    p.add_argument("--patch-size", type=int, default=7, help="patch side, odd (default 7)")
    p.add_argument("--iterations", type=int, default=5, help="PatchMatch iterations (default 5)")
    p.add_argument("--levels", type=positive, default=1, help="coarse-to-fine pyramid levels (default 1)")
    p.add_argument("--method", choices=("patchmatch", "kdtree", "exact"), default="patchmatch",
                   help="search method: patchmatch (default); kdtree, PatchMatch seeded by a PCA kd-tree search "
                   "(He & Sun 2012: within a few %% of exact, ~4x the time); exact")  # fmt: skip
    common_options(p, writes=False)
    p.add_argument("--force", action="store_true", help="replace OUT if it exists")
    p.set_defaults(func=_cmd_nnf)
