"""``phloem bark``: :func:`phloem.bark.generate` on files, with its label maps, height map and preview."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from .. import bark, data, io, shapes
from ._common import (
    common_options,
    deprecated_alias,
    non_negative,
    parse_size,
    positive,
    preflight,
    run,
    save,
    stage_image,
)


def _weight(text: str) -> float | None:
    """``--stand-in-weight``: a finite number >= 0, or ``none`` for no stand-ins."""
    return None if text.lower() == "none" else non_negative(text)


def _targets(args: argparse.Namespace) -> dict[str, Path]:
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
    extra = _targets(args)
    preflight(args, list(extra.values()))  # also refuses two outputs of one name
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
    res = run(
        "bark",
        args,
        lambda bar: bark.generate(
            photo,
            args.size,
            n_labels=args.n_labels,
            height_map=hm,
            labels_in=lab_in,
            labels_out=lab_out,
            method=args.method,
            rotations=args.rotations,
            edge_label=args.edge_label,
            tileable=args.tileable,
            seed=args.seed,
            stand_in_weight=args.stand_in_weight,
            threads=args.threads,
            max_memory=args.max_memory,
            progress=bar,
            full_output=True,
        ),
    )
    written = {role: str(p) for role, p in extra.items()}
    save(args, "bark", res.texture, input=args.input or "phloem.data.bark()", files=written)
    maps = {"labels_in": res.labels_in, "labels_out": res.labels_out}
    for role, path in extra.items():
        if role in maps:
            img = bark.encode_labels(maps[role])
        elif role == "height":
            assert res.height is not None
            img = res.height
        else:
            img = bark.cylinder_preview(res.texture, height=res.height)
        stage_image(path, img, args, bit_depth=16 if role == "height" else None)


def add_parsers(sub: Any) -> None:
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
        type=parse_size,
        default=None,
        metavar="WxH",
        help="output width x height, e.g. 512x384, or N for NxN (required unless --labels-out is given)",
    )
    p.add_argument("--out", required=True, metavar="OUT", help="output texture (.png, .jpg, .tif)")
    p.add_argument(
        "--n-labels",
        type=positive,
        default=2,
        metavar="K",
        help="regions of the input label map (default 2; 2-3 work best)",
    )
    deprecated_alias(p, "--labels", "--n-labels", dest="n_labels", type=positive)
    p.add_argument("--method", choices=("layered", "joint"), default="joint",
                   help="label-map synthesis: phloem's joint multi-label variant (default) or the thesis' nested layers")  # fmt: skip
    p.add_argument("--rotations", choices=shapes.ROTATIONS, default="half",
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
    p.add_argument("--stand-in-weight", type=_weight, default=5.0, metavar="W|none",
                   help="cost of letting a coherent piece of the photo run across a label boundary on nearest-coloured pixels "
                        "of the right label (default 5; lower: more seamless, looser boundaries); none: no stand-ins, the "
                        "texture follows every boundary of the label map exactly, with seams along them")  # fmt: skip
    deprecated_alias(p, "--strict-labels", "--stand-in-weight none", dest="stand_in_weight", flag=True)
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
    common_options(p)
    p.set_defaults(func=_cmd_bark)
