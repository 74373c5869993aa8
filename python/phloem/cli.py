"""The ``phloem`` command: one sub-command per capability.

Every sub-command that writes an image also writes ``OUT.json`` beside it with the parameters,
the seed and the phloem version, refuses to replace existing files unless ``--force`` is given,
and checks all of that before the (possibly long) computation starts.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import cv2
import numpy as np

from . import __version__, bark, branching, data, io, patch, texture, trees
from ._progress import Bar

__all__ = ["main"]


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 512x512, got {text!r}") from None
    if w < 1 or h < 1:
        raise argparse.ArgumentTypeError(f"expected positive sizes, got {text!r}")
    return h, w


def _positive(text: str) -> int:
    v = int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text}")
    return v


def _non_negative(text: str) -> float:
    v = float(text)
    if not (v >= 0 and v != float("inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text}")
    return v


def _common(p: argparse.ArgumentParser, *, writes: bool = True) -> None:
    g = p.add_argument_group("common options")
    g.add_argument(
        "--seed", type=int, default=0, help="seed of every random choice; same seed, same output (default 0)"
    )
    g.add_argument(
        "--threads", type=_positive, default=None, help="worker threads (default: PHLOEM_NUM_THREADS or all cores)"
    )
    g.add_argument(
        "--max-pixels",
        type=_positive,
        default=io.DEFAULT_MAX_PIXELS,
        help="refuse input images larger than this many pixels (default %(default)s)",
    )
    g.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    if writes:
        g.add_argument("--force", action="store_true", help="replace OUT and OUT.json if they exist")
        g.add_argument(
            "--bit-depth",
            type=int,
            choices=(8, 16),
            default=8,
            help="bits per channel of OUT (16 for PNG/TIFF only; default 8)",
        )


def _check_writable(path: Path, args: argparse.Namespace) -> None:
    io._encode(path, np.zeros((1, 1), np.float32), args.bit_depth)  # extension and bit depth
    io._check_target(path, args.force)


def _preflight(args: argparse.Namespace, extra: Sequence[Path] = ()) -> None:
    """Fail before computing if the output, its sidecar or an ``extra`` file cannot be written."""
    out = Path(args.out)
    _check_writable(out, args)
    io._check_target(io.sidecar_path(out), args.force)
    for path in extra:
        _check_writable(path, args)


def _params(args: argparse.Namespace, skip: Sequence[str] = ()) -> dict[str, Any]:
    drop = {"func", "command", "quiet", "force", "threads", "seed", "max_pixels", *skip}
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(args).items() if k not in drop}


T = TypeVar("T")


def _run(label: str, args: argparse.Namespace, work: Callable[[Any], T]) -> T:
    bar = Bar(label, enabled=not args.quiet)
    t0 = time.perf_counter()
    try:
        out = work(bar)
    finally:
        bar.close()
    if not args.quiet:
        print(f"{label}: {time.perf_counter() - t0:.2f} s", file=sys.stderr)
    return out


def _save(args: argparse.Namespace, command: str, image: np.ndarray, **extra: Any) -> None:
    side = io.write_result(
        args.out, image, command=command, parameters={**_params(args), **extra}, seed=args.seed,
        overwrite=args.force, bit_depth=args.bit_depth,
    )  # fmt: skip
    if not args.quiet:
        print(f"wrote {args.out} and {side}", file=sys.stderr)


def _cmd_synthesize(args: argparse.Namespace) -> None:
    _preflight(args)
    ex = io.read_image(args.input, max_pixels=args.max_pixels)
    out = _run(
        "synthesize",
        args,
        lambda bar: texture.synthesize(
            ex,
            args.size,
            patch_size=args.patch_size,
            levels=args.levels,
            iterations=args.iterations,
            seed=args.seed,
            threads=args.threads,
            progress=bar,
        ),
    )
    _save(args, "synthesize", out)


def _cmd_quilt(args: argparse.Namespace) -> None:
    _preflight(args)
    ex = io.read_image(args.input, max_pixels=args.max_pixels)
    out = _run(
        "quilt",
        args,
        lambda bar: texture.quilt(
            ex,
            args.size,
            block=args.block,
            overlap=args.overlap,
            randomness=args.randomness,
            cost=args.cost,
            seed=args.seed,
            threads=args.threads,
            progress=bar,
        ),
    )
    _save(args, "quilt", out)


def _cmd_complete(args: argparse.Namespace) -> None:
    _preflight(args)
    img = io.read_image(args.input, max_pixels=args.max_pixels)
    m = io.read_image(args.mask, max_pixels=args.max_pixels)
    if m.ndim == 3:
        m = m[..., 3] if m.shape[2] == 4 and args.mask_alpha else m[..., :3].max(axis=2)
    if m.shape != img.shape[:2]:
        raise ValueError(
            f"mask: {args.mask} is {m.shape[1]}×{m.shape[0]}, but the image is {img.shape[1]}×{img.shape[0]}"
        )
    hole = (m < 0.5) if args.mask_alpha else (m >= 0.5)
    out = _run(
        "complete",
        args,
        lambda bar: texture.complete(
            img,
            hole,
            patch_size=args.patch_size,
            levels=args.levels,
            iterations=args.iterations,
            seed=args.seed,
            threads=args.threads,
            progress=bar,
        ),
    )
    _save(args, "complete", out)


def _cmd_nnf(args: argparse.Namespace) -> None:
    out = Path(args.out)
    if out.suffix.lower() != ".npz":
        raise ValueError(f"out: expected a .npz file for the field, got {out.name}")
    io._check_target(out, args.force)
    src = io.read_image(args.source, max_pixels=args.max_pixels)
    tgt = io.read_image(args.target, max_pixels=args.max_pixels)
    t0 = time.perf_counter()
    field, dist = patch.nnf(
        src, tgt, patch_size=args.patch_size, iterations=args.iterations, method=args.method, levels=args.levels,
        seed=args.seed, threads=args.threads,
    )  # fmt: skip
    import io as _pyio

    buf = _pyio.BytesIO()
    np.savez_compressed(buf, field=field, distance=dist)
    io._atomic_write(out, buf.getvalue(), args.force)
    if not args.quiet:
        print(
            f"nnf: {time.perf_counter() - t0:.2f} s, mean distance {float(dist.mean()):.4g}; wrote {out}",
            file=sys.stderr,
        )


def _bark_targets(args: argparse.Namespace) -> dict[str, Path]:
    """The extra files ``phloem bark`` writes beside OUT, by role."""
    out = Path(args.out)
    stem = out.with_suffix("")
    files: dict[str, Path] = {}
    if args.keep_intermediates:
        files["labels_in"] = Path(f"{stem}_labels_in.png")
        files["labels_out"] = Path(f"{stem}_labels_out.png")
    if args.height_map is not None:
        files["height"] = Path(f"{stem}_height.png")
    if args.cylinder_preview is not None:
        files["cylinder"] = Path(args.cylinder_preview)
    return files


def _cmd_bark(args: argparse.Namespace) -> None:
    extra = _bark_targets(args)
    _preflight(args, list(extra.values()))
    if len({Path(args.out).resolve(), *(p.resolve() for p in extra.values())}) != len(extra) + 1:
        raise ValueError("out: OUT, the intermediate maps and the preview must be different files")
    photo = data.bark() if args.input is None else io.read_image(args.input, max_pixels=args.max_pixels)
    hm = None if args.height_map is None else io.read_image(args.height_map, max_pixels=args.max_pixels)
    if hm is not None and hm.ndim == 3:
        hm = hm[..., :3].mean(axis=2)
    lab_in = (
        None
        if args.labels_in is None
        else bark.decode_labels(io.read_image(args.labels_in, max_pixels=args.max_pixels))
    )
    lab_out = (
        None
        if args.labels_out is None
        else bark.decode_labels(io.read_image(args.labels_out, max_pixels=args.max_pixels))
    )
    res = _run(
        "bark",
        args,
        lambda bar: bark.generate(
            photo,
            args.size,
            n_labels=args.labels,
            height_map=hm,
            labels_in=lab_in,
            labels_out=lab_out,
            method=args.method,
            rotations=args.rotations,
            edge_label=args.edge_label,
            tileable=args.tileable,
            seed=args.seed,
            stand_in_weight=None if args.strict_labels else args.stand_in_weight,
            threads=args.threads,
            progress=bar,
            full_output=True,
        ),
    )
    written = {role: str(p) for role, p in extra.items()}
    _save(args, "bark", res.texture, input=args.input or "phloem.data.bark()", files=written)
    maps = {"labels_in": res.labels_in, "labels_out": res.labels_out}
    for role, path in extra.items():
        if role in maps:
            img = bark.encode_labels(maps[role])
        elif role == "height":
            assert res.height is not None
            img = res.height
        else:
            img = bark.cylinder_preview(res.texture, height=res.height)
        io.write_image(path, img, overwrite=args.force, bit_depth=16 if role == "height" else args.bit_depth)
        if not args.quiet:
            print(f"wrote {path}", file=sys.stderr)


def _tree_library(args: argparse.Namespace, bar: Any) -> trees.Library:
    src = Path(args.library)
    atlas = {"auto": None, "yes": True, "no": False}[args.atlas]
    clf = None
    if args.trunk_model is not None:
        clf = trees.TrunkClassifier.from_dict(json.loads(Path(args.trunk_model).read_text(encoding="utf-8")))
    return trees.Library.load(
        src, atlas=atlas, size=args.size, skip_bad=args.skip_bad, classifier=clf, max_pixels=args.max_pixels,
        progress=bar,
    )  # fmt: skip


def _cmd_trees(args: argparse.Namespace) -> None:
    out_dir = Path(args.out_dir)
    targets = [out_dir / f"{args.prefix}{i:04d}.png" for i in range(args.count)]
    if out_dir.exists() and not out_dir.is_dir():
        raise ValueError(f"out-dir: {out_dir} exists and is not a folder")
    out_dir.mkdir(parents=True, exist_ok=True)
    for t in targets:
        _check_writable(t, args)
        io._check_target(io.sidecar_path(t), args.force)
    if args.sheet is not None:
        _check_writable(Path(args.sheet), args)
    like = None if args.like is None else io.read_image(args.like, max_pixels=args.max_pixels)
    lib = _run("trees: library", args, lambda bar: _tree_library(args, bar))
    if not args.quiet:
        print(f"library: {len(lib)} trees", file=sys.stderr)

    colors = args.colors or ("contour" if like is not None else "random")

    def make(bar: Any) -> list[trees.Variation]:
        if like is not None:
            own = trees.prepare(like, size=args.size)
            out = []
            # One variation at a time so the bar moves; vary's draws for variation i depend only on (seed, i).
            for i in range(args.count):
                out += trees.vary(own, lib, n=1, seed=_sub_seed(args.seed, i), sources=args.sources, colors=colors,
                                  histogram=args.histogram, threads=args.threads)  # fmt: skip
                bar(i + 1, args.count)
            return out
        res = []
        for i in range(args.count):
            res.append(trees.variation(lib, sources=args.sources, seed=_sub_seed(args.seed, i), colors=colors,
                                       histogram=args.histogram, threads=args.threads))  # fmt: skip
            bar(i + 1, args.count)
        return res

    variations = _run("trees: variations", args, make)
    for i, (v, path) in enumerate(zip(variations, targets)):
        rec = v.describe(lib)
        if like is not None:
            rec["exemplars"] = [str(args.like), *rec["exemplars"]]
        io.write_result(
            path, v.image, command="trees",
            parameters={**_params(args), "colors": colors, **rec, "variation_seed": _sub_seed(args.seed, i)},
            seed=args.seed, overwrite=args.force, bit_depth=args.bit_depth,
        )  # fmt: skip
    if not args.quiet:
        print(f"wrote {len(targets)} trees (and their .json) to {out_dir}", file=sys.stderr)
    if args.sheet is not None:
        sheet = _run("trees: sheet", args, lambda bar: _tree_sheet(lib, variations, args))
        io.write_image(args.sheet, sheet, overwrite=args.force, bit_depth=args.bit_depth)
        if not args.quiet:
            print(f"wrote {args.sheet}", file=sys.stderr)


def _sub_seed(seed: int, i: int) -> int:
    """The seed of variation ``i`` of a run with ``--seed seed`` (recorded in its sidecar)."""
    return int(np.random.SeedSequence([seed, i]).generate_state(1)[0])


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
        "--min-length", type=float, default=8.0, help="drop traced branches shorter than this many pixels (default 8)"
    )


def _trace_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    return {"kind": args.kind, "sigmas": tuple(args.sigmas), "channel": args.channel, "min_length": args.min_length}


def _write_skeleton(path: Path, sk: branching.Skeleton, args: argparse.Namespace, command: str, **extra: Any) -> None:
    """A skeleton file and its sidecar, both checked before either is written."""
    side = io.sidecar_path(path)
    io._check_target(path, args.force)
    io._check_target(side, args.force)
    sk.save(path, overwrite=args.force)
    meta = {"phloem_version": __version__, "command": command, "seed": getattr(args, "seed", None),
            "parameters": {**_params(args), **extra}, "output": path.name}  # fmt: skip
    io._atomic_write(side, (json.dumps(meta, indent=2, sort_keys=True, default=str) + "\n").encode(), args.force)
    if not args.quiet:
        print(f"wrote {path} and {side}", file=sys.stderr)


def _check_json_target(path: Path, args: argparse.Namespace) -> None:
    if path.suffix.lower() != ".json":
        raise ValueError(f"out: expected a .json file for the skeleton, got {path.name}")
    io._check_target(path, args.force)
    io._check_target(io.sidecar_path(path), args.force)


def _cmd_branching_trace(args: argparse.Namespace) -> None:
    out = Path(args.out)
    _check_json_target(out, args)
    if args.overlay is not None:
        _check_writable(Path(args.overlay), args)
    img = io.read_image(args.input, max_pixels=args.max_pixels)
    sk = _run("branching trace", args, lambda bar: branching.trace(img, **_trace_kwargs(args)))
    _write_skeleton(
        out, sk, args, "branching trace", branches=len(sk.branches), total_length=round(sk.total_length(), 1)
    )
    if args.overlay is not None:
        io.write_image(args.overlay, sk.draw(img, width=2), overwrite=args.force, bit_depth=args.bit_depth)
        if not args.quiet:
            print(f"wrote {args.overlay}", file=sys.stderr)


def _guide(path: str | None, args: argparse.Namespace) -> Any:
    if path is None:
        return None
    p = Path(path)
    if p.suffix.lower() == ".json":
        pts = np.asarray(json.loads(p.read_text(encoding="utf-8")), dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2:
            raise ValueError(f"guide: {p} must hold a JSON list of at least two [x, y] points")
        return pts
    g = io.read_image(p, max_pixels=args.max_pixels)
    return (g.mean(axis=2) if g.ndim == 3 else g) > 0.5


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
        "--fragment-map", metavar="PNG", default=None, help="also write the map of which fragment painted each pixel"
    )


def _render_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    return {"omega_s": args.omega_s, "omega_c": args.omega_c, "complete": not args.no_complete}


def _fragment_map(labels: np.ndarray) -> np.ndarray:
    rng = np.random.default_rng(0)
    colours = rng.uniform(0.25, 1.0, (int(labels.max()) + 2, 3)).astype(np.float32)
    colours[0] = 0.0
    out: np.ndarray = colours[labels + 1]
    return out


def _grow_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("structure synthesis (§4)")
    g.add_argument("--h", type=float, default=None,
                   help="resampling step in pixels (default: the input's median thickness). The model remembers k steps, so "
                        "a larger h (e.g. 10 on a traced river) keeps long branches on course instead of curling")  # fmt: skip
    g.add_argument("--k", type=_positive, default=3, help="order of the Markov bending model (paper: 3)")
    g.add_argument(
        "--m", type=_positive, default=None, help="elements appended per step, the feature size s/h (default 4)"
    )
    g.add_argument(
        "--c",
        type=_positive,
        default=2,
        help="candidates: 1 follows the input exactly, more gives more variety (paper: 2)",
    )
    g.add_argument("--generations", type=_positive, default=3, help="branch generations to grow (default 3)")
    g.add_argument("--max-length", type=_length, default=None, metavar="PX|input",
                   help="stop at this total branch length in pixels, or 'input' for about as much structure as the example "
                        "(root trees are added until then; default: one tree for grow, 'input' for run)")  # fmt: skip
    g.add_argument(
        "--no-colonize", action="store_true", help="turn off space colonisation (§4.4; crossings are still refused)"
    )
    g.add_argument("--guide", metavar="PATH", default=None,
                   help="guided synthesis (§4.5): a JSON list of [x, y] points or a mask image the structure should follow")  # fmt: skip


def _grow(args: argparse.Namespace, bend: Any, fur: Any, shape: tuple[int, int], bar: Any) -> branching.Skeleton:
    return branching.grow(
        bend, fur, shape=shape, seed=args.seed, generations=args.generations, max_length=args.max_length,
        colonize=not args.no_colonize, guide=_guide(args.guide, args), progress=bar,
    )  # fmt: skip


def _cmd_branching_grow(args: argparse.Namespace) -> None:
    out = Path(args.out)
    _check_json_target(out, args)
    extra = [Path(x) for x in (args.preview, args.histograms) if x is not None]
    for x in extra:
        _check_writable(x, args)
    source = branching.Skeleton.load(args.skeleton)
    shape = args.size or source.shape
    if shape is None:
        raise ValueError("size: the skeleton file has no shape; pass --size WxH")
    bend, fur = branching.fit_models(source, h=args.h, k=args.k, m=args.m, c=args.c)
    new = _run("branching grow", args, lambda bar: _grow(args, bend, fur, shape, bar))
    _write_skeleton(out, new, args, "branching grow", h=bend.h, branches=len(new.branches))
    if args.preview is not None:
        io.write_image(
            args.preview,
            new.draw(shape=shape, color=(1.0, 1.0, 1.0), width=2),
            overwrite=args.force,
            bit_depth=args.bit_depth,
        )
    if args.histograms is not None:
        fig = branching.histogram_figure(source, new, h=bend.h)
        io.write_image(args.histograms, fig, overwrite=args.force, bit_depth=args.bit_depth)


def _cmd_branching_render(args: argparse.Namespace) -> None:
    extra = [Path(args.fragment_map)] if args.fragment_map else []
    _preflight(args, extra)
    img = io.read_image(args.input, max_pixels=args.max_pixels)
    source = branching.Skeleton.load(args.skeleton)
    target = branching.Skeleton.load(args.target)
    if target.shape is None:
        raise ValueError(f"target: {args.target} has no shape; the new image's size comes from it")
    res = _run(
        "branching render", args,
        lambda bar: branching.render(img, source, target, seed=args.seed, threads=args.threads, progress=bar,
                                     full_output=True, **_render_kwargs(args)),
    )  # fmt: skip
    _save(args, "branching render", res.image)
    if args.fragment_map:
        io.write_image(args.fragment_map, _fragment_map(res.labels), overwrite=args.force, bit_depth=args.bit_depth)


def _branching_run_targets(args: argparse.Namespace) -> dict[str, Path]:
    stem = Path(args.out).with_suffix("")
    files = {"skeleton": Path(f"{stem}_skeleton.json"), "histograms": Path(f"{stem}_histograms.png")}
    if args.fragment_map:
        files["fragments"] = Path(args.fragment_map)
    return files


def _cmd_branching_run(args: argparse.Namespace) -> None:
    files = _branching_run_targets(args)
    _preflight(args, [p for r, p in files.items() if r != "skeleton"])
    _check_json_target(files["skeleton"], args)
    img = io.read_image(args.input, max_pixels=args.max_pixels)
    source = None if args.skeleton is None else branching.Skeleton.load(args.skeleton)
    res = _run(
        "branching run", args,
        lambda bar: branching.synthesize(
            img, source, size=args.size, seed=args.seed, trace_options=_trace_kwargs(args), h=args.h, k=args.k, m=args.m,
            c=args.c, generations=args.generations, max_length=args.max_length, colonize=not args.no_colonize,
            guide=_guide(args.guide, args), render_options=_render_kwargs(args), threads=args.threads, progress=bar,
        ),
    )  # fmt: skip
    written = {role: str(p) for role, p in files.items()}
    _save(args, "branching run", res.image, h=res.bending.h, files=written,
          source_branches=len(res.source.branches), target_branches=len(res.target.branches))  # fmt: skip
    _write_skeleton(files["skeleton"], res.target, args, "branching run", h=res.bending.h)
    fig = branching.histogram_figure(res.source, res.target, h=res.bending.h)
    io.write_image(files["histograms"], fig, overwrite=args.force, bit_depth=args.bit_depth)
    if "fragments" in files:
        io.write_image(
            files["fragments"], _fragment_map(res.render.labels), overwrite=args.force, bit_depth=args.bit_depth
        )
    if not args.quiet:
        print(f"wrote {files['histograms']}", file=sys.stderr)


def _cmd_demo(args: argparse.Namespace) -> None:
    _preflight(args)
    out = _run(
        "demo: bark texture",
        args,
        lambda bar: bark.generate(data.bark(), args.size, seed=args.seed, threads=args.threads, progress=bar),
    )
    _save(args, "demo", out, input="phloem.data.bark()", pipeline="phloem.bark.generate")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``phloem`` command."""
    ap = argparse.ArgumentParser(
        prog="phloem",
        description="New images of natural structures from a few real examples.",
        epilog="Run 'phloem COMMAND --help' for the options of a command.",
    )
    ap.add_argument("--version", action="version", version=f"phloem {__version__}")
    sub = ap.add_subparsers(
        dest="command", metavar="COMMAND", required=True, help="what to make; each has its own --help"
    )

    p = sub.add_parser("synthesize", help="synthesise a texture of any size from an exemplar image",
                       description="Texture optimisation (Kwatra et al. 2005) over an image pyramid, with PatchMatch search and robust patch voting.")  # fmt: skip
    p.add_argument("input", metavar="IN", help="exemplar image (PNG, JPEG or TIFF)")
    p.add_argument(
        "--size", type=_size, required=True, metavar="WxH", help="output width x height in pixels, e.g. 512x512"
    )
    p.add_argument("--out", required=True, metavar="OUT", help="output image (.png, .jpg, .tif)")
    p.add_argument("--patch-size", type=int, default=7, help="patch side, odd (default 7)")
    p.add_argument("--levels", type=_positive, default=None, help="pyramid levels (default: from the exemplar size)")
    p.add_argument("--iterations", type=_positive, default=4, help="search-and-vote iterations per level (default 4)")
    _common(p)
    p.set_defaults(func=_cmd_synthesize)

    p = sub.add_parser("quilt", help="texture of any size from exemplar blocks joined along graph-cut seams",
                       description="Graph-cut quilting (Kwatra et al. 2003): exemplar blocks placed by entire-patch matching, "
                                   "cut into the output along minimum-cost seams. Every output pixel is an exemplar pixel.")  # fmt: skip
    p.add_argument("input", metavar="IN", help="exemplar image (PNG, JPEG or TIFF)")
    p.add_argument(
        "--size", type=_size, required=True, metavar="WxH", help="output width x height in pixels, e.g. 512x512"
    )
    p.add_argument("--out", required=True, metavar="OUT", help="output image (.png, .jpg, .tif)")
    p.add_argument(
        "--block",
        type=_positive,
        default=None,
        help="side of the exemplar blocks (default: 64, or half the exemplar's shorter side)",
    )
    p.add_argument(
        "--overlap", type=_positive, default=None, help="overlap of neighbouring blocks in pixels (default: block/4)"
    )
    p.add_argument("--randomness", type=float, default=0.01,
                   help="Kwatra's k: 0 always takes the best-matching block, larger values pick worse matches more often (default 0.01)")  # fmt: skip
    p.add_argument("--cost", choices=("kwatra", "gradient", "luo"), default="kwatra",
                   help="seam cost: colour difference, gradient-normalised colour difference, or Luo et al.'s d^4/G (default kwatra)")  # fmt: skip
    _common(p)
    p.set_defaults(func=_cmd_quilt)

    p = sub.add_parser("complete", help="fill a masked region of an image from the rest of it",
                       description="Coarse-to-fine patch-based completion (Wexler et al. 2007) on PatchMatch.")  # fmt: skip
    p.add_argument("input", metavar="IN", help="image with a region to fill")
    p.add_argument("mask", metavar="MASK", help="image of the same size, white where pixels are to be filled")
    p.add_argument("--out", required=True, metavar="OUT", help="output image (.png, .jpg, .tif)")
    p.add_argument(
        "--mask-alpha",
        action="store_true",
        help="take the hole from MASK's alpha channel: transparent pixels are filled",
    )
    p.add_argument("--patch-size", type=int, default=7, help="patch side, odd (default 7)")
    p.add_argument("--levels", type=_positive, default=None, help="pyramid levels (default: from the hole size)")
    p.add_argument("--iterations", type=_positive, default=None,
                   help="search-and-vote iterations per level (default: 1 + 2 x level, coarsest level highest)")  # fmt: skip
    _common(p)
    p.set_defaults(func=_cmd_complete)

    p = sub.add_parser("nnf", help="nearest-neighbour field between two images, saved as .npz",
                       description="PatchMatch (Barnes et al. 2009) or exact search; writes arrays 'field' (H, W, 2) and 'distance' (H, W).")  # fmt: skip
    p.add_argument("source", metavar="SOURCE", help="image the patches come from")
    p.add_argument("target", metavar="TARGET", help="image whose pixels get matches")
    p.add_argument("--out", required=True, metavar="OUT.npz", help="output .npz file")
    p.add_argument("--patch-size", type=int, default=7, help="patch side, odd (default 7)")
    p.add_argument("--iterations", type=int, default=5, help="PatchMatch iterations (default 5)")
    p.add_argument("--levels", type=_positive, default=1, help="coarse-to-fine pyramid levels (default 1)")
    p.add_argument("--method", choices=("patchmatch", "kdtree", "exact"), default="patchmatch",
                   help="search method: patchmatch (default); kdtree, PatchMatch seeded by a PCA kd-tree search "
                   "(He & Sun 2012: within a few %% of exact, ~4x the time); exact")  # fmt: skip
    _common(p, writes=False)
    p.add_argument("--force", action="store_true", help="replace OUT if it exists")
    p.set_defaults(func=_cmd_nnf)

    p = sub.add_parser("bark", help="a bark texture of any size from one bark photo (the bark thesis' pipeline)",
                       description="Input label map (non-local means, CIELAB, k-means, §3.5), a new label map of the output size "
                                   "(Rosenberger et al. shape synthesis, §3.6), then texture-by-numbers (Fan et al. 2012, §3.3-3.4). "
                                   "Write the label maps with --keep-intermediates, edit them, and resume with --labels-in/--labels-out.")  # fmt: skip
    p.add_argument(
        "input",
        metavar="IN",
        nargs="?",
        default=None,
        help="bark photo (PNG, JPEG or TIFF; default: phloem's embedded Douglas-fir bark)",
    )
    p.add_argument(
        "--size",
        type=_size,
        default=None,
        metavar="WxH",
        help="output width x height, e.g. 512x512 (required unless --labels-out is given)",
    )
    p.add_argument("--out", required=True, metavar="OUT", help="output texture (.png, .jpg, .tif)")
    p.add_argument(
        "--labels",
        type=_positive,
        default=2,
        metavar="K",
        help="regions of the input label map (default 2; 2-3 work best)",
    )
    p.add_argument("--method", choices=("layered", "joint"), default="joint",
                   help="label-map synthesis: phloem's joint multi-label variant (default) or the thesis' nested layers")  # fmt: skip
    p.add_argument("--rotations", choices=("half", "all", "none"), default="half",
                   help="turns of the photo's shapes the new label map may use: half (0 and 180 degrees, default: bark grows "
                        "along the trunk), all (also 90 degrees, for bark without a grain such as plane trees) or none")  # fmt: skip
    p.add_argument(
        "--edge-label",
        action="store_true",
        help="add a region for the borders between regions to both label maps (§3.5.5)",
    )
    p.add_argument(
        "--height-map",
        metavar="HM",
        default=None,
        help="height map of IN, synthesised along; written as OUT_height.png (16-bit)",
    )
    p.add_argument(
        "--tileable", action="store_true", help="make the label map and the texture wrap around so OUT tiles"
    )
    p.add_argument("--stand-in-weight", type=_non_negative, default=5.0, metavar="W",
                   help="cost of letting a coherent piece of the photo run across a label boundary on nearest-coloured pixels "
                        "of the right label (default 5; lower: more seamless, looser boundaries)")  # fmt: skip
    p.add_argument("--strict-labels", action="store_true",
                   help="no stand-ins: the texture follows every boundary of the label map exactly, with seams along them")  # fmt: skip
    p.add_argument(
        "--cylinder-preview", metavar="PNG", default=None, help="also write the texture wrapped around a trunk to PNG"
    )
    p.add_argument(
        "--keep-intermediates",
        action="store_true",
        help="also write the label maps as OUT_labels_in.png and OUT_labels_out.png",
    )
    p.add_argument(
        "--labels-in",
        metavar="PNG",
        default=None,
        help="use this input label map (flat colours, same size as IN) instead of computing it",
    )
    p.add_argument(
        "--labels-out",
        metavar="PNG",
        default=None,
        help="use this output label map instead of synthesising one (sets the size)",
    )
    _common(p)
    p.set_defaults(func=_cmd_bark)

    p = sub.add_parser("trees", help="new tree billboards from a library of RGBA trees (Argudo et al. 2017)",
                       description="Every tree of LIBRARY is normalised, segmented into crown and trunk and described by a "
                                   "2000-point contour (§4). Each new tree's contour is a random convex combination of the "
                                   "contours of --sources trees, filled by mean value coordinate colour transfer from them (§5). "
                                   "Writes DIR/PREFIX0000.png ... with a .json sidecar naming the sources and weights.")  # fmt: skip
    p.add_argument(
        "library",
        metavar="LIBRARY",
        help="folder of RGBA tree images (atlases of several trees are split), or one atlas image",
    )
    p.add_argument("--count", type=_positive, required=True, metavar="N", help="number of new trees")
    p.add_argument("--out-dir", required=True, metavar="DIR", help="folder for the new trees (created if missing)")
    p.add_argument("--prefix", default="tree_", help="file name prefix of the new trees (default tree_)")
    p.add_argument("--like", metavar="TREE", default=None,
                   help="make variations of this RGBA tree: it gets weight 0.6-0.9 and the library trees the rest (§3)")  # fmt: skip
    p.add_argument(
        "--size",
        type=_positive,
        default=1024,
        help="side of the square output images; the library is normalised to it (default 1024)",
    )
    p.add_argument(
        "--sources", type=_positive, default=2, help="trees combined in each new tree, --like included (default 2)"
    )
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
    p.add_argument(
        "--skip-bad",
        action="store_true",
        help="skip library images that cannot be used (no alpha, empty) instead of stopping",
    )
    p.add_argument("--sheet", metavar="PNG", default=None,
                   help="also write a contact sheet: the combination tables of the paper's Fig. 13-14 for six library trees, then the new trees")  # fmt: skip
    _common(p)
    p.set_defaults(func=_cmd_trees)

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
    _common(q)
    q.set_defaults(func=_cmd_branching_trace)
    q = bsub.add_parser("grow", help="learn an example skeleton's bending and branching and grow a new one",
                        description="Markov bending model with histogram matching (§4.2), SVM furcation model (§4.3), "
                                    "space colonisation (§4.4) and optional guidance (§4.5).")  # fmt: skip
    q.add_argument("skeleton", metavar="SKEL.json", help="the example skeleton (phloem.skeleton JSON)")
    q.add_argument("--out", required=True, metavar="NEW.json", help="new skeleton file to write")
    q.add_argument(
        "--size",
        type=_size,
        default=None,
        metavar="WxH",
        help="size of the new structure's image (default: the example's)",
    )
    q.add_argument("--preview", metavar="PNG", default=None, help="also draw the new skeleton into PNG")
    q.add_argument(
        "--histograms",
        metavar="PNG",
        default=None,
        help="also write the input and output angle and thickness histograms (Fig. 7)",
    )
    _grow_options(q)
    _common(q)
    q.set_defaults(func=_cmd_branching_grow)
    q = bsub.add_parser("render", help="paint a new skeleton with fragments of the example image (§5)",
                        description="Fragments along both skeletons, shape and colour matching, deformation by a smooth "
                                    "displacement field, photometric correction, graph-cut seams, gap completion.")  # fmt: skip
    q.add_argument("input", metavar="IN", help="the example image")
    q.add_argument("skeleton", metavar="SKEL.json", help="the example's skeleton")
    q.add_argument("target", metavar="NEW.json", help="the skeleton to paint (its shape sets the output size)")
    q.add_argument("--out", required=True, metavar="OUT", help="output image (.png, .jpg, .tif)")
    _render_options(q)
    _common(q)
    q.set_defaults(func=_cmd_branching_render)
    q = bsub.add_parser("run", help="image in, new image out: trace (or load) the skeleton, grow a new one, render it",
                        description="The whole pipeline. Writes OUT, OUT.json, the new skeleton OUT_skeleton.json and the "
                                    "input/output angle and thickness histograms OUT_histograms.png (Fig. 7).")  # fmt: skip
    q.add_argument("input", metavar="IN", help="the example image")
    q.add_argument("--skeleton", metavar="SKEL.json", default=None, help="the example's skeleton (default: trace it)")
    q.add_argument("--out", required=True, metavar="OUT", help="output image (.png, .jpg, .tif)")
    q.add_argument(
        "--size", type=_size, default=None, metavar="WxH", help="size of the new image (default: the example's)"
    )
    _trace_options(q)
    _grow_options(q)
    _render_options(q)
    _common(q)
    q.set_defaults(func=_cmd_branching_run, max_length="input")

    p = sub.add_parser("demo", help="the main job on embedded data: a bark texture from the built-in Douglas-fir photo",
                       description="Runs the bark pipeline (phloem bark) on phloem's embedded CC0 Douglas-fir bark photo.")  # fmt: skip
    p.add_argument("--out", default="bark.png", metavar="OUT", help="output image (default bark.png)")
    p.add_argument("--size", type=_size, default=(512, 512), metavar="WxH", help="output size (default 512x512)")
    _common(p)
    p.set_defaults(func=_cmd_demo)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``phloem`` command; returns the exit status."""
    ap = build_parser()
    args = ap.parse_args(argv)
    try:
        args.func(args)
    except (ValueError, TypeError, FileExistsError, FileNotFoundError, io.ImageReadError) as e:
        name = f"{args.command} {args.action}" if getattr(args, "action", None) else args.command
        print(f"phloem {name}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"phloem {args.command}: interrupted; nothing was written", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
