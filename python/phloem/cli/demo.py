"""``phloem demo``: the bark pipeline on the embedded Douglas-fir photo."""

from __future__ import annotations

import argparse
from typing import Any

from .. import bark, data
from ._common import common_options, parse_size, preflight, run, save


def _cmd_demo(args: argparse.Namespace) -> None:
    preflight(args)
    out = run(
        "demo: bark texture",
        args,
        lambda bar: bark.generate(
            data.bark(), args.size, seed=args.seed, threads=args.threads, progress=bar, max_memory=args.max_memory
        ),
    )
    save(args, "demo", out, input="phloem.data.bark()", pipeline="phloem.bark.generate")


def add_parsers(sub: Any) -> None:
    p = sub.add_parser("demo", help="the main job on embedded data: a bark texture from the built-in Douglas-fir photo",
                       description="Runs the bark pipeline (phloem bark) on phloem's embedded CC0 Douglas-fir bark photo.")  # fmt: skip
    p.add_argument("--out", default="bark.png", metavar="OUT", help="output image (default bark.png)")
    p.add_argument("--size", type=parse_size, default=(512, 512), metavar="WxH",
                   help="output width x height, or N for NxN (default 512x512)")  # fmt: skip
    common_options(p)
    p.set_defaults(func=_cmd_demo)
