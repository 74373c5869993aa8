"""``phloem branching trace|grow|render|run``: :mod:`phloem.branching` on images and skeleton files."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from .. import _json, branching, io
from ..branching._fragment_map import fragment_map
from ..branching.bending import DENOISE, STEM_THICKNESS, TURN_HISTOGRAM
from ..branching.measures import resolve_trace_options
from ..branching.pipeline import DENOISE_COURSE, GUIDED_TURN_HISTOGRAM, N_BEST
from ._common import (
    check_writable,
    common_options,
    deprecated_alias,
    kept,
    non_negative,
    parse_size,
    positive,
    preflight,
    recall,
    remember,
    run,
    save,
    sidecar,
    stage,
    stage_image,
    stamp,
    transaction,
)

_TRACE_KINDS = ("auto", "bright", "dark", "mask")


def _trace_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("tracing (when no skeleton file is given)")
    g.add_argument("--kind", choices=_TRACE_KINDS, default="auto",
                   help="what the structure looks like: a binary mask, bright ridges (lightning, ridges of an elevation model) "
                        "or dark ones (vessels, cracks, rivers on land); auto decides (default)")  # fmt: skip
    g.add_argument("--sigmas", type=float, nargs="+", default=[1.0, 2.0, 3.0], metavar="S",
                   help="ridge-filter scales in pixels, about the radii of the structures to find (default 1 2 3)")  # fmt: skip
    g.add_argument(
        "--channel",
        type=int,
        default=None,
        help="trace this channel of a colour image (e.g. 1 = green for retinas; default: luminance)",
    )
    g.add_argument(
        "--threshold",
        type=float,
        default=None,
        metavar="T",
        help="ridge-filter response (photos) or level (masks) that counts as structure; default: Otsu's threshold of "
        "the response, raised on a grainy surface (asphalt) until the grain is shed, and halfway between the image's "
        "extremes for a mask. Lower it to keep more of a faint structure, grain included",
    )
    g.add_argument(
        "--threshold-scale",
        type=float,
        default=1.0,
        metavar="F",
        help="multiply the default ridge threshold of a photo by F instead of giving --threshold in the filter's "
        "units: below 1 keeps fainter structure, grain included (0.5 on an elevation model traces its smaller "
        "valleys too, and the new image's ground between the valleys comes out as dissected as the input's); "
        "default 1",
    )
    g.add_argument(
        "--min-length", type=float, default=8.0, help="drop traced branches shorter than this many pixels (default 8)"
    )
    g.add_argument(
        "--gap",
        type=float,
        default=None,
        metavar="PX",
        help="join the end of a traced piece to other structure at most PX ahead of it: a ridge filter breaks "
        "vessels where they cross or fork. Default 2 x the largest of --sigmas + 3 for photos (more on a grainy "
        "surface), 0 for masks. A larger gap (e.g. 30 on a fundus photo) traces a vessel network as one tree",
    )
    g.add_argument(
        "--root",
        type=float,
        nargs=2,
        default=None,
        metavar=("X", "Y"),
        help="start the traced structure there (its tree is rooted at the nearest skeleton pixel: a vessel tree at "
        "its optic disc, a river at its source). Default: each tree at its thickest far end",
    )
    g.add_argument(
        "--subpixel",
        action="store_true",
        help="evaluate the ridge filter on a twice finer grid (photos): thin lines in a glow, such as lightning, are "
        "traced whole instead of in pieces, but more of a textured surface's grain is traced too; off by default",
    )
    g.add_argument(
        "--no-wide",
        action="store_true",
        help="trace the ridge filter's scales only (photos): by default a structure wider than they reach, such as a "
        "vessel tree's trunk, is found by a second, wider filter and traced through its middle",
    )
    g.add_argument(
        "--keep-edges",
        action="store_true",
        help="keep every traced tree (photos): by default a further tree thicker than the main one's branches whose "
        "two sides differ, an edge between two regions such as a dish's rim beside a tissue section, is dropped",
    )


def _trace_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    return {
        "kind": args.kind,
        "sigmas": tuple(args.sigmas),
        "channel": args.channel,
        "threshold": args.threshold,
        "threshold_scale": args.threshold_scale,
        "min_length": args.min_length,
        "gap": args.gap,
        "root": None if args.root is None else tuple(args.root),
        "subpixel": args.subpixel,
        "wide": not args.no_wide,
        "edges": not args.keep_edges,
    }


def _write_skeleton(path: Path, sk: branching.Skeleton, args: argparse.Namespace, command: str, **details: Any) -> None:
    """A skeleton file and its sidecar, staged together."""
    side = io.sidecar_path(path)
    stage(path, sk.to_json().encode("utf-8"), args, note=f"wrote {path} and {side}")
    transaction().stage(side, sidecar(path, args, command, details))


def _resolve_kind(args: argparse.Namespace, img: np.ndarray) -> None:
    """``--kind auto`` recorded as the kind it traced with."""
    args.kind = resolve_trace_options(img, _trace_kwargs(args))["kind"]


def _resolve_models(args: argparse.Namespace, bend: Any) -> None:
    """The defaults of the bending model (``--h``, ``--m``, ``--course``, ``--turn-bound``) recorded as fitted."""
    args.h, args.m, args.course, args.turn_bound = bend.h, bend.m, bend.course, bend.turn_bound


def _resolve_course(args: argparse.Namespace, source: branching.Skeleton) -> None:
    """``--total-turn``, ``--repel-border``, ``--course``, ``--orientation``, ``--direction-histogram``,
    ``--turn-histogram``, ``--denoise``, ``--h``, ``--joined-ends`` and ``--layout`` left at their defaults,
    resolved for this example."""
    d = branching.source_defaults(
        source,
        total_turn=args.total_turn,
        repel_border=args.repel_border,
        course=args.course,
        orientation=args.orientation,
        direction_histogram=args.direction_histogram,
        turn_histogram=args.turn_histogram,
        denoise=args.denoise,
        h=args.h,
        joined_ends=args.joined_ends,
        layout=args.layout,
        guided=getattr(args, "guide", None) is not None,
    )
    args.total_turn, args.repel_border, args.course = d.total_turn, d.repel_border, d.course
    args.joined_ends = d.joined_ends
    args.orientation, args.direction_histogram = d.orientation, d.direction_histogram
    args.turn_histogram, args.denoise, args.h = d.turn_histogram, d.denoise, d.h
    args.layout = d.layout


def _check_json_target(path: Path, args: argparse.Namespace) -> None:
    if path.suffix.lower() != ".json":
        raise ValueError(f"out: expected a .json file for the skeleton, got {path.name}")
    transaction().reserve(path)
    transaction().reserve(io.sidecar_path(path))


def _cmd_branching_trace(args: argparse.Namespace) -> None:
    out = Path(args.out)
    _check_json_target(out, args)
    if args.overlay is not None:
        check_writable(Path(args.overlay), args)
    img = io.read_image(args.input, max_pixels=args.max_pixels)
    valid = _valid(args, img)
    sk = run("branching trace", args, lambda bar: branching.trace(img, valid=valid, **_trace_kwargs(args)))
    _resolve_kind(args, img)
    _write_skeleton(
        out, sk, args, "branching trace", branches=len(sk.branches), total_length=round(sk.total_length(), 1)
    )
    if args.overlay is not None:
        stage_image(args.overlay, sk.draw(img, width=2), args)


def _guide(path: str | None, args: argparse.Namespace) -> Any:
    if path is None:
        return None
    p = Path(path)
    if p.suffix.lower() == ".json":
        data = _json.read_json(p, "guide")
        ok = isinstance(data, list) and len(data) >= 2
        for i, q in enumerate(data if ok else []):
            if not (
                isinstance(q, list)
                and len(q) == 2
                and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in q)
            ):
                raise ValueError(f"guide: {p}: point [{i}] must be [x, y] with two numbers")
        if not ok:
            raise ValueError(f"guide: {p} must hold a JSON list of at least two [x, y] points")
        return np.asarray(data, dtype=np.float64)
    g = io.read_image(p, max_pixels=args.max_pixels)
    return (g.mean(axis=2) if g.ndim == 3 else g) > 0.5


def _share(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a share between 0 and 1, got {text!r}") from None
    if not 0 <= v <= 1:
        raise argparse.ArgumentTypeError(f"expected a share between 0 and 1, got {text}")
    return v


def _length(text: str) -> float | str:
    if text == "input":
        return text
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a length in pixels or 'input', got {text!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"expected a positive length, got {text}")
    return v


def _render_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("image synthesis (§5)")
    g.add_argument(
        "--omega-s",
        type=float,
        default=2.0,
        help="weight of the thickness term of the fragment shape distance (paper: 2)",
    )
    g.add_argument(
        "--omega-c",
        type=float,
        default=1.0,
        help="weight of colour consistency with the fragments already placed (default 1)",
    )
    g.add_argument(
        "--no-complete",
        action="store_true",
        help="leave the background black instead of completing it from the example (§5.4)",
    )
    g.add_argument(
        "--gap-diversity",
        type=non_negative,
        default=None,
        help="weight of the occurrence penalty in the completion of the gaps; above 0 the gaps are also started "
        "from random background blocks, so a grainy background keeps its grain instead of repeating a few of its "
        "patches, at some contrast of the branches (default: 1 on a grainy surface such as asphalt, where the "
        "trace's threshold climbs above Otsu's, else 0)",
    )
    g.add_argument(
        "--fragment-map", metavar="PNG", default=None, help="also write the map of which fragment painted each pixel"
    )
    _valid_option(g)


def _render_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    return {
        "omega_s": args.omega_s,
        "omega_c": args.omega_c,
        "complete": not args.no_complete,
        "gap_diversity": args.gap_diversity,
    }


def _resolve_gap_diversity(args: argparse.Namespace, img: np.ndarray, valid: Any, trace_options: Any = None) -> None:
    """``--gap-diversity`` left at its default, resolved for this example (and recorded so)."""
    if not args.no_complete:
        args.gap_diversity = branching.gap_diversity_default(
            img, valid=valid, trace_options=trace_options, gap_diversity=args.gap_diversity
        )


def _valid_option(g: Any) -> None:
    g.add_argument(
        "--valid",
        metavar="PNG|auto|none",
        default="auto",
        help="where the example shows content: a mask image (white = content, same size as IN), 'auto' "
        "(default: all but a flat frame touching the border, such as a fundus photo's black frame) or 'none'. "
        "The new image keeps a frame that runs along at least a sixth of the border, and the structure grows "
        "inside it; 'none' fills the whole image",
    )


def _valid(args: argparse.Namespace, img: np.ndarray) -> Any:
    """``--valid`` as a mask of where ``img`` shows content, or None for everywhere."""
    if args.valid == "none":
        return None
    if args.valid == "auto":
        ok = branching.valid_region(img)
        return None if ok.all() else ok
    mask = io.read_image(args.valid, max_pixels=args.max_pixels)
    if mask.shape[:2] != img.shape[:2]:
        raise ValueError(
            f"--valid: {args.valid} is {mask.shape[1]}x{mask.shape[0]}, but IN is {img.shape[1]}x{img.shape[0]}"
        )
    return (mask if mask.ndim == 2 else mask[..., :3].mean(axis=2)) > 0.5


def _grow_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("structure synthesis (§4)")
    g.add_argument("--h", type=float, default=None,
                   help="resampling step in pixels (default: the input's median thickness, at least 2 px). The model remembers --order steps, so "
                        "a larger h (e.g. 10 on a traced river) keeps long branches on course instead of curling")  # fmt: skip
    g.add_argument("--order", type=positive, default=3, help="order of the Markov bending model (the paper's k: 3)")
    deprecated_alias(g, "--k", "--order", dest="order", type=positive)
    g.add_argument(
        "--m", type=positive, default=None, help="elements appended per step, the feature size s/h (default 4)"
    )
    g.add_argument(
        "--n-best",
        type=positive,
        default=N_BEST,
        help="candidates to draw from (the paper's c): 1 follows the input exactly, more gives more variety and the "
        "--turn-histogram more to choose between (default %(default)s; paper: 2)",
    )
    deprecated_alias(g, "--c", "--n-best", dest="n_best", type=positive)
    g.add_argument(
        "--course",
        type=int,
        default=None,
        metavar="EDGES",
        help="edges over which a branch keeps its course (default 8 m where the example's course is known, "
        "as for --total-turn, else 0: the paper's Markov model alone)",
    )
    g.add_argument(
        "--coarse-history",
        type=float,
        default=2.0,
        metavar="WEIGHT",
        help="weight of matching each branch's turns summed over its last order + 1 extensions, so that turns "
        "stay correlated as in the input over several extensions (default 2; 0: the paper's Markov model alone)",
    )
    g.add_argument(
        "--total-turn",
        type=float,
        default=None,
        metavar="WEIGHT",
        help="weight of matching each branch's whole turn since its start, so that stems keep a course across the "
        "image instead of curling (default: 2 where the example's heading statistics are well determined, i.e. "
        "phloem.metrics.drift_noise of its skeleton is at most 0.125, else 0, the paper's Markov model alone)",
    )
    g.add_argument(
        "--turn-bound",
        type=float,
        default=None,
        metavar="WEIGHT",
        help="weight of the bound on each stem's whole turn: a stem that has turned further than 90 %% of the "
        "example's stems do is steered back, so that it crosses the image instead of spiralling (default: 5 "
        "with --total-turn above 0, else 0: off)",
    )
    g.add_argument(
        "--orientation",
        type=float,
        default=None,
        metavar="WEIGHT",
        help="weight of matching each branch's heading on the image against the example's branches, so that "
        "branches run the ways the example's run (lightning falls, roots keep their slant; default: 3 where the "
        "example runs one way, i.e. phloem.metrics.direction_concentration of its skeleton is at least 0.4, and "
        "no --guide is given, else 0, the paper's model, which only knows turns)",
    )
    g.add_argument(
        "--turn-histogram",
        type=float,
        default=None,
        metavar="WEIGHT",
        help="weight of matching the histogram of heading changes over 60 px of branch against the example's, "
        "so that branches curl and zigzag as much as the example's over that arc, no more and no less "
        f"(default {TURN_HISTOGRAM:g}, or {GUIDED_TURN_HISTOGRAM:g} with --guide, whose path sets the turns; 0: the "
        "paper's model)",
    )
    g.add_argument(
        "--direction-histogram",
        type=float,
        default=None,
        metavar="WEIGHT",
        help="weight of matching the histogram of the directions the branches run on the image against the "
        "example's, so that the structure runs each way as much as the example's and a branch that wandered off "
        "its ways is steered back (default: 1 where --orientation defaults to 3, else 0, the paper's model)",
    )
    g.add_argument(
        "--layout",
        type=float,
        default=None,
        metavar="WEIGHT",
        help="weight of the example's layout of directions: branches grow the way the example's branches run "
        "at the same place of the picture (a fundus's vessels round its disc, a delta's channels fanning out); "
        "where the example's branches agree on no way (cracks, bark) it changes little (default: 1 where the "
        "example is one connected structure and no --guide is given, else 0, the paper's model, the same "
        "everywhere)",
    )
    g.add_argument(
        "--stem-thickness",
        type=non_negative,
        default=STEM_THICKNESS,
        metavar="WEIGHT",
        help="weight of matching each tree's main branch against the thickness of the example's main branch at "
        "the same length, so that a trunk stays as thick as the example's and tapers as it does (default 5; 0: "
        "the paper's model, where a trunk thins to its children's thickness)",
    )
    g.add_argument(
        "--denoise",
        type=non_negative,
        default=None,
        metavar="PX",
        help="smooth the example's branches along their length by a Gaussian of this many pixels before the bending "
        "model takes their angles, so that a traced centre line's pixel staircase is not grown as wandering "
        f"(default: {DENOISE:g} where the example's branches keep a course, i.e. their median heading change over "
        f"60 px is at most {DENOISE_COURSE:g} rad, else 0: the skeleton as given, the paper's model, which keeps "
        "sharp bends)",
    )
    g.add_argument(
        "--generations",
        type=positive,
        default=None,
        help="maximum branch generations to grow (default: as deep as the input's trees)",
    )
    g.add_argument("--max-length", type=_length, default=None, metavar="PX|input",
                   help="stop at this total branch length in pixels, or 'input' for about as much structure as the example "
                        "(root trees are added until then; default: one tree for grow, 'input' for run)")  # fmt: skip
    g.add_argument(
        "--no-colonize", action="store_true", help="turn off space colonisation (§4.4; crossings are still refused)"
    )
    g.add_argument(
        "--repel-border",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="count the image's border as structure in the colonisation density, so that stems do not run "
        "along it (default: on with the default --total-turn 2, else off: the border is empty space, as in the paper)",
    )
    g.add_argument("--joined-ends", type=_share, default=None, metavar="SHARE",
                   help="share of the branches that end on other structure, 0-1: ends are carried on to structure "
                        "ahead of them, so that channels rejoin round islands (default: the example's share; "
                        "0: the paper's trees)")  # fmt: skip
    g.add_argument("--guide", metavar="PATH", default=None,
                   help="guided synthesis (§4.5): a JSON list of [x, y] points or a mask image the structure should follow")  # fmt: skip


def _grow(args: argparse.Namespace, bend: Any, fur: Any, shape: tuple[int, int], bar: Any) -> branching.Skeleton:
    return branching.grow(
        bend, fur, size=shape, seed=args.seed, generations=args.generations, max_length=args.max_length,
        colonize=not args.no_colonize, repel_border=args.repel_border, guide=_guide(args.guide, args),
        joined_ends=args.joined_ends, progress=bar, max_memory=args.max_memory,
    )  # fmt: skip


def _cmd_branching_grow(args: argparse.Namespace) -> None:
    out = Path(args.out)
    _check_json_target(out, args)
    extra = [Path(x) for x in (args.preview, args.histograms) if x is not None]
    for x in extra:
        check_writable(x, args)
    source = branching.Skeleton.load(args.skeleton)
    shape = args.size or source.shape
    if shape is None:
        raise ValueError("size: the skeleton file has no shape; pass --size WxH")
    _resolve_course(args, source)
    # fitting takes seconds on real skeletons; a batch worker fits once per skeleton and options
    options = (args.h, args.order, args.m, args.n_best, args.course, args.coarse_history, args.total_turn,
               args.turn_bound, args.orientation, args.turn_histogram, args.stem_thickness,
               args.direction_histogram, args.layout, args.denoise)  # fmt: skip
    bend, fur = kept("branching models", [Path(args.skeleton)], options, lambda: branching.fit_models(
        source, h=args.h, order=args.order, m=args.m, n_best=args.n_best, course=args.course,
        coarse_history=args.coarse_history, total_turn=args.total_turn, turn_bound=args.turn_bound,
        orientation=args.orientation, turn_histogram=args.turn_histogram, stem_thickness=args.stem_thickness,
        direction_histogram=args.direction_histogram, layout=args.layout, denoise=args.denoise))  # fmt: skip
    new = run("branching grow", args, lambda bar: _grow(args, bend, fur, shape, bar))
    _resolve_models(args, bend)
    args.size = shape
    _write_skeleton(out, new, args, "branching grow", branches=len(new.branches))
    if args.preview is not None:
        stage_image(args.preview, new.draw(size=shape, color=(1.0, 1.0, 1.0), width=2), args)
    if args.histograms is not None:
        stage_image(args.histograms, branching.histogram_figure(source, new, h=bend.h), args)


def _cmd_branching_render(args: argparse.Namespace) -> None:
    extra = [Path(args.fragment_map)] if args.fragment_map else []
    preflight(args, extra)
    img = io.read_image(args.input, max_pixels=args.max_pixels)
    source = branching.Skeleton.load(args.skeleton)
    target = branching.Skeleton.load(args.target)
    if target.shape is None:
        raise ValueError(f"target: {args.target} has no shape; the new image's size comes from it")
    valid = _valid(args, img)
    _resolve_gap_diversity(args, img, valid)
    res = run(
        "branching render", args,
        lambda bar: branching.render(img, source, target, seed=args.seed, threads=args.threads, progress=bar,
                                     full_output=True, max_memory=args.max_memory, valid=valid, **_render_kwargs(args)),
    )  # fmt: skip
    save(args, "branching render", res.image)
    if args.fragment_map:
        stage_image(args.fragment_map, fragment_map(res.labels), args)


def _branching_run_targets(args: argparse.Namespace) -> dict[str, Path]:
    stem = Path(args.out).with_suffix("")
    files = {"skeleton": Path(f"{stem}_skeleton.json"), "histograms": Path(f"{stem}_histograms.png")}
    if args.fragment_map:
        files["fragments"] = Path(args.fragment_map)
    return files


def _cmd_branching_run(args: argparse.Namespace) -> None:
    files = _branching_run_targets(args)
    preflight(args, [p for r, p in files.items() if r != "skeleton"])  # also refuses two outputs of one name
    _check_json_target(files["skeleton"], args)
    img = io.read_image(args.input, max_pixels=args.max_pixels)
    source = None if args.skeleton is None else branching.Skeleton.load(args.skeleton)
    valid = _valid(args, img)
    # tracing and fitting are seconds on real inputs and the same for every seed: a batch worker
    # does them once per input and options, and grows and renders each seed from them
    read = [Path(p) for p in (args.input, args.skeleton) if p is not None]
    if args.valid not in ("auto", "none"):
        read.append(Path(args.valid))
    key = stamp(read, (_trace_kwargs(args), args.valid, args.h, args.order, args.m, args.n_best, args.course,
                               args.coarse_history, args.total_turn, args.turn_bound, args.orientation,
                               args.turn_histogram, args.stem_thickness, args.direction_histogram,
                               args.layout, args.denoise))  # fmt: skip
    prior = recall("branching run models", key)
    _resolve_gap_diversity(args, img, valid, _trace_kwargs(args))
    res = run(
        "branching run", args,
        lambda bar: branching.synthesize(
            img, source if prior is None else prior[0], models=None if prior is None else prior[1:], size=args.size, seed=args.seed, trace_options=_trace_kwargs(args), h=args.h, order=args.order,
            m=args.m, n_best=args.n_best, course=args.course, coarse_history=args.coarse_history, total_turn=args.total_turn, turn_bound=args.turn_bound, orientation=args.orientation, turn_histogram=args.turn_histogram, stem_thickness=args.stem_thickness, direction_histogram=args.direction_histogram, layout=args.layout, denoise=args.denoise, generations=args.generations, max_length=args.max_length, colonize=not args.no_colonize, repel_border=args.repel_border,
            joined_ends=args.joined_ends, guide=_guide(args.guide, args), valid=valid, render_options=_render_kwargs(args),
            threads=args.threads, progress=bar, max_memory=args.max_memory,
        ),
    )  # fmt: skip
    remember("branching run models", key, (res.source, res.bending, res.furcation))
    written = {role: str(p) for role, p in files.items()}
    if source is None:
        _resolve_kind(args, img)
    _resolve_course(args, res.source)  # as synthesize resolved them, for the sidecar
    _resolve_models(args, res.bending)
    args.size = res.image.shape[:2]
    save(args, "branching run", res.image, files=written,
          source_branches=len(res.source.branches), target_branches=len(res.target.branches))  # fmt: skip
    _write_skeleton(files["skeleton"], res.target, args, "branching run")
    stage_image(files["histograms"], branching.histogram_figure(res.source, res.target, h=res.bending.h), args)
    if "fragments" in files:
        stage_image(files["fragments"], fragment_map(res.render.labels), args)


def add_parsers(sub: Any) -> None:
    p = sub.add_parser("branching", help="branching structures: trace, learn and grow skeletons, render images (Sibbing et al. 2010)",
                       description="Rivers, cracks, lightning, ridges and vessels from one example image: trace or load its skeleton, "
                                   "learn how it bends and branches (§4), grow a new skeleton and compose a new image from "
                                   "fragments of the example (§5).")  # fmt: skip
    bsub = p.add_subparsers(dest="action", metavar="ACTION", required=True, help="each has its own --help")
    q = bsub.add_parser("trace", help="trace the skeleton of a structure in an image into a skeleton JSON file",
                        description="Ridge filter (or a binary mask), skeletonisation, and a tree of branches with parents; "
                                    "thickness from the image (the paper's §3 operator).")  # fmt: skip
    q.add_argument("input", metavar="IN", help="image of the structure (PNG, JPEG or TIFF)")
    q.add_argument("--out", required=True, metavar="SKEL.json", help="skeleton file to write")
    q.add_argument("--overlay", metavar="PNG", default=None, help="also draw the traced skeleton over IN into PNG")
    _trace_options(q)
    _valid_option(q)
    common_options(q)
    q.set_defaults(func=_cmd_branching_trace)
    q = bsub.add_parser("grow", help="learn an example skeleton's bending and branching and grow a new one",
                        description="Markov bending model with histogram matching (§4.2), SVM furcation model (§4.3), "
                                    "space colonisation (§4.4) and optional guidance (§4.5).")  # fmt: skip
    q.add_argument("skeleton", metavar="SKEL.json", help="the example skeleton (phloem.skeleton JSON)")
    q.add_argument("--out", required=True, metavar="NEW.json", help="new skeleton file to write")
    q.add_argument(
        "--size",
        type=parse_size,
        default=None,
        metavar="WxH",
        help="width x height of the new structure's image, or N for NxN (default: the example's)",
    )
    q.add_argument("--preview", metavar="PNG", default=None, help="also draw the new skeleton into PNG")
    q.add_argument(
        "--histograms",
        metavar="PNG",
        default=None,
        help="also write the input and output angle and thickness histograms (Fig. 7)",
    )
    _grow_options(q)
    common_options(q)
    q.set_defaults(func=_cmd_branching_grow)
    q = bsub.add_parser("render", help="paint a new skeleton with fragments of the example image (§5)",
                        description="Fragments along both skeletons, shape and colour matching, deformation by a smooth "
                                    "displacement field, photometric correction, graph-cut seams, gap completion.")  # fmt: skip
    q.add_argument("input", metavar="IN", help="the example image")
    q.add_argument("skeleton", metavar="SKEL.json", help="the example's skeleton")
    q.add_argument("target", metavar="NEW.json", help="the skeleton to paint (its shape sets the output size)")
    q.add_argument("--out", required=True, metavar="OUT", help="output image (.png, .jpg, .tif)")
    _render_options(q)
    common_options(q)
    q.set_defaults(func=_cmd_branching_render)
    q = bsub.add_parser("run", help="image in, new image out: trace (or load) the skeleton, grow a new one, render it",
                        description="The whole pipeline. Writes OUT, OUT.json, the new skeleton OUT_skeleton.json and the "
                                    "input/output angle and thickness histograms OUT_histograms.png (Fig. 7).")  # fmt: skip
    q.add_argument("input", metavar="IN", help="the example image")
    q.add_argument("--skeleton", metavar="SKEL.json", default=None, help="the example's skeleton (default: trace it)")
    q.add_argument("--out", required=True, metavar="OUT", help="output image (.png, .jpg, .tif)")
    q.add_argument(
        "--size",
        type=parse_size,
        default=None,
        metavar="WxH",
        help="width x height of the new image, or N for NxN (default: the example's)",
    )
    _trace_options(q)
    _grow_options(q)
    _render_options(q)
    common_options(q)
    q.set_defaults(func=_cmd_branching_run, max_length="input")
