"""The ``phloem`` command: one sub-command per capability.

Every sub-command that writes an image also writes a sidecar beside it (``OUT.png.json``;
``docs/replay.md``) with every parameter as it ran, the seed, the thread count, the inputs' hashes
and the phloem version, which ``phloem replay`` re-runs to the same bytes; each refuses to replace existing files unless ``--force`` is given,
and checks all of that before the (possibly long) computation starts. Flags spell the Python
parameters they set (``docs/conventions.md``).
"""

from __future__ import annotations

import argparse
import functools
import re
import sys
import warnings
from collections.abc import Sequence

from .. import io
from ._common import join_negative_values, outputs, resolve_bit_depth
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


def _message(e: BaseException) -> str:
    """One line for an error: ours as they are, the system's (``[Errno 28] ...: 'o.png'``) as
    ``FILE: reason``."""
    if isinstance(e, OSError) and e.errno is not None and e.strerror:
        files = [str(f) for f in (e.filename, e.filename2) if f is not None]
        return f"{' -> '.join(files)}: {e.strerror}" if files else e.strerror
    return str(e)


def _from_json(argv: list[str]) -> list[str]:
    """``phloem COMMAND [ACTION] --from-json SIDECAR [options]`` as ``phloem replay SIDECAR
    [options]``, checked against COMMAND; any other arguments are left as they are."""
    at = next((i for i, a in enumerate(argv) if a == "--from-json" or a.startswith("--from-json=")), None)
    if at is None or argv[:1] == ["replay"]:
        return argv
    first = next((i for i, a in enumerate(argv) if a.startswith("-")), len(argv))
    words = argv[:first]
    rest = argv[first:]
    at -= first
    if rest[at] == "--from-json":
        if at + 1 >= len(rest):
            return argv  # argparse says "expected one argument"
        sidecar, rest = rest[at + 1], rest[:at] + rest[at + 2 :]
    else:
        sidecar, rest = rest[at].split("=", 1)[1], rest[:at] + rest[at + 1 :]
    return ["replay", sidecar, "--expect", " ".join(words), *rest]


@functools.cache
def _parser() -> argparse.ArgumentParser:
    # built once per process: building every sub-command's options costs more than a small
    # item's work when a batch worker runs hundreds of commands (parsing does not change it)
    return build_parser()


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``phloem`` command; returns the exit status."""
    ap = _parser()
    argv = _from_json(list(sys.argv[1:] if argv is None else argv))
    args = ap.parse_args(join_negative_values(argv))
    name = f"{args.command} {args.action}" if getattr(args, "action", None) else args.command

    def one_line(message: Warning | str, *_: object, **__: object) -> None:
        # a warning (e.g. io.RescaledImageWarning) as one line, not Python's file:line + source
        print(f"phloem {name}: warning: {message}", file=sys.stderr)

    try:
        with warnings.catch_warnings(), outputs(args) as tx:
            warnings.showwarning = one_line
            resolve_bit_depth(args)
            args.func(args)
            tx.commit()
    except (ValueError, TypeError, OSError, io.ImageReadError) as e:
        print(f"phloem {name}: error: {_in_flags(_message(e), ap, args)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        what = getattr(args, "interrupted", "nothing was written")  # a command may keep finished work
        print(f"phloem {args.command}: interrupted; {what}", file=sys.stderr)
        return 130
    for note in tx.notes:
        print(note, file=sys.stderr)
    return 0
