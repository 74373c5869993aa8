"""Shared plumbing of the fuzz targets: optional atheris, instrumentation, one temp file per process.

The targets import this module by name (``fuzz/`` is put on ``sys.path`` by running a target as
a script, and by ``tests/test_fuzz_corpus.py``), so atheris stays optional: without it the
targets still import and their ``TestOneInput`` runs once per input, which is how the committed
corpus doubles as a regression suite in CI.
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import os
import shutil
import sys
import tempfile
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

try:
    import atheris
except ImportError:  # the corpus test runs without it
    atheris = None

_DIR = Path(tempfile.mkdtemp(prefix="phloem-fuzz-"))
atexit.register(shutil.rmtree, _DIR, True)


def target(test_one_input: Callable[[bytes], None]) -> Callable[[bytes], None]:
    """Decorate a ``TestOneInput``: RuntimeWarnings become errors while it runs.

    numpy's "invalid value encountered in cast" and Pillow's DecompressionBombWarning are
    RuntimeWarnings: a parser that lets one through has read something it did not check. The
    filter is set per call, not at import, so that the corpus test leaves pytest's filters alone.
    """

    @functools.wraps(test_one_input)
    def wrapped(data: bytes) -> None:
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            test_one_input(data)

    return wrapped


@contextlib.contextmanager
def instrumented() -> Iterator[None]:
    """Instrument the imports inside for coverage when a target runs under atheris; a no-op otherwise."""
    if atheris is None or not Path(sys.argv[0]).name.startswith("fuzz_"):  # not under the fuzzer
        yield
    else:
        with atheris.instrument_imports(include=["phloem", "PIL", "tifffile", "json"]):
            yield


def temp_file(data: bytes, suffix: str) -> Path:
    """``data`` written to this process's scratch file with the given name ending."""
    path = _DIR / f"input{suffix}"
    path.write_bytes(data)
    return path


def json_format(data: bytes, cls: Any) -> Any:
    """``data`` through ``cls.load`` (as a file) and ``cls.from_json`` (as UTF-8 text), for one of
    phloem's JSON formats (``_json.JsonFile``): they must agree on whether it is a file of the
    format, and what loads must survive ``to_json`` → ``from_json`` unchanged. The loaded
    value, or None."""
    try:
        loaded = cls.load(temp_file(data, ".json"))
    except cls.error:
        loaded = None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = None
    if text is not None:
        try:
            parsed = cls.from_json(text)
        except cls.error:
            parsed = None
        assert (parsed is None) == (loaded is None), "load and from_json disagree"
    if loaded is not None:
        assert cls.from_json(loaded.to_json()) == loaded, "to_json/from_json round trip changed the value"
    return loaded


def signature(exc: BaseException) -> str:
    """``Type@file:line`` of the frame that raised ``exc``: what tells one crash from another."""
    tb = exc.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    where = f"{Path(tb.tb_frame.f_code.co_filename).name}:{tb.tb_lineno}" if tb is not None else "?"
    return f"{type(exc).__name__}@{where}"


def fuzz(test_one_input: Callable[[bytes], Any]) -> None:
    """Run ``test_one_input`` under libFuzzer with the command line's options (``-max_total_time`` ...).

    libFuzzer stops at the first crash, and its fork mode does not run atheris targets, so
    ``PHLOEM_FUZZ_KNOWN`` (comma-separated :func:`signature` strings, printed with each crash)
    lets a campaign go on past crashes already written up. Never set in tests.
    """
    if atheris is None:
        sys.exit("fuzz: atheris is not installed (pip install 'phloem[fuzz]')")
    known = {s for s in os.environ.get("PHLOEM_FUZZ_KNOWN", "").split(",") if s}

    def one(data: bytes) -> None:
        try:
            test_one_input(data)
        except BaseException as exc:
            sig = signature(exc)
            if sig in known:
                return
            print(f"\nfuzz crash signature: {sig}", file=sys.stderr)
            raise

    atheris.Setup(sys.argv, one)
    atheris.Fuzz()
