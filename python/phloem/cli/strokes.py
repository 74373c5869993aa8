"""``phloem strokes edit|draw``: :mod:`phloem.strokes` on images and stroke files."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from .. import io, strokes
from ._common import common_options, parse_size, preflight, run, save, stage_image


def _stroke_set(args: argparse.Namespace, *, svg_widths: bool = False) -> strokes.StrokeSet:
    path = Path(args.strokes)
    if path.suffix.lower() == ".svg":
        src = strokes.read_svg(path, layer=args.source_layer)
        tgt = strokes.read_svg(path, layer=args.target_layer)
        widths = strokes.read_svg_widths(path, layer=args.target_layer) if svg_widths else None
        return strokes.StrokeSet.from_lists(src, tgt, widths=widths)
    if svg_widths:
        raise ValueError(f"--svg-widths: expected an SVG stroke drawing, got {path.name}")
    return strokes.StrokeSet.load(path)


def _mask(args: argparse.Namespace, shape: tuple[int, int]) -> np.ndarray | None:
    if args.mask is None:
        return None
    m = io.read_image(args.mask, max_pixels=args.max_pixels)
    if m.shape[:2] != shape:
        raise ValueError(f"mask: {args.mask} is {m.shape[1]}×{m.shape[0]}, but the image is {shape[1]}×{shape[0]}")
    channels = 1 if m.ndim == 2 else m.shape[2]
    if channels in (2, 4) and (m[..., -1] < 1).any():
        return np.asarray(m[..., -1] >= 0.5)
    gray = m if m.ndim == 2 else m[..., : min(channels, 3)].max(axis=2)
    return np.asarray(gray >= 0.5)


def _cmd_edit(args: argparse.Namespace) -> None:
    extra = [] if args.sheet is None else [Path(args.sheet)]
    preflight(args, extra)
    img = io.read_image(args.image, max_pixels=args.max_pixels)
    sset = _stroke_set(args, svg_widths=args.svg_widths)
    mask = _mask(args, img.shape[:2])
    scene = None if args.background is None else io.read_image(args.background, max_pixels=args.max_pixels)
    res = run(
        "strokes edit",
        args,
        lambda bar: strokes.edit(
            img, sset, size=args.size, mask=mask, spacing=args.spacing, stretch=args.stretch, sampling=args.sampling,
            background=scene, threads=args.threads, progress=bar, max_memory=args.max_memory, full_output=True,
        ),
    )  # fmt: skip
    if args.sheet is not None:
        stage_image(args.sheet, strokes.contact_sheet(img, sset, res), args, bit_depth=8)
    args.size = res.image.shape[:2]  # recorded resolved: the background's, target_size or IMAGE's
    save(args, "strokes edit", res.image)


def _cmd_draw(args: argparse.Namespace) -> None:
    preflight(args)
    sset = _stroke_set(args)
    if args.side == "source":
        img = io.read_image(args.image, max_pixels=args.max_pixels)
    else:
        h, w = args.size = args.size or sset.target_size or io.image_size(args.image)
        img = np.full((h, w, 3), 0.92, np.float32)
    save(args, "strokes draw", strokes.draw(img, sset, side=args.side))


def _strokes_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("strokes", metavar="STROKES",
                   help="stroke set: a phloem.strokes JSON file, or an SVG drawing with a source and a target layer")  # fmt: skip
    p.add_argument("--source-layer", default="source", metavar="NAME",
                   help="SVG only: the layer (label, name or id) of the source strokes (default 'source')")  # fmt: skip
    p.add_argument("--target-layer", default="target", metavar="NAME",
                   help="SVG only: the layer of the target strokes, paired with the sources in drawing order (default 'target')")  # fmt: skip


def add_parsers(sub: Any) -> None:
    p = sub.add_parser("strokes", help="re-draw an object along new strokes (Luo, Lin, Shen & Chen)",
                       description="Source strokes run along an object's skeleton in a photo, target strokes say where it "
                                   "goes in the output: the object is re-drawn along the targets, bent, stretched or branched.")  # fmt: skip
    ssub = p.add_subparsers(dest="action", metavar="ACTION", required=True, help="each has its own --help")

    q = ssub.add_parser("edit", help="the object of IMAGE re-drawn along the target strokes",
                        description="Pieces of the object fetched along each target stroke, their source positions chosen by "
                                    "dynamic programming, joined by graph cuts. Writes OUT (RGBA) and OUT.json.")  # fmt: skip
    q.add_argument("image", metavar="IMAGE", help="photo of the object (PNG, JPEG or TIFF; its alpha is the object if it has one)")  # fmt: skip
    _strokes_argument(q)
    q.add_argument("--out", required=True, metavar="OUT", help="output image (.png or .tif keep the alpha)")
    q.add_argument("--mask", default=None, metavar="PNG",
                   help="the object in IMAGE: white (or opaque) pixels (default: IMAGE's alpha, else the object on a plain background)")  # fmt: skip
    q.add_argument("--size", type=parse_size, default=None, metavar="WxH",
                   help="output size (default: the stroke set's target_size, else IMAGE's size)")  # fmt: skip
    q.add_argument("--spacing", type=float, default=None, metavar="PX",
                   help="px between samples along a target stroke, half a piece's length (default: the object's median half width)")  # fmt: skip
    q.add_argument("--stretch", type=float, default=2.0,
                   help="most the source may be stretched or squeezed between samples, against the uniform mapping (default 2)")  # fmt: skip
    q.add_argument("--sampling", choices=strokes.synthesis.SAMPLINGS, default="dp",
                   help="dp: the paper's dynamic-programming texture sampling; uniform: arc-length proportional (default dp)")  # fmt: skip
    q.add_argument("--svg-widths", action="store_true",
                   help="SVG only: make the object as wide along each target stroke as that stroke is drawn "
                        "(its stroke-width); default: as wide as in the photo")  # fmt: skip
    q.add_argument("--background", default=None, metavar="IMG",
                   help="paste the object into this scene by Poisson image editing (sets the output size)")  # fmt: skip
    q.add_argument("--sheet", default=None, metavar="PNG",
                   help="also write a contact sheet: source with strokes, target strokes, pieces and seams, result")  # fmt: skip
    common_options(q)
    q.set_defaults(func=_cmd_edit)

    q = ssub.add_parser("draw", help="draw a stroke set over its image, to check it",
                        description="The source strokes over IMAGE, or the target strokes on a blank canvas of the output's "
                                    "size; each stroke numbered at its start, control points as dots.")  # fmt: skip
    q.add_argument("image", metavar="IMAGE", help="the photo the source strokes were drawn on")
    _strokes_argument(q)
    q.add_argument("--out", required=True, metavar="OUT", help="output image")
    q.add_argument(
        "--side", choices=("source", "target"), default="source", help="which strokes to draw (default source)"
    )
    q.add_argument("--size", type=parse_size, default=None, metavar="WxH",
                   help="target side: canvas size (default: the stroke set's target_size, else IMAGE's size)")  # fmt: skip
    common_options(q)
    q.set_defaults(func=_cmd_draw)
