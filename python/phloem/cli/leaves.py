"""``phloem leaves extract|analyze|synthesize|run``: :mod:`phloem.leaves` on scans and model folders."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from .. import io, leaves
from ._common import (
    check_writable,
    common_options,
    kept,
    params,
    positive,
    run,
    sidecar,
    stage_image,
    stage_result,
    sub_seed,
    transaction,
)

#: A leaf's source file size ``(H, W)`` and its box ``(y0, y1, x0, x1)`` in it.
Cut = tuple[tuple[int, ...], tuple[int, int, int, int]]


def _read_leaves(files: list[str], args: argparse.Namespace) -> tuple[list[np.ndarray], list[str], list[Cut]]:
    """Every leaf of every file, in file order then reading order; where each came from; and its
    cut (the file's size and the leaf's box in it)."""
    out: list[np.ndarray] = []
    where: list[str] = []
    cuts: list[Cut] = []
    for f in files:
        img = io.read_image(f, max_pixels=args.max_pixels)
        try:
            found = leaves.extract(img, full_output=True)
        except ValueError as e:
            raise ValueError(f"LEAF: {f}: {str(e).split(': ', 1)[-1]}") from None
        out += found.leaves
        where += [f"{f}#{j}" for j in range(len(found.leaves))]
        cuts += [(img.shape[:2], box) for box in found.boxes]
    return out, where, cuts


def _scribbles(args: argparse.Namespace, leaf: np.ndarray, cut: Cut) -> Any:
    """The scribbles file as labels of the training leaf: drawn on the leaf as ``phloem leaves
    extract`` writes it, taken as they are; drawn on the whole scan, cut with the leaf's box."""
    (fh, fw), (y0, y1, x0, x1) = cut
    size = io.image_size(args.scribbles, max_pixels=args.max_pixels)
    if size == leaf.shape[:2] or size != (fh, fw):
        return args.scribbles  # leaves.analyze reads it, or says which size it expected
    labels, _ = leaves.read_scribbles(args.scribbles, (fh, fw))
    out = np.zeros((y1 - y0, x1 - x0), np.int32)
    sy, sx = slice(max(0, y0), min(fh, y1)), slice(max(0, x0), min(fw, x1))
    out[sy.start - y0 : sy.stop - y0, sx.start - x0 : sx.stop - x0] = labels[sy, sx]
    return out


def _order(text: str | None) -> list[int] | None:
    if text is None:
        return None
    try:
        return [int(v) for v in text.split(",")]
    except ValueError:
        raise ValueError(f"order: expected comma-separated layer labels such as 2,1,3, got {text!r}") from None


def _reserve_folder(folder: Path, names: list[str], args: argparse.Namespace) -> None:
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"out: {folder} exists and is not a folder")
    transaction().make_folders = True
    for name in names:
        transaction().reserve(folder / name)


def _stage_model(model: leaves.LeafModel, folder: Path, args: argparse.Namespace, where: list[str]) -> None:
    for name, data in model.files().items():
        transaction().stage(folder / name, data)
    side = io.sidecar_path(folder)
    # A model written by 'leaves run' is recorded as the 'leaves analyze' run that writes it alone.
    parameters = {**params(args, skip=("out_dir", "count", "prefix", "sheet", "model_out")), "out": str(folder),
                  "sheet": getattr(args, "sheet", None) if args.action == "analyze" else None}  # fmt: skip
    details = {"leaves": where, "lam": model.lam, "delta": model.delta, "objective": model.objective,
               "residual": model.residual}  # fmt: skip
    transaction().stage(side, sidecar(folder, args, "leaves analyze", details, parameters))
    if not args.quiet:
        transaction().notes.append(f"wrote the model {folder} and {side}")


def _analyze(args: argparse.Namespace, model_dir: Path | None) -> tuple[leaves.LeafModel, list[str]]:
    """Read the leaves and scribbles, analyse them, and stage the model when asked to."""
    imgs, where, cuts = run("leaves: extract", args, lambda bar: _read_leaves(args.leaves, args))
    if not 0 <= args.training < len(imgs):
        raise ValueError(f"training: the LEAF files hold {len(imgs)} leaves, so it must be 0 to {len(imgs) - 1}")
    scribbles = _scribbles(args, imgs[args.training], cuts[args.training])
    model = run(
        "leaves: analyze", args,
        lambda bar: leaves.analyze(imgs, scribbles, training=args.training, order=_order(args.order),
                                   points=args.points, epsilon=args.epsilon, kappa=args.kappa, seed=args.seed,
                                   keep_holes=args.keep_holes, threads=args.threads, progress=bar,
                                   max_memory=args.max_memory),
    )  # fmt: skip
    if model_dir is not None:
        _stage_model(model, model_dir, args, where)
    return model, where


def _synthesize(model: leaves.LeafModel, args: argparse.Namespace, origin: str) -> list[np.ndarray]:
    """New leaves with their sidecars (command: the one that ran, synthesize or run)."""
    out_dir = Path(args.out_dir)
    targets = [out_dir / f"{args.prefix}{i:04d}.png" for i in range(args.count)]

    def make(bar: Any) -> list[np.ndarray]:
        res = []
        # one call per leaf with its own seed (the sidecar's leaf_seed), so any leaf can be remade alone
        for i in range(args.count):
            res += leaves.synthesize(model, count=1, seed=sub_seed(args.seed, i), threads=args.threads)
            bar(i + 1, args.count)
        return res

    new = run("leaves: synthesize", args, make)
    for i, (img, path) in enumerate(zip(new, targets)):
        stage_result(path, img, args, f"leaves {args.action}", {"model": origin, "leaf_seed": sub_seed(args.seed, i)},
                     quiet=True)  # fmt: skip
    if not args.quiet:
        transaction().notes.append(f"wrote {len(targets)} leaves (and their .json) to {out_dir}")
    return new


def _reserve_leaves(args: argparse.Namespace) -> None:
    out_dir = Path(args.out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise ValueError(f"out-dir: {out_dir} exists and is not a folder")
    transaction().make_folders = True
    for i in range(args.count):
        t = out_dir / f"{args.prefix}{i:04d}.png"
        check_writable(t, args)
        transaction().reserve(io.sidecar_path(t))
    if args.sheet is not None:
        check_writable(Path(args.sheet), args)


def _cmd_leaves_extract(args: argparse.Namespace) -> None:
    out_dir = Path(args.out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise ValueError(f"out-dir: {out_dir} exists and is not a folder")
    transaction().make_folders = True
    imgs, where, _ = _read_leaves(args.leaves, args)
    for k, (img, origin) in enumerate(zip(imgs, where)):
        f, j = origin.rsplit("#", 1)
        path = out_dir / f"{Path(f).stem}_{int(j)}.png"
        check_writable(path, args)
        stage_result(path, img, args, "leaves extract", {"source": origin, "index": k}, quiet=True)
    if not args.quiet:
        transaction().notes.append(f"wrote {len(imgs)} leaves (and their .json) to {out_dir}")


def _cmd_leaves_analyze(args: argparse.Namespace) -> None:
    folder = Path(args.out)
    # the exemplar count is known only after extraction: reserve model.json now, the rest when staged
    _reserve_folder(folder, ["model.json"], args)
    transaction().reserve(io.sidecar_path(folder))
    if args.sheet is not None:
        check_writable(Path(args.sheet), args)
    model, _ = _analyze(args, folder)
    if args.sheet is not None:
        stage_image(args.sheet, leaves.contact_sheet(model), args)


def _load_model(folder: Path) -> leaves.LeafModel:
    # a batch worker runs many items of one model, and reading one takes seconds; the CLI never
    # changes a model, so the process keeps the last one it read
    try:
        files = sorted(folder.iterdir())
    except OSError:
        return leaves.LeafModel.load(folder)  # its own one-line error
    model: leaves.LeafModel = kept("leaves model", files, (), lambda: leaves.LeafModel.load(folder))
    return model


def _cmd_leaves_synthesize(args: argparse.Namespace) -> None:
    _reserve_leaves(args)
    model = run("leaves: load", args, lambda bar: _load_model(Path(args.model)))
    new = _synthesize(model, args, str(args.model))
    if args.sheet is not None:
        stage_image(args.sheet, leaves.contact_sheet(model, new), args)


def _cmd_leaves_run(args: argparse.Namespace) -> None:
    _reserve_leaves(args)
    folder = None if args.model_out is None else Path(args.model_out)
    if folder is not None:
        _reserve_folder(folder, ["model.json"], args)
        transaction().reserve(io.sidecar_path(folder))
    model, where = _analyze(args, folder)
    new = _synthesize(model, args, str(folder) if folder is not None else ", ".join(where))
    if args.sheet is not None:
        stage_image(args.sheet, leaves.contact_sheet(model, new), args)


def _analysis_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("leaves", metavar="LEAF", nargs="+",
                   help="scans or photos of leaves of one species on a plain background, or RGBA leaf PNGs; a scan with "
                        "several leaves gives several exemplars (at least 2 in all)")  # fmt: skip
    p.add_argument("--scribbles", required=True, metavar="PNG",
                   help="strokes on the training leaf, drawn on its scan or on the leaf as 'phloem leaves extract' writes "
                        "it: one opaque colour per layer (numbered in order of first appearance, row by row) or an integer "
                        "PNG (0 unmarked, 1..n); the last layer is the residual (blade)")  # fmt: skip
    p.add_argument("--training", type=int, default=0, metavar="K",
                   help="which leaf the scribbles are on, counting the leaves of all LEAF files in order from 0 (default 0)")  # fmt: skip
    p.add_argument("--order", default=None, metavar="L1,L2,...",
                   help="layer labels in removal order, the residual layer last (default 1,2,...,n)")  # fmt: skip
    p.add_argument(
        "--points", type=positive, default=100, help="registration keypoints per leaf (default 100, as the paper)"
    )
    p.add_argument("--epsilon", type=float, default=40.0,
                   help="spatial falloff of layer induction in pixels, about the largest registration error (default 40, Eq. 3)")  # fmt: skip
    p.add_argument("--kappa", type=float, default=1.5, help="κ of Eq. 5: how strongly layer overlap makes a layer structural (default 1.5)")  # fmt: skip
    p.add_argument("--keep-holes", action="store_true",
                   help="keep the exemplars' interior holes (insect damage) in their background layers; by default they "
                        "are filled, since a hole left there would repeat in every new leaf drawn on that background")  # fmt: skip


def _synthesis_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--count", type=positive, required=True, metavar="N", help="number of new leaves")
    p.add_argument("--out-dir", required=True, metavar="DIR", help="folder for the new leaves (created if missing)")
    p.add_argument("--prefix", default="leaf_", help="file name prefix of the new leaves (default leaf_)")


def add_parsers(sub: Any) -> None:
    p = sub.add_parser("leaves", help="new leaves of one species from a few scans (Assa & Cohen-Or, structural layering)",
                       description="Register a handful of leaves to a training leaf (TPS-RPM, §3), expand scribbles on it into "
                                   "layers and induce them on every leaf (§4), and make new leaves by mixing warped layers of "
                                   "different leaves (§5).")  # fmt: skip
    lsub = p.add_subparsers(dest="action", metavar="ACTION", required=True, help="each has its own --help")
    q = lsub.add_parser("extract", help="cut the leaves of scans into RGBA PNGs (to draw scribbles on)",
                        description="Each leaf of each scan (plain background) becomes DIR/STEM_J.png, J in reading order.")  # fmt: skip
    q.add_argument("leaves", metavar="SCAN", nargs="+", help="scans or photos of leaves on a plain background")
    q.add_argument("--out-dir", required=True, metavar="DIR", help="folder for the leaves (created if missing)")
    common_options(q)
    q.set_defaults(func=_cmd_leaves_extract)

    q = lsub.add_parser("analyze", help="analyse leaves and scribbles into a model folder",
                        description="Writes the folder MODEL (model.json and one exemplar_NNN.npz per leaf) and MODEL.json, "
                                    "the run's parameters.")  # fmt: skip
    _analysis_options(q)
    q.add_argument("--out", required=True, metavar="MODEL", help="model folder to write")
    q.add_argument(
        "--sheet",
        metavar="PNG",
        default=None,
        help="also write a contact sheet: exemplars, aligned, layers, backgrounds",
    )
    common_options(q)
    q.set_defaults(func=_cmd_leaves_analyze)

    q = lsub.add_parser("synthesize", help="new leaves from a model folder",
                        description="Writes DIR/PREFIX0000.png ... (RGBA), each with a .json sidecar holding its own seed.")  # fmt: skip
    q.add_argument("model", metavar="MODEL", help="a folder written by 'phloem leaves analyze'")
    _synthesis_options(q)
    q.add_argument(
        "--sheet", metavar="PNG", default=None, help="also write a contact sheet: the model's rows, then the new leaves"
    )
    common_options(q)
    q.set_defaults(func=_cmd_leaves_synthesize)

    q = lsub.add_parser("run", help="leaves and scribbles in, new leaves out (analyze, then synthesize)",
                        description="The whole pipeline; --model-out keeps the model for later 'synthesize' runs.")  # fmt: skip
    _analysis_options(q)
    _synthesis_options(q)
    q.add_argument("--model-out", metavar="MODEL", default=None, help="also write the model folder")
    q.add_argument(
        "--sheet", metavar="PNG", default=None, help="also write a contact sheet: exemplars, layers, new leaves"
    )
    common_options(q)
    q.set_defaults(func=_cmd_leaves_run)
