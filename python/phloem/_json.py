"""The one reader of the JSON files phloem is given (skeletons, guides, trunk models).

:func:`read_json` turns every way a file can be wrong into one line that names the argument and
the file: too large, binary, not UTF-8, nested too deeply, a syntax error (with line and
column), ``NaN``/``Infinity`` literals. The nesting depth is measured before parsing, because
Python's parser would otherwise hit its recursion limit (``RecursionError``) on ``[[[[...``.
"""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path
from typing import Any, ClassVar, TypeVar

import numpy as np

__all__ = ["MAX_BYTES", "MAX_DEPTH", "JsonFile", "is_number", "parse_json", "read_json", "short_repr"]

MAX_BYTES = 256 * 1024 * 1024
# Our formats nest 4 deep at most; 64 leaves room for others while staying far below the
# recursion limit of json's decoder (and of anything walking the value afterwards).
MAX_DEPTH = 64

# A JSON string: its contents are blanked (same length) before the bracket and literal scans.
_STRING = re.compile(r'"(?:[^"\\\n]|\\.)*"', re.DOTALL)
_BAD_LITERAL = re.compile(r"-?\b(?:NaN|Infinity)\b")
_OPEN = np.frombuffer(b"[{", np.uint8)
_CLOSE = np.frombuffer(b"]}", np.uint8)
_CHUNK = 1 << 24


class _Overflow(ValueError):
    pass


def _finite(text: str) -> float:
    # json reads 1e999 as inf; a file cannot mean that.
    v = float(text)
    if not math.isfinite(v):
        raise _Overflow(text if len(text) <= 40 else text[:40] + "...")
    return v


def _where(text: str, pos: int) -> str:
    line = text.count("\n", 0, pos) + 1
    col = pos - (text.rfind("\n", 0, pos) + 1) + 1
    return f"line {line} column {col}"


def parse_json(text: str, name: str, source: str, *, error: type[ValueError] = ValueError) -> Any:
    """Parse ``text`` (the contents of the file ``source``, or ``""``) with the checks of :func:`read_json`."""
    blank = _STRING.sub(lambda m: '"' + " " * (len(m.group(0)) - 2) + '"', text)
    raw = blank.encode("utf-8")
    at = source + " " if source else ""
    # Depth by a running sum over the brackets, in chunks so that a large file needs no
    # array of its full length in int32.
    level = 0
    for start in range(0, len(raw), _CHUNK):
        codes = np.frombuffer(raw, np.uint8, min(_CHUNK, len(raw) - start), start)
        step = np.isin(codes, _OPEN).astype(np.int32) - np.isin(codes, _CLOSE)
        depth = level + np.cumsum(step)
        if depth.size and int(depth.max()) > MAX_DEPTH:
            pos = len(raw[: start + int(np.argmax(depth > MAX_DEPTH))].decode("utf-8", "replace"))
            raise error(f"{name}: {at}{_where(text, pos)}: nested more than {MAX_DEPTH} levels deep")
        level = int(depth[-1]) if depth.size else level
    bad = _BAD_LITERAL.search(blank)
    if bad is not None:
        raise error(f"{name}: {at}{_where(text, bad.start())}: {bad.group(0)} is not a JSON number")
    try:
        return json.loads(text, parse_float=_finite)
    except json.JSONDecodeError as exc:
        raise error(f"{name}: {at}line {exc.lineno} column {exc.colno}: {exc.msg}") from None
    except _Overflow as exc:
        raise error(f"{name}: {at}{exc.args[0]} is too large for a number") from None
    except ValueError:  # an integer of thousands of digits (Python's int-string limit)
        raise error(f"{name}: {at}holds an integer with too many digits") from None
    except RecursionError:  # pragma: no cover - the depth scan above refuses such text first
        raise error(f"{name}: {at}nested too deeply") from None


def read_json(
    path: str | os.PathLike[str],
    name: str,
    *,
    max_bytes: int = MAX_BYTES,
    error: type[ValueError] = ValueError,
) -> Any:
    """The parsed contents of a JSON file, or ``error`` with one line naming ``name`` and the file.

    Parameters
    ----------
    path : path-like
        The file.
    name : str
        The argument it came from (``"skeleton"``, ``"trunk_model"``); the message's prefix.
    max_bytes : int, optional
        Refuse larger files before reading them (default 256 MiB).
    error : type, optional
        The exception class raised (a :class:`ValueError` subclass).
    """
    p = Path(path)
    try:
        size = p.stat().st_size
        if p.is_dir():
            raise error(f"{name}: {p} is a folder, not a JSON file")
        if size > max_bytes:
            raise error(f"{name}: {p} is {size} bytes, larger than the limit of {max_bytes} for a JSON file")
        with p.open("rb") as f:
            data = f.read(max_bytes + 1)
    except FileNotFoundError:
        raise error(f"{name}: {p} does not exist") from None
    except OSError as exc:
        raise error(f"{name}: cannot read {p} ({exc.strerror or exc})") from None
    if len(data) > max_bytes:
        raise error(f"{name}: {p} is larger than the limit of {max_bytes} bytes for a JSON file")
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    nul = data.find(b"\x00")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        at = exc.start if nul < 0 else min(nul, exc.start)
        raise error(f"{name}: {p} is not a JSON file (binary data at byte {at})") from None
    if nul >= 0:
        raise error(f"{name}: {p} is not a JSON file (binary data at byte {nul})")
    return parse_json(text, name, str(p), error=error)


def short_repr(v: Any) -> str:
    """``repr(v)``, cut to 40 characters: a file's value as an error message quotes it."""
    text = repr(v)
    return text if len(text) <= 40 else text[:37] + "..."


def is_number(v: Any) -> bool:
    """A JSON number (``true`` / ``false`` are not, though Python counts them as ints)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool)


_F = TypeVar("_F", bound="JsonFile")


class JsonFile:
    """``from_json``, ``load`` and ``save`` for a class of one of phloem's JSON file formats.

    The class gives ``from_dict`` (raising its ``error`` with a one-line message) and
    ``to_json``; ``load`` adds the file to every message, ``save`` writes atomically and never
    over an existing file unless asked (skeletons, stroke sets).
    """

    error: ClassVar[type[ValueError]] = ValueError
    #: The file's ``"format"`` and ``"version"``, and what one is called in messages.
    file_format: ClassVar[str] = ""
    file_version: ClassVar[int] = 1
    what: ClassVar[str] = ""

    @classmethod
    def from_dict(cls: type[_F], data: Any) -> _F:  # pragma: no cover - every format defines it
        raise NotImplementedError

    def to_dict(self) -> dict[str, Any]:  # pragma: no cover - every format defines it
        raise NotImplementedError

    def to_json(self) -> str:
        """The file's contents as a JSON string."""
        return json.dumps(self.to_dict())

    @classmethod
    def check_header(cls, data: Any) -> dict[str, Any]:
        """``data`` if it is an object whose ``format`` and ``version`` (when present) are the class's."""
        if not isinstance(data, dict):
            raise cls.error(f"a {cls.what} must be a JSON object, got {type(data).__name__}")
        for key, want in (("format", cls.file_format), ("version", cls.file_version)):
            got = data.get(key, want)
            if got != want or isinstance(got, bool):
                text = short_repr(got)
                if key == "format":
                    raise cls.error(f"format must be {want!r}, got {text}")
                raise cls.error(f"unsupported {cls.what} version {text} (this phloem reads {want})")
        return data

    @classmethod
    def from_json(cls: type[_F], text: str) -> _F:
        """Parse the JSON file format."""
        if not isinstance(text, str):
            raise TypeError(f"text: expected a str, got {type(text).__name__}")
        return cls.from_dict(parse_json(text, "text", "", error=cls.error))

    @classmethod
    def load(cls: type[_F], path: str | os.PathLike[str]) -> _F:
        """Read a file of the format; every error is one line that names the file."""
        data = read_json(path, "path", error=cls.error)
        try:
            return cls.from_dict(data)
        except cls.error as exc:
            raise cls.error(f"path: {path}: {exc}") from None

    def save(self, path: str | os.PathLike[str], *, overwrite: bool = False) -> None:
        """Write the file atomically; refuses to overwrite an existing file unless asked."""
        from ._files import atomic_write

        atomic_write(Path(path), self.to_json().encode("utf-8"), overwrite)
