"""What every sub-command shares: argument types, the common options, output checks before the
computation, sidecars, the progress bar and deprecated flag spellings."""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from .. import _files, _memory, io
from .._progress import Bar
from .._seeds import sub_seed as sub_seed

T = TypeVar("T")


def parse_size(text: str) -> tuple[int, int]:
    """``--size WxH`` or ``--size N`` (N×N) as ``(height, width)``."""
    try:
        parts = [int(v) for v in text.lower().split("x")]
    except ValueError:
        parts = []
    if len(parts) == 1:
        parts *= 2
    if len(parts) != 2 or min(parts) < 1:
        raise argparse.ArgumentTypeError(
            f"expected WxH or N with positive integers (WIDTHxHEIGHT such as 512x384, or N for NxN), got {text!r}"
        )
    w, h = parts
    return h, w


def join_negative_values(argv: Sequence[str], flags: Sequence[str] = ("--size",)) -> list[str]:
    """``--size -5x5`` as ``--size=-5x5``: argparse takes a value that starts with ``-`` and is no
    plain negative number for an option and says "expected one argument"; joined, it reaches the
    size type, which names what is wrong with it."""
    out: list[str] = []
    it = iter(argv)
    for a in it:
        if a in flags:
            v = next(it, None)
            if v is not None and v[:1] == "-" and v[1:2].isdigit():
                out.append(f"{a}={v}")
                continue
            out.append(a)
            if v is not None:
                out.append(v)
            continue
        out.append(a)
    return out


def parse_square_size(text: str) -> int:
    """``--size N`` or ``--size NxN`` for outputs that must be square, as the side ``N``."""
    h, w = parse_size(text)
    if h != w:
        raise argparse.ArgumentTypeError(f"expected a square size N or NxN, got {text!r}")
    return h


def positive(text: str) -> int:
    v = int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text}")
    return v


def non_negative(text: str) -> float:
    v = float(text)
    if not (v >= 0 and v != float("inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text}")
    return v


def max_memory(text: str) -> int:
    try:
        return _memory.parse_memory(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def common_options(p: argparse.ArgumentParser, *, writes: bool = True) -> None:
    g = p.add_argument_group("common options")
    g.add_argument(
        "--seed", type=int, default=0, help="seed of every random choice; same seed, same output (default 0)"
    )
    g.add_argument(
        "--threads", type=positive, default=None, help="worker threads (default: PHLOEM_NUM_THREADS or all cores)"
    )
    g.add_argument(
        "--max-pixels",
        type=positive,
        default=io.DEFAULT_MAX_PIXELS,
        help="refuse input images larger than this many pixels (default %(default)s)",
    )
    g.add_argument(
        "--max-memory",
        type=max_memory,
        default=None,
        metavar="BYTES",
        help="refuse a job whose estimated peak memory is over this (e.g. 8G, 512M; default 75%% of this machine's)",
    )
    g.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    if writes:
        g.add_argument("--force", action="store_true", help="replace OUT and its sidecar if they exist")
        g.add_argument(
            "--from-json",
            metavar="SIDECAR",
            default=None,
            help="re-run the command a sidecar records, to the same bytes (as 'phloem replay SIDECAR'; "
            "takes --out, --force and --allow-changed-inputs, and no other option)",
        )
        g.add_argument(
            "--bit-depth",
            type=int,
            choices=(8, 16),
            default=None,
            help="bits per channel of OUT (16 for PNG/TIFF only; default: 16 where the input image has "
            "more than 8 bits and OUT can hold them, such as a 16-bit elevation model, else 8)",
        )


def deprecated_alias(
    p: argparse.ArgumentParser | argparse._ArgumentGroup,
    old: str,
    new: str,
    *,
    dest: str,
    type: Callable[[str], Any] | None = None,
    const: Any = None,
    flag: bool = False,
) -> None:
    """A hidden old spelling of a flag: it works as ``new`` (a ``flag`` stores ``const``) and
    prints one deprecation line on stderr."""

    class Alias(argparse.Action):
        def __call__(
            self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any, option: Any = None
        ) -> None:
            print(
                f"{parser.prog}: warning: {old} is deprecated and goes in the next release; use {new}", file=sys.stderr
            )
            setattr(namespace, self.dest, const if flag else values)

    if flag:
        p.add_argument(old, dest=dest, nargs=0, action=Alias, help=argparse.SUPPRESS)
    else:
        p.add_argument(old, dest=dest, type=type or str, action=Alias, help=argparse.SUPPRESS)


_active: list[_files.Transaction] = []


@contextlib.contextmanager
def outputs(args: argparse.Namespace) -> Iterator[_files.Transaction]:
    """The transaction of one command's output files: ``main`` opens it around the command and
    commits it when the command returned, so a failure or Ctrl-C anywhere leaves nothing behind."""
    with _files.Transaction(getattr(args, "force", False)) as tx:
        _active.append(tx)
        try:
            yield tx
        finally:
            _active.pop()


def transaction() -> _files.Transaction:
    """The output transaction of the running command (see :func:`outputs`)."""
    if not _active:
        raise RuntimeError("no output transaction: run sub-commands through phloem.cli.main")
    return _active[-1]


def resolve_bit_depth(args: argparse.Namespace) -> None:
    """``--bit-depth``'s default, set on ``args`` before the command runs (so the sidecar records
    it): 16 where the input image (``IN``/``IMAGE``) stores more than 8 bits and OUT is a PNG or
    TIFF, else 8. An 8-bit copy of a 16-bit elevation model keeps a handful of levels."""
    if not hasattr(args, "bit_depth") or args.bit_depth is not None:
        return
    src = next((v for v in (getattr(args, d, None) for d in ("input", "image")) if isinstance(v, str)), None)
    out = getattr(args, "out", None)
    deep = src is not None and Path(src).is_file() and io.stored_bit_depth(src) == 16
    holds = out is not None and _files.WRITE_EXTENSIONS.get(Path(str(out)).suffix.lower(), 8) == 16
    args.bit_depth = 16 if deep and holds else 8


def check_writable(path: Path, args: argparse.Namespace) -> None:
    _files.encode(path, np.zeros((1, 1), np.float32), args.bit_depth)  # extension and bit depth
    transaction().reserve(path)


def preflight(args: argparse.Namespace, extra: Sequence[Path] = ()) -> None:
    """Fail before computing if the output, its sidecar or an ``extra`` file cannot be written."""
    out = Path(args.out)
    check_writable(out, args)
    transaction().reserve(io.sidecar_path(out))
    for path in extra:
        check_writable(path, args)


def stage(path: str | Path, data: bytes, args: argparse.Namespace, note: str | None = None) -> None:
    """Write ``data`` to ``path`` when the command has succeeded; ``note`` is printed then."""
    tx = transaction()
    tx.stage(Path(path), data)
    if not getattr(args, "quiet", False):
        tx.notes.append(note or f"wrote {path}")


def stage_image(path: str | Path, image: Any, args: argparse.Namespace, bit_depth: int | None = None) -> None:
    p = Path(path)
    stage(p, _files.encode(p, image, args.bit_depth if bit_depth is None else bit_depth), args)


def stage_result(
    path: str | Path,
    image: Any,
    args: argparse.Namespace,
    command: str,
    details: dict[str, Any] | None = None,
    quiet: bool = False,
) -> None:
    """An image and its sidecar, staged together (see :func:`phloem.io.write_result`)."""
    p = Path(path)
    side = io.sidecar_path(p)
    tx = transaction()
    tx.stage(p, _files.encode(p, image, args.bit_depth))
    tx.stage(side, sidecar(p, args, command, details))
    if not (quiet or args.quiet):
        tx.notes.append(f"wrote {p} and {side}")


#: ``dest``s of the arguments that name files or folders a command reads: their SHA-256 goes
#: into the sidecar, and ``phloem replay`` refuses to run on changed ones.
INPUT_ARGUMENTS = ("input", "image", "mask", "strokes", "skeleton", "target", "library", "like", "trunk_model",
                   "height_map", "labels_in", "labels_out", "valid", "guide", "background", "leaves", "scribbles",
                   "model")  # fmt: skip
#: ``dest``s of the arguments that name outputs (``out`` or ``out_dir`` is the main one).
OUTPUT_ARGUMENTS = ("out", "out_dir", "sheet", "cylinder_preview", "fragment_map", "overlay", "preview", "histograms",
                    "model_out")  # fmt: skip
_KEYWORDS = ("auto", "none")  # values of file arguments that name no file (--valid auto)


def input_files(args: argparse.Namespace) -> list[str]:
    """The files and folders the command reads, as given, in argument order."""
    found: list[str] = []
    for dest in INPUT_ARGUMENTS:
        value = getattr(args, dest, None)
        for v in value if isinstance(value, list) else [value]:
            if isinstance(v, str) and v not in _KEYWORDS and v not in found and Path(v).exists():
                found.append(v)
    return found


def threads_used(args: argparse.Namespace) -> int:
    """The worker thread count of the run: ``--threads``, else the default pool's."""
    from .. import _core

    return int(args.threads) if getattr(args, "threads", None) is not None else _core.default_threads()


def sidecar(
    path: Path,
    args: argparse.Namespace,
    command: str,
    details: dict[str, Any] | None = None,
    parameters: dict[str, Any] | None = None,
) -> bytes:
    """The sidecar of output ``path``: ``params(args)`` (or ``parameters``), the seed, the thread
    count, the inputs' hashes and ``details`` (what the run found; ``docs/replay.md``)."""
    if getattr(args, "_input_digests", None) is None:  # once per run, not once per output
        args._input_digests = {f: io.file_digest(f) for f in input_files(args)}
    return io._sidecar(
        path, command, params(args) if parameters is None else parameters, getattr(args, "seed", None), str,
        threads=threads_used(args), inputs=args._input_digests, details=details,
    )  # fmt: skip


#: What a sidecar's ``parameters`` leave out: argparse's own entries, and the options about this
#: machine or the terminal, or recorded apart (seed, threads).
NOT_PARAMETERS = ("help", "func", "command", "action", "quiet", "force", "threads", "seed", "max_pixels", "max_memory",
                  "from_json", "library_cache", "interrupted")  # fmt: skip


def params(args: argparse.Namespace, skip: Sequence[str] = ()) -> dict[str, Any]:
    """Every option of the command with the value it ran with: what ``phloem replay`` passes back.

    Options about this machine or the terminal (threads, memory and pixel limits, the bar) and
    the seed, which the sidecar holds apart, are left out. A command that resolves a default
    (``--levels`` from the exemplar, ``--kind auto``) sets the resolved value on ``args`` first.
    """
    drop = {*NOT_PARAMETERS, *skip}
    return {
        k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(args).items() if k not in drop and k[:1] != "_"
    }


def run(label: str, args: argparse.Namespace, work: Callable[[Any], T]) -> T:
    bar = Bar(label, enabled=not args.quiet)
    t0 = time.perf_counter()
    try:
        out = work(bar)
    finally:
        bar.close()
    if not args.quiet:
        print(f"{label}: {time.perf_counter() - t0:.2f} s", file=sys.stderr)
    return out


def save(args: argparse.Namespace, command: str, image: np.ndarray, **details: Any) -> None:
    """OUT and its sidecar; ``details`` are what the run found (recorded, not replayed)."""
    stage_result(args.out, image, args, command, details)


#: What :func:`kept` keeps: per kind, the last (key, value) this process made.
_KEPT: dict[str, tuple[tuple[Any, ...], Any]] = {}


def stamp(files: Sequence[Path], options: tuple[Any, ...]) -> tuple[Any, ...]:
    """A key for :func:`recall`: ``files`` by path, size and modification time, and ``options``."""
    return (tuple((str(f.absolute()), f.stat().st_size, f.stat().st_mtime_ns) for f in files), options)


def recall(kind: str, key: tuple[Any, ...]) -> Any:
    """What :func:`remember` kept last for ``kind`` under ``key`` in this process, or None."""
    last = _KEPT.get(kind)
    return last[1] if last is not None and last[0] == key else None


def remember(kind: str, key: tuple[Any, ...], value: Any) -> None:
    """Keep ``value`` as the last ``kind`` made from ``key`` (one per kind)."""
    _KEPT[kind] = (key, value)


def kept(kind: str, files: Sequence[Path], options: tuple[Any, ...], make: Callable[[], T]) -> T:
    """``make()``, or what it gave last time in this process for the same ``files`` (by path,
    size and modification time) and ``options``. A batch worker runs many items of one model;
    the commands never change what they read, so sharing it is safe."""
    key = stamp(files, options)
    value: T | None = recall(kind, key)
    if value is None:
        value = make()
        remember(kind, key, value)
    return value
