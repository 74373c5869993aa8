"""``phloem trees``: new tree billboards from a library folder (:mod:`phloem.trees`)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from .. import _json, io, trees
from ._common import (
    check_writable,
    common_options,
    deprecated_alias,
    parse_square_size,
    positive,
    run,
    stage_image,
    stage_result,
    sub_seed,
    transaction,
)


def _tree_library(args: argparse.Namespace, bar: Any) -> trees.Library:
    src = Path(args.library)
    clf = None
    if args.trunk_model is not None:
        data = _json.read_json(args.trunk_model, "trunk_model")
        try:
            clf = trees.TrunkClassifier.from_dict(data)
        except ValueError as exc:
            raise ValueError(f"trunk_model: {args.trunk_model}: {str(exc).removeprefix('data: ')}") from None
    return trees.Library.load(
        src, atlas=args.atlas, size=args.size, skip_bad=args.skip_bad, classifier=clf, max_pixels=args.max_pixels,
        progress=bar, max_memory=args.max_memory, cache=args.library_cache,
    )  # fmt: skip


def _cmd_trees(args: argparse.Namespace) -> None:
    out_dir = Path(args.out_dir)
    targets = [out_dir / f"{args.prefix}{i:04d}.png" for i in range(args.n_variations)]
    if out_dir.exists() and not out_dir.is_dir():
        raise ValueError(f"out-dir: {out_dir} exists and is not a folder")
    transaction().make_folders = True  # DIR is made when the trees are written, and removed if that fails
    for t in targets:
        check_writable(t, args)
        transaction().reserve(io.sidecar_path(t))
    if args.sheet is not None:
        check_writable(Path(args.sheet), args)
    like = None if args.like is None else io.read_image(args.like, max_pixels=args.max_pixels)
    lib = run("trees: library", args, lambda bar: _tree_library(args, bar))
    if not args.quiet:
        print(f"library: {len(lib)} trees", file=sys.stderr)

    colors = args.colors = args.colors or ("contour" if like is not None else "random")  # recorded resolved

    def make(bar: Any) -> list[trees.Variation]:
        if like is not None:
            own = trees.prepare(like, size=args.size)
            out = []
            # One vary call per variation, each with its own seed (the sidecar's variation_seed), so any
            # tree can be remade alone; vary(progress=) would draw all from one seed, so the loop draws the bar.
            for i in range(args.n_variations):
                out += trees.vary(own, lib, n_variations=1, seed=sub_seed(args.seed, i), n_sources=args.n_sources, colors=colors,
                                  histogram=args.histogram, threads=args.threads, max_memory=args.max_memory)  # fmt: skip
                bar(i + 1, args.n_variations)
            return out
        res = []
        for i in range(args.n_variations):
            res.append(trees.variation(lib, n_sources=args.n_sources, seed=sub_seed(args.seed, i), colors=colors,
                                       histogram=args.histogram, threads=args.threads, max_memory=args.max_memory))  # fmt: skip
            bar(i + 1, args.n_variations)
        return res

    variations = run("trees: variations", args, make)
    for i, (v, path) in enumerate(zip(variations, targets)):
        rec = v.describe(lib)
        if like is not None:
            rec["exemplars"] = [str(args.like), *rec["exemplars"]]
        stage_result(path, v.image, args, "trees", {**rec, "variation_seed": sub_seed(args.seed, i)}, quiet=True)
    if not args.quiet:
        transaction().notes.append(f"wrote {len(targets)} trees (and their .json) to {out_dir}")
    if args.sheet is not None:
        sheet = run("trees: sheet", args, lambda bar: _tree_sheet(lib, variations, args))
        stage_image(args.sheet, sheet, args)


def _tree_sheet(lib: trees.Library, variations: Sequence[trees.Variation], args: argparse.Namespace) -> np.ndarray:
    """Fig. 13 and Fig. 14 tables for up to six exemplars, then a row of the new trees."""
    rng = np.random.default_rng(args.seed)
    k = min(6, len(lib))
    picks = sorted(int(i) for i in rng.choice(len(lib), size=k, replace=False))
    chosen = [lib[i] for i in picks]
    tile = 160
    if k >= 2:
        tables = [trees.morph_table(chosen, tile=tile, colors=False, threads=args.threads),
                  trees.morph_table(chosen, tile=tile, threads=args.threads)]  # fmt: skip
        top = np.concatenate(tables, axis=1)
    else:
        top = np.full((tile, tile, 3), 0.8, np.float32)
    width = top.shape[1]
    per_row = max(1, width // tile)
    rows = []
    for r in range(0, len(variations), per_row):
        row = np.full((tile, width, 3), 0.8, np.float32)
        for c, v in enumerate(variations[r : r + per_row]):
            small = cv2.resize(v.image, (tile, tile), interpolation=cv2.INTER_AREA)
            a = small[..., 3:4]
            row[:, c * tile : (c + 1) * tile] = small[..., :3] * a + 0.8 * (1 - a)
        rows.append(row)
    return np.concatenate([top, *rows], axis=0)


def add_parsers(sub: Any) -> None:
    p = sub.add_parser("trees", help="new tree billboards from a library of RGBA trees (Argudo et al. 2017)",
                       description="Every tree of LIBRARY is normalised, segmented into crown and trunk and described by a "
                                   "2000-point contour (§4). Each new tree's contour is a random convex combination of the "
                                   "contours of --n-sources trees, filled by mean value coordinate colour transfer from them (§5). "
                                   "Writes DIR/PREFIX0000.png ... with a .json sidecar naming the sources and weights.")  # fmt: skip
    p.add_argument(
        "library",
        metavar="LIBRARY",
        help="folder of RGBA tree images (atlases of several trees are split), or one atlas image",
    )
    count = p.add_mutually_exclusive_group(required=True)  # so that the old --count alone satisfies it
    count.add_argument("--n-variations", type=positive, metavar="N", help="number of new trees")
    deprecated_alias(count, "--count", "--n-variations", dest="n_variations", type=positive)
    p.add_argument("--out-dir", required=True, metavar="DIR", help="folder for the new trees (created if missing)")
    p.add_argument("--prefix", default="tree_", help="file name prefix of the new trees (default tree_)")
    p.add_argument("--like", metavar="TREE", default=None,
                   help="make variations of this RGBA tree: it gets weight 0.6-0.9 and the library trees the rest (§3)")  # fmt: skip
    p.add_argument(
        "--size",
        type=parse_square_size,
        default=1024,
        metavar="N",
        help="side N (or NxN) of the square output images; the library is normalised to it (default 1024)",
    )
    p.add_argument(
        "--n-sources", type=positive, default=2, help="trees combined in each new tree, --like included (default 2)"
    )
    deprecated_alias(p, "--sources", "--n-sources", dest="n_sources", type=positive)
    p.add_argument("--colors", choices=("random", "contour", "single"), default=None,
                   help="colour weights: an independent random convex combination (§5.2), the contour's weights, or one source "
                        "(default: random; contour with --like)")  # fmt: skip
    p.add_argument(
        "--histogram", action="store_true", help="match each tree's colour histogram to another library tree (§5.3)"
    )
    p.add_argument(
        "--atlas",
        choices=("auto", "yes", "no"),
        default="auto",
        help="split library images into single trees: auto (default), yes, no",
    )
    p.add_argument("--trunk-model", metavar="JSON", default=None,
                   help="crown/trunk segmentation by a classifier trained with phloem.trees.TrunkClassifier.fit and saved with "
                        "to_dict (default: the training-free width-profile segmenter)")  # fmt: skip
    p.add_argument("--library-cache", metavar="DIR", default=None,
                   help="keep the prepared library in DIR and reuse it while LIBRARY's images, these options and the "
                        "phloem version are unchanged (checked by a SHA-256 of them); preparing it is most of a run's "
                        "time (default: prepare it every run)")  # fmt: skip
    p.add_argument(
        "--skip-bad",
        action="store_true",
        help="skip library images that cannot be used (no alpha, empty) instead of stopping",
    )
    p.add_argument("--sheet", metavar="PNG", default=None,
                   help="also write a contact sheet: the combination tables of the paper's Fig. 13-14 for six library trees, then the new trees")  # fmt: skip
    common_options(p)
    p.set_defaults(func=_cmd_trees)
