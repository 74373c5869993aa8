"""The ``phloem`` command: one sub-command per capability.

Every sub-command that writes an image also writes ``OUT.json`` beside it with the parameters,
the seed and the phloem version, refuses to replace existing files unless ``--force`` is given,
and checks all of that before the (possibly long) computation starts. Flags spell the Python
parameters they set (``docs/conventions.md``).
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Sequence

from .. import io
from ._common import join_negative_values
from .parser import build_parser

__all__ = ["build_parser", "main"]


# API parameter names that the CLI spells differently and that are no ``dest`` of any flag
_API_NAMES = {"k": "n_labels", "labels": "n_labels", "overwrite": "force", "target_skeleton": "target"}


def _command_parser(ap: argparse.ArgumentParser, args: argparse.Namespace) -> argparse.ArgumentParser:
    """The (sub-)sub-command parser that parsed ``args``."""
    p = ap
    for key in ("command", "action"):
        sub = next((a for a in p._actions if isinstance(a, argparse._SubParsersAction) and a.dest == key), None)
        name = getattr(args, key, None)
        if sub is None or name not in sub.choices:
            break
        p = sub.choices[name]
    return p


def _flags(p: argparse.ArgumentParser) -> dict[str, str]:
    """``dest`` → what the user types: the long option string, or the metavar of a positional."""
    flags: dict[str, str] = {}
    for a in p._actions:
        if a.help == argparse.SUPPRESS and a.dest in flags:
            continue
        if a.option_strings:
            if a.help != argparse.SUPPRESS or a.dest not in flags:
                flags[a.dest] = max(a.option_strings, key=len)
        elif isinstance(a.metavar, str):
            flags[a.dest] = a.metavar
    return flags


def _in_flags(message: str, ap: argparse.ArgumentParser, args: argparse.Namespace) -> str:
    """An API error message with the sub-command's flags in place of the Python parameter names."""
    flags = _flags(_command_parser(ap, args))
    message = message.replace("overwrite=True / --force", "--force").replace("overwrite=True", "--force")
    head, sep, rest = message.partition(": ")
    if sep and re.fullmatch(r"[a-z_]+", head):
        dest = _API_NAMES.get(head, head) if head not in flags else head
        if head == "path":  # io.read_image: the file named in the message
            dest = next((d for d, v in vars(args).items() if d in flags and isinstance(v, str) and v and v in rest), "")
        if dest in flags:
            message = f"{flags[dest]}: {rest}"

    def word(m: re.Match[str]) -> str:
        return flags.get(m.group(0), m.group(0))

    return re.sub(r"\b[a-z]+(?:_[a-z]+)+\b", word, message)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``phloem`` command; returns the exit status."""
    ap = build_parser()
    args = ap.parse_args(join_negative_values(sys.argv[1:] if argv is None else argv))
    try:
        args.func(args)
    except (ValueError, TypeError, FileExistsError, FileNotFoundError, io.ImageReadError) as e:
        name = f"{args.command} {args.action}" if getattr(args, "action", None) else args.command
        print(f"phloem {name}: error: {_in_flags(str(e), ap, args)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"phloem {args.command}: interrupted; nothing was written", file=sys.stderr)
        return 130
    return 0
