"""The argument parser of the ``phloem`` command, assembled from one module per sub-command family."""

from __future__ import annotations

import argparse

from .. import __version__
from . import bark, batch, branching, demo, leaves, patch, replay, strokes, studio, texture, trees


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
    for family in (
        texture,
        patch,
        bark,
        trees,
        leaves,
        strokes,
        branching,
        batch,
        demo,
        replay,
        studio,
    ):  # the order of the command list in --help
        family.add_parsers(sub)
    return ap
