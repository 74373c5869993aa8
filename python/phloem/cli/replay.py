"""``phloem replay SIDECAR`` (and ``--from-json SIDECAR`` on every sub-command): re-run the command
a sidecar records, with the values it ran with, to the same bytes (``docs/replay.md``)."""

from __future__ import annotations

import argparse
import contextlib
import io as _pyio
import os
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .. import _json, io
from ._common import NOT_PARAMETERS, OUTPUT_ARGUMENTS, outputs, parse_size, parse_square_size, transaction

__all__ = ["command_line", "read_sidecar", "replay"]


def _fail(path: Any, what: str) -> ValueError:
    return ValueError(f"sidecar: {path}: {what}")


def read_sidecar(path: str | os.PathLike[str]) -> dict[str, Any]:
    """A sidecar's fields, checked: one-line ``ValueError`` naming the file and what is wrong.

    Sidecars of layout 1 (no ``sidecar_version``) are read too: they have no input hashes, and
    their ``parameters`` also hold what the run found, which replay ignores.
    """
    meta = _json.read_json(path, "sidecar")
    if not isinstance(meta, dict):
        raise _fail(path, f"expected a JSON object (a phloem sidecar), got {type(meta).__name__}")
    version = meta.get("sidecar_version", 1)
    if not isinstance(version, int) or isinstance(version, bool) or not 1 <= version <= io.SIDECAR_VERSION:
        raise _fail(path, f"sidecar_version {version!r} is not one this phloem reads (1 to {io.SIDECAR_VERSION})")
    if not isinstance(meta.get("command"), str):
        raise _fail(path, "'command' is missing or not a string")
    if not isinstance(meta.get("parameters"), dict):
        raise _fail(path, "'parameters' is missing or not an object")
    for key in ("seed", "threads"):
        value = meta.get(key)
        if value is not None and (not isinstance(value, int) or isinstance(value, bool) or value < 0):
            raise _fail(path, f"{key!r} must be a non-negative integer or null, got {value!r}")
    if version >= 2 and not isinstance(meta.get("inputs"), list):
        raise _fail(path, "'inputs' is missing or not a list")
    for i, rec in enumerate(meta.get("inputs") or []):
        if not (isinstance(rec, dict) and isinstance(rec.get("path"), str) and isinstance(rec.get("sha256"), str)):
            raise _fail(path, f"inputs[{i}] must be an object with a 'path' and a 'sha256' string")
    return meta


def _parser_of(ap: argparse.ArgumentParser, command: str, path: Any) -> argparse.ArgumentParser:
    """The sub-command parser of a recorded ``command`` ("synthesize", "branching trace")."""
    p = ap
    for word in command.split():
        sub = next((a for a in p._actions if isinstance(a, argparse._SubParsersAction)), None)
        if sub is None or word not in sub.choices:
            break
        p = sub.choices[word]
    else:
        if any(a.dest == "from_json" for a in p._actions):  # the sub-commands that write sidecars
            return p
    raise _fail(path, f"command 'phloem {command}' is not a sub-command this phloem can replay")


def _words(action: argparse.Action, value: Any) -> list[str]:
    """A recorded value as the command-line words that parse back to it."""
    if action.type is parse_size and isinstance(value, list) and len(value) == 2:
        return [f"{value[1]}x{value[0]}"]  # recorded (H, W), typed WxH
    if action.type is parse_square_size and isinstance(value, list) and len(value) == 2:
        return [str(value[0])]
    if isinstance(value, list):
        return [str(v) for v in value]
    return [str(value)]


def _relocate(parameters: dict[str, Any], out: str | os.PathLike[str]) -> dict[str, Any]:
    """The main output (``out``, or ``out_dir`` for commands that write a folder of results) at
    ``out``; every other named output keeps its file name and goes beside it."""
    new = dict(parameters)
    main = "out_dir" if isinstance(parameters.get("out_dir"), str) else "out"
    new[main] = str(out)
    folder = Path(out).parent
    for dest in OUTPUT_ARGUMENTS:
        if dest != main and isinstance(new.get(dest), str):
            new[dest] = str(folder / Path(new[dest]).name)
    return new


def command_line(
    meta: dict[str, Any],
    *,
    out: str | os.PathLike[str] | None = None,
    overwrite: bool = False,
    quiet: bool = False,
    path: Any = "sidecar",
) -> list[str]:
    """The ``phloem`` arguments that re-run a sidecar's command (``meta`` from :func:`read_sidecar`).

    Every option the command has is passed with its recorded value, so a default that changed in
    a later phloem does not change the output; options the sidecar does not record (layout 1)
    keep their defaults.

    Examples
    --------
    >>> from phloem.cli.replay import command_line
    >>> command_line({"command": "quilt", "seed": 3, "threads": 2, "parameters": {"input": "ex.png",
    ...     "size": [48, 64], "out": "q.png", "block": 24, "overlap": 6, "randomness": 0.01, "cost": "kwatra",
    ...     "bit_depth": 8}}, out="again/q.png")
    ['quilt', 'ex.png', '--size=64x48', '--out=again/q.png', '--block=24', '--overlap=6', '--randomness=0.01', '--cost=kwatra', '--bit-depth=8', '--seed', '3', '--threads', '2']
    """
    from .parser import build_parser

    command = str(meta["command"])
    p = _parser_of(build_parser(), command, path)
    params = meta["parameters"] if out is None else _relocate(meta["parameters"], out)
    argv = command.split()
    for action in p._actions:
        dest = action.dest
        if dest in NOT_PARAMETERS or action.help == argparse.SUPPRESS or dest not in params:
            continue
        value = params[dest]
        if not action.option_strings:  # a positional
            if value is not None:
                argv += _words(action, value)
            continue
        flag = max(action.option_strings, key=len)
        if isinstance(action, argparse.BooleanOptionalAction):  # --x / --no-x, None: the default
            if isinstance(value, bool):
                argv.append(action.option_strings[0 if value else 1])
            elif value is not None:
                raise _fail(path, f"parameter {dest!r} must be true, false or null, got {value!r}")
        elif isinstance(action, argparse._StoreTrueAction):
            if value is True:
                argv.append(flag)
            elif value is not False:
                raise _fail(path, f"parameter {dest!r} must be true or false, got {value!r}")
        elif value is None:
            if action.default is not None:  # None is an option's "off", spelled none (--stand-in-weight none)
                argv += [flag, "none"]
        elif action.nargs in (None, "?"):
            argv.append(f"{flag}={_words(action, value)[0]}")  # one word, even one that starts with '-'
        else:
            argv += [flag, *_words(action, value)]
    if meta.get("seed") is not None:
        argv += ["--seed", str(meta["seed"])]
    if meta.get("threads") is not None:
        argv += ["--threads", str(meta["threads"])]
    return argv + (["--force"] if overwrite else []) + (["-q"] if quiet else [])


def _check_inputs(meta: dict[str, Any], allow_changed: bool, path: Any, warn: Callable[[str], None]) -> None:
    from .. import __version__

    for rec in meta.get("inputs") or []:
        f = rec["path"]
        if not os.path.exists(f):
            raise ValueError(f"input {f}: no such file or folder (paths are as given to the recorded command)")
        if not allow_changed and io.file_digest(f) != rec["sha256"]:
            raise ValueError(
                f"input {f} has changed since the recorded run (its SHA-256 differs); "
                "pass --allow-changed-inputs to replay on it anyway"
            )
    if "inputs" not in meta:
        warn(f"{path} is a layout-1 sidecar without input hashes; the inputs are not checked")
    recorded = meta.get("phloem_version")
    if recorded != __version__:
        warn(
            f"{path} was written by phloem {recorded or '(unknown)'}, this is phloem {__version__}; the bytes may differ"
        )


def _python_warning(message: str) -> None:
    warnings.warn(message, UserWarning, stacklevel=5)  # at the caller of phloem.replay


def prepare(
    sidecar: str | os.PathLike[str],
    *,
    out: str | os.PathLike[str] | None = None,
    overwrite: bool = False,
    allow_changed_inputs: bool = False,
    quiet: bool = True,
    expect: str | None = None,
    warn: Callable[[str], None] = _python_warning,
) -> argparse.Namespace:
    """The parsed arguments of a sidecar's command, inputs checked; ``expect`` is the command
    ``--from-json`` was given to (``phloem branching --from-json S``), or None; ``warn`` gets the
    lines about another phloem version or unchecked inputs."""
    from .parser import build_parser

    meta = read_sidecar(sidecar)
    command = str(meta["command"])
    if expect and command.split()[: len(expect.split())] != expect.split():
        raise ValueError(f"--from-json: {sidecar} records 'phloem {command}', not 'phloem {expect}'")
    argv = command_line(meta, out=out, overwrite=overwrite, quiet=quiet, path=sidecar)
    err = _pyio.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            args = build_parser().parse_args(argv)
    except SystemExit:
        why = err.getvalue().strip().splitlines()[-1:] or ["unreadable parameters"]
        raise _fail(sidecar, f"its parameters do not make a valid 'phloem {command}' ({why[0]})") from None
    _check_inputs(meta, allow_changed_inputs, sidecar, warn)
    return args


def replay(
    sidecar: str | os.PathLike[str],
    *,
    out: str | os.PathLike[str] | None = None,
    overwrite: bool = False,
    allow_changed_inputs: bool = False,
) -> Path:
    """Re-run the command a sidecar records, with the values it ran with, to the same bytes.

    Parameters
    ----------
    sidecar : str or path-like
        A sidecar written beside an output (``out.png.json``, ``skel.sidecar.json``).
    out : str or path-like, optional
        Where the main output goes (``OUT``, or ``DIR`` for the commands that write a folder:
        ``trees``, ``leaves synthesize|run|extract``); the other outputs keep their names and go
        beside it. Default: the recorded paths.
    overwrite : bool, optional
        Replace existing outputs (``--force``); by default an existing one raises
        ``FileExistsError`` and nothing is written.
    allow_changed_inputs : bool, optional
        Run even if an input file's SHA-256 is not the recorded one (by default a ``ValueError``
        names the file).

    Returns
    -------
    path : Path
        The main output (file or folder).

    Warns
    -----
    UserWarning
        If the sidecar was written by another phloem version.

    Examples
    --------
    >>> import os, pathlib, tempfile, phloem
    >>> from phloem.cli import main
    >>> d = tempfile.mkdtemp(); ex = os.path.join(d, "ex.png"); q = os.path.join(d, "q.png")
    >>> phloem.io.write_image(ex, phloem.data.bark()[:48, :48])
    >>> main(["quilt", ex, "--size", "64", "--out", q, "-q"])
    0
    >>> again = phloem.replay(q + ".json", out=os.path.join(d, "again", "q.png"))
    >>> again.read_bytes() == pathlib.Path(q).read_bytes()
    True
    """
    args = prepare(sidecar, out=out, overwrite=overwrite, allow_changed_inputs=allow_changed_inputs)
    with outputs(args) as tx:
        tx.make_folders = True
        args.func(args)
        tx.commit()
    return Path(args.out_dir if isinstance(getattr(args, "out_dir", None), str) else args.out)


def _cmd_replay(args: argparse.Namespace) -> None:
    inner = prepare(args.sidecar, out=args.out, overwrite=args.force, allow_changed_inputs=args.allow_changed_inputs,
                    quiet=args.quiet, expect=args.expect, warn=lambda m: print(f"phloem replay: warning: {m}", file=sys.stderr))  # fmt: skip
    transaction().make_folders = True  # --out may name a new folder
    inner.func(inner)


def add_parsers(sub: Any) -> None:
    p = sub.add_parser("replay", help="re-run the command a sidecar records, to the same bytes",
                       description="Reads SIDECAR (the .json written beside every output), checks that its input files "
                                   "are unchanged (SHA-256) and runs its command again with every value it ran with: "
                                   "seed, resolved defaults, thread count. 'phloem COMMAND --from-json SIDECAR' does the "
                                   "same. See docs/replay.md.")  # fmt: skip
    p.add_argument("sidecar", metavar="SIDECAR", help="a sidecar: OUT.png.json, SKEL.sidecar.json, MODEL.json")
    p.add_argument("--out", metavar="PATH", default=None,
                   help="where the main output goes (OUT, or DIR for trees and leaves); the other outputs keep their "
                        "names and go beside it (default: the recorded paths)")  # fmt: skip
    p.add_argument("--out-dir", dest="out", default=None, help=argparse.SUPPRESS)  # as 'phloem trees' spells it
    p.add_argument("--force", action="store_true", help="replace the outputs and sidecars if they exist")
    p.add_argument("--allow-changed-inputs", action="store_true",
                   help="run even if an input file is not the one recorded (its SHA-256 differs)")  # fmt: skip
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.add_argument("--expect", default=None, help=argparse.SUPPRESS)  # the command --from-json came with
    p.set_defaults(func=_cmd_replay)
