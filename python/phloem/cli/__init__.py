"""The ``phloem`` command: one sub-command per capability.

Every sub-command that writes an image also writes ``OUT.json`` beside it with the parameters,
the seed and the phloem version, refuses to replace existing files unless ``--force`` is given,
and checks all of that before the (possibly long) computation starts. Flags spell the Python
parameters they set (``docs/conventions.md``).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from .. import io
from .parser import build_parser

__all__ = ["build_parser", "main"]


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
