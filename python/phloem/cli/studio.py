"""``phloem studio``: the local web page of phloem's interactive tools (:mod:`phloem.studio`)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from .. import io
from ._common import max_memory, positive


def _cmd_studio(args: argparse.Namespace) -> None:
    try:
        from .. import studio
    except ImportError as e:  # the optional extra is missing
        raise ValueError(f'studio: needs the studio extra (pip install "phloem[studio]"): {e}') from None
    root = Path(args.project)
    if not root.exists() and root.parent.is_dir():  # a new project: its folder, not its parents
        root.mkdir()
    if not root.is_dir():
        raise FileNotFoundError(f"PROJECT_DIR: {root} is not a folder")
    project = studio.Project(
        root, max_pixels=args.max_pixels, max_upload_bytes=args.max_upload, max_memory=args.max_memory
    )
    studio.serve(project, host=args.host, port=args.port, open_browser=not args.no_browser, threads=args.threads)


def add_parsers(sub: Any) -> None:
    p = sub.add_parser(
        "studio",
        help="the interactive tools in a local web page: strokes, bark label maps, skeletons, leaf scribbles, trees, textures",
        description="Starts a local web server over PROJECT_DIR and opens its page, one workspace per tool: draw "
        "source and target strokes and render them (phloem strokes edit); turn a bark photo into a label map, paint "
        "it and make a texture (phloem bark); trace a branching structure, edit its skeleton with the mouse, draw a "
        "guide, grow and render new ones (phloem branching); scribble layers on a leaf, expand them and synthesise "
        "new leaves (phloem leaves); make tree variations from a library folder (phloem trees); synthesise, quilt, "
        "or fill a brush-painted hole (phloem synthesize, quilt, complete). Everything is saved in PROJECT_DIR as the "
        "files the CLI reads (stroke, skeleton and guide JSON, label-map, scribble and mask PNGs, results with "
        "their .json sidecars). The server listens on 127.0.0.1 and every request needs the random token in the "
        "URL it prints. Ctrl-C stops it. Needs the studio extra: "
        'pip install "phloem[studio]". See docs/studio.md.',
    )
    p.add_argument("project", metavar="PROJECT_DIR", nargs="?", default=".",
                   help="folder the studio reads and writes, made if new; nothing outside it is touched (default: this folder)")  # fmt: skip
    p.add_argument("--port", type=int, default=8765, help="port to listen on (default 8765; 0 picks a free one)")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default 127.0.0.1, this machine only; the token guards any other)")  # fmt: skip
    p.add_argument("--no-browser", action="store_true", help="print the URL but do not open a browser")
    p.add_argument("--threads", type=positive, default=None, help="worker threads of each job (default: all cores)")
    p.add_argument("--max-pixels", type=positive, default=io.DEFAULT_MAX_PIXELS,
                   help="refuse images larger than this many pixels (default %(default)s)")  # fmt: skip
    p.add_argument("--max-upload", type=positive, default=64 * 2**20, metavar="BYTES",
                   help="refuse uploads larger than this many bytes (default %(default)s)")  # fmt: skip
    p.add_argument("--max-memory", type=max_memory, default=None, metavar="BYTES",
                   help="refuse a job whose estimated peak memory is over this (e.g. 8G; default 75%% of this machine's)")  # fmt: skip
    p.set_defaults(func=_cmd_studio)
