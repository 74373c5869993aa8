"""``phloem synthesize``, ``phloem quilt`` and ``phloem complete``: :mod:`phloem.texture` on files."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

from .. import io, texture
from .._masks import hole_from_mask
from ..texture.quilt import _default_block, _default_overlap
from ..texture.synthesis import _auto_levels
from ._common import common_options, non_negative, parse_size, positive, preflight, run, save


def _from_exemplar(
    args: argparse.Namespace, command: str, job: Callable[[Any, Any], Any], resolve: Callable[[Any], None]
) -> None:
    """One exemplar file in, one texture file out: ``job(exemplar, bar)`` makes the texture;
    ``resolve(exemplar)`` then sets the defaults it used on ``args``, for the sidecar."""
    preflight(args)
    ex = io.read_image(args.input, max_pixels=args.max_pixels)
    out = run(command, args, lambda bar: job(ex, bar))
    resolve(ex)
    save(args, command, out)


def _cmd_synthesize(args: argparse.Namespace) -> None:
    def resolve(ex: Any) -> None:
        if args.levels is None:
            args.levels = _auto_levels(min(ex.shape[:2]), args.patch_size)

    _from_exemplar(args, "synthesize", lambda ex, bar: texture.synthesize(
        ex, args.size, patch_size=args.patch_size, levels=args.levels, iterations=args.iterations,
        diversity=args.diversity, tileable=args.tileable, seed=args.seed, threads=args.threads, progress=bar,
        max_memory=args.max_memory,
    ), resolve)  # fmt: skip


def _cmd_quilt(args: argparse.Namespace) -> None:
    def resolve(ex: Any) -> None:
        # texture.quilt's own defaults, recorded as used
        if args.block is None:
            args.block = _default_block(*ex.shape[:2])
        if args.overlap is None:
            args.overlap = _default_overlap(args.block)

    _from_exemplar(args, "quilt", lambda ex, bar: texture.quilt(
        ex, args.size, block=args.block, overlap=args.overlap, randomness=args.randomness, cost=args.cost,
        tileable=args.tileable, seed=args.seed, threads=args.threads, progress=bar, max_memory=args.max_memory,
    ), resolve)  # fmt: skip


def _cmd_complete(args: argparse.Namespace) -> None:
    preflight(args)
    img = io.read_image(args.input, max_pixels=args.max_pixels)
    hole = hole_from_mask(io.read_image(args.mask, max_pixels=args.max_pixels), args.mask, alpha=args.mask_alpha,
                          invert=args.invert_mask)  # fmt: skip
    if hole.shape != img.shape[:2]:
        raise ValueError(
            f"mask: {args.mask} is {hole.shape[1]}×{hole.shape[0]}, but the image is {img.shape[1]}×{img.shape[0]}"
        )
    out = run(
        "complete",
        args,
        lambda bar: texture.complete(
            img,
            hole,
            patch_size=args.patch_size,
            levels=args.levels,
            iterations=args.iterations,
            diversity=args.diversity,
            finest=args.finest,
            start=args.start,
            tileable=args.tileable,
            seed=args.seed,
            threads=args.threads,
            max_memory=args.max_memory,
            progress=bar,
        ),
    )
    save(args, "complete", out)


def _exemplar_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", metavar="IN", help="exemplar image (PNG, JPEG or TIFF)")
    p.add_argument(
        "--size",
        type=parse_size,
        required=True,
        metavar="WxH",
        help="output width x height in pixels, e.g. 512x384, or N for NxN",
    )
    p.add_argument("--out", required=True, metavar="OUT", help="output image (.png, .jpg, .tif)")


def add_parsers(sub: Any) -> None:
    p = sub.add_parser("synthesize", help="synthesise a texture of any size from an exemplar image",
                       description="Texture optimisation (Kwatra et al. 2005) over an image pyramid, with PatchMatch search and robust patch voting.")  # fmt: skip
    _exemplar_arguments(p)
    p.add_argument("--patch-size", type=int, default=7, help="patch side, odd (default 7)")
    p.add_argument("--levels", type=positive, default=None, help="pyramid levels (default: from the exemplar size)")
    p.add_argument("--iterations", type=positive, default=4, help="search-and-vote iterations per level (default 4)")
    p.add_argument("--diversity", type=non_negative, default=1.0,
                   help="weight of the occurrence penalty (Kaspar et al. 2015) that keeps the output from settling on a "
                        "few, usually the smoothest, exemplar patches; 0 is plain texture optimisation (default 1)")  # fmt: skip
    p.add_argument("--tileable", action="store_true",
                   help="make OUT tile: synthesise on a torus, so copies of OUT placed side by side show no seam")  # fmt: skip
    common_options(p)
    p.set_defaults(func=_cmd_synthesize)

    p = sub.add_parser("quilt", help="texture of any size from exemplar blocks joined along graph-cut seams",
                       description="Graph-cut quilting (Kwatra et al. 2003): exemplar blocks placed by entire-patch matching, "
                                   "cut into the output along minimum-cost seams. Every output pixel is an exemplar pixel.")  # fmt: skip
    _exemplar_arguments(p)
    p.add_argument(
        "--block",
        type=positive,
        default=None,
        help="side of the exemplar blocks (default: 64, or half the exemplar's shorter side)",
    )
    p.add_argument(
        "--overlap", type=positive, default=None, help="overlap of neighbouring blocks in pixels (default: block/4)"
    )
    p.add_argument("--randomness", type=float, default=0.01,
                   help="Kwatra's k: 0 always takes the best-matching block, larger values pick worse matches more often (default 0.01)")  # fmt: skip
    p.add_argument("--cost", choices=("kwatra", "gradient", "luo"), default="kwatra",
                   help="seam cost: colour difference, gradient-normalised colour difference, or Luo et al.'s d^4/G (default kwatra)")  # fmt: skip
    p.add_argument("--tileable", action="store_true",
                   help="make OUT tile: the last blocks of each row and column overlap the first ones across the "
                        "wrap and are cut into them along seams (needs sides of at least block + 2)")  # fmt: skip
    common_options(p)
    p.set_defaults(func=_cmd_quilt)

    p = sub.add_parser("complete", help="fill a masked region of an image from the rest of it",
                       description="Coarse-to-fine patch-based completion (Wexler et al. 2007) on PatchMatch.")  # fmt: skip
    p.add_argument("input", metavar="IN", help="image with a region to fill")
    p.add_argument("mask", metavar="MASK", help="image of the same size, white where pixels are to be filled")
    p.add_argument("--out", required=True, metavar="OUT", help="output image (.png, .jpg, .tif)")
    p.add_argument(
        "--mask-alpha",
        action="store_true",
        help="take the hole from MASK's alpha channel: every pixel that is not fully opaque is filled "
        "(MASK must have alpha)",
    )
    p.add_argument(
        "--invert-mask",
        action="store_true",
        help="flip the mask's meaning: fill where MASK is black (or, with --mask-alpha, opaque)",
    )
    p.add_argument("--patch-size", type=int, default=7, help="patch side, odd (default 7)")
    p.add_argument("--levels", type=positive, default=None, help="pyramid levels (default: from the hole size)")
    p.add_argument("--iterations", type=positive, default=None,
                   help="search-and-vote iterations per level (default: 1 + 2 x level, coarsest level highest)")  # fmt: skip
    p.add_argument("--diversity", type=non_negative, default=0.0,
                   help="weight of the occurrence penalty (Kaspar et al. 2015): a large hole filled from few sources "
                        "settles on the smoothest ones; 1 spreads the fill over more of them (default 0: off)")  # fmt: skip
    p.add_argument("--finest", choices=("vote", "copy"), default="vote",
                   help="the full-resolution level's last step: the weighted mean of the overlapping matches (vote, "
                        "Wexler's) or each pixel copied from its own match (copy: keeps a grainy texture's grain)")  # fmt: skip
    p.add_argument("--start", choices=("auto", "blocks"), default="auto",
                   help="what the coarsest level starts from: the rim peeled inward (auto) or random source blocks "
                        "(blocks; it also skips coarse levels with too few sources for their hole, so that a grainy "
                        "fill copies many sources instead of repeating a few)")  # fmt: skip
    p.add_argument("--tileable", action="store_true",
                   help="IN is a tile: its opposite borders touch, so the hole may cross them, is filled from the "
                        "context on the other side, and the result still tiles")  # fmt: skip
    common_options(p)
    p.set_defaults(func=_cmd_complete)
