"""The project folder: every file the studio reads or writes is named relative to it and checked
here, so that no request can reach outside it (``..``, absolute names, symbolic links)."""

from __future__ import annotations

import os
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .. import _files, _memory, io

__all__ = ["IMAGE_SUFFIXES", "JSON_SUFFIXES", "PathError", "Project", "name_pattern"]

IMAGE_SUFFIXES = frozenset(io.IMAGE_SUFFIXES)
JSON_SUFFIXES = frozenset({".json"})
# One part of a relative name: no hidden files (.phloem-studio holds our temporaries), no
# separators, no characters a shell or a URL would need quoted.
_PART = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.\-]{0,127}")
_MAX_PARTS = 8


def name_pattern(suffixes: frozenset[str]) -> str:
    """The regular expression of a project name ending in one of ``suffixes``, for the API's
    description (the check itself is :meth:`Project.resolve`, which also follows links and takes
    the suffixes in any case; the pattern stays in the ECMA subset JSON Schema uses)."""
    part = _PART.pattern
    ends = "|".join(sorted(s[1:] for s in suffixes))
    return rf"^(?:{part}/){{0,{_MAX_PARTS - 1}}}{part}\.(?:{ends})$"


# A decoded image holds at most 4 float32 channels per pixel while it is checked and converted.
_BYTES_PER_PIXEL = 4 * 4 * 2


class PathError(ValueError):
    """A file name a request gave that names nothing inside the project folder."""


@dataclass(frozen=True)
class Project:
    """The folder the studio works in, with the limits its uploads are held to.

    Parameters
    ----------
    root : path-like
        An existing folder; it is resolved once, and every name is checked against it.
    max_pixels : int, optional
        Refuse images with more pixels than this (default :data:`phloem.io.DEFAULT_MAX_PIXELS`).
    max_upload_bytes : int, optional
        Refuse uploads larger than this many bytes (default 64 MiB).
    max_memory : int, optional
        Memory limit in bytes for decoding uploads and for jobs (default: 75% of the machine's).

    Examples
    --------
    >>> import tempfile
    >>> p = Project(tempfile.mkdtemp())
    >>> p.resolve("strokes/a.json").relative_to(p.root).as_posix()
    'strokes/a.json'
    >>> p.resolve("../etc/passwd")
    Traceback (most recent call last):
    ...
    phloem.studio.files.PathError: path: '../etc/passwd' is not a plain relative name (parts of letters, digits, '_', '.', '-'; no '..')
    """

    root: Path
    max_pixels: int = io.DEFAULT_MAX_PIXELS
    max_upload_bytes: int = 64 * 2**20
    max_memory: int | None = None

    def __post_init__(self) -> None:
        root = Path(self.root)
        if not root.is_dir():
            raise ValueError(f"project: {root} is not a folder")
        object.__setattr__(self, "root", root.resolve(strict=True))
        if int(self.max_pixels) < 1:
            raise ValueError(f"max_pixels: expected a positive pixel count, got {self.max_pixels}")
        if int(self.max_upload_bytes) < 1:
            raise ValueError(f"max_upload_bytes: expected a positive byte count, got {self.max_upload_bytes}")

    def resolve(self, name: str, *, suffixes: frozenset[str] | None = None, name_of: str = "path") -> Path:
        """The absolute path of ``name``, a relative name inside the project.

        Refuses (with :class:`PathError` naming ``name_of``) absolute names, ``..``, hidden
        parts, odd characters, a suffix not in ``suffixes``, and a name whose existing parts
        lead, through a symbolic link, outside the project folder.
        """
        parts = name.split("/") if isinstance(name, str) else []
        if not parts or len(parts) > _MAX_PARTS or not all(_PART.fullmatch(p) for p in parts):
            raise PathError(
                f"{name_of}: {name!r} is not a plain relative name (parts of letters, digits, '_', '.', '-'; no '..')"
            )
        path = self.root.joinpath(*parts)
        if suffixes is not None and path.suffix.lower() not in suffixes:
            raise PathError(f"{name_of}: {name!r} must end in one of {', '.join(sorted(suffixes))}")
        # resolve() follows every link that exists; a name that ends up elsewhere escaped.
        real = path.resolve(strict=False)
        if not real.is_relative_to(self.root):
            raise PathError(f"{name_of}: {name!r} leads outside the project folder")
        return path

    def existing(self, name: str, *, suffixes: frozenset[str] | None = None, name_of: str = "path") -> Path:
        """:meth:`resolve` for a file that must exist (``FileNotFoundError`` otherwise)."""
        path = self.resolve(name, suffixes=suffixes, name_of=name_of)
        if not path.is_file():
            raise FileNotFoundError(f"{name_of}: no file {name!r} in the project")
        return path

    def name(self, path: Path) -> str:
        """The project-relative name of ``path``, as requests write it."""
        return path.relative_to(self.root).as_posix()

    def files(self, *, limit: int = 2000) -> list[dict[str, Any]]:
        """The images and JSON files of the project (hidden folders and links left out), by name."""
        out: list[dict[str, Any]] = []
        for folder, dirs, names in os.walk(self.root):
            base = Path(folder)
            depth = len(base.relative_to(self.root).parts)
            dirs[:] = sorted(
                d for d in dirs if _PART.fullmatch(d) and not (base / d).is_symlink() and depth < _MAX_PARTS - 1
            )
            for n in sorted(names):
                p = base / n
                suffix = p.suffix.lower()
                if not _PART.fullmatch(n) or p.is_symlink() or suffix not in IMAGE_SUFFIXES | JSON_SUFFIXES:
                    continue
                kind = "image" if suffix in IMAGE_SUFFIXES else "json"
                out.append({"path": self.name(p), "kind": kind, "bytes": p.stat().st_size})
                if len(out) >= limit:
                    return out
        return out

    def read_image(self, name: str, *, name_of: str = "image") -> np.ndarray:
        """An image of the project, read with phloem's checks and the project's pixel limit."""
        path = self.existing(name, suffixes=IMAGE_SUFFIXES, name_of=name_of)
        h, w = io.image_size(path, max_pixels=self.max_pixels)
        _memory.check(h * w * _BYTES_PER_PIXEL, self.max_memory, name_of, f"{w}×{h} px")
        try:
            return io.read_image(path, max_pixels=self.max_pixels)
        except io.ImageReadError as e:
            raise io.ImageReadError(str(e).replace(f"path: {path}", f"{name_of}: {name}")) from None

    def check_image_bytes(self, data: bytes, suffix: str, name_of: str = "file") -> tuple[int, int]:
        """Check that ``data`` is an image phloem reads within the project's limits; its (height, width).

        The bytes are written to a hidden temporary in the project and read back with
        :func:`phloem.io.read_image`, the reader the CLI uses, so that every check it makes
        (format, corruption, truncation, pixel limit, NaN) applies to uploads too.
        """
        if len(data) > self.max_upload_bytes:
            raise ValueError(f"{name_of}: {len(data)} bytes, over the upload limit of {self.max_upload_bytes}")
        scratch = self.root / ".phloem-studio"
        if scratch.is_symlink() or (scratch.exists() and not scratch.is_dir()):  # it would take the bytes elsewhere
            raise PathError(f"{name_of}: {scratch} must be a plain folder of the studio's temporaries")
        scratch.mkdir(exist_ok=True)
        fd, tmp = tempfile.mkstemp(suffix=suffix, dir=scratch)
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(data)
            try:
                h, w = io.image_size(tmp, max_pixels=self.max_pixels)
                _memory.check(h * w * _BYTES_PER_PIXEL, self.max_memory, name_of, f"{w}×{h} px")
                img = io.read_image(tmp, max_pixels=self.max_pixels)
            except io.ImageReadError as e:
                raise io.ImageReadError(str(e).replace(f"path: {tmp}", f"{name_of}:")) from None
        finally:
            os.unlink(tmp)
        return int(img.shape[0]), int(img.shape[1])

    def write_bytes(self, name: str, data: bytes, *, overwrite: bool, name_of: str = "path") -> Path:
        """Write ``data`` to ``name`` atomically, making its folders; an existing file only with ``overwrite``."""
        path = self.resolve(name, name_of=name_of)
        path.parent.mkdir(parents=True, exist_ok=True)
        self.resolve(name, name_of=name_of)  # the folders just made may not be links, but check again
        try:
            _files.atomic_write(path, data, overwrite)
        except FileExistsError:
            raise FileExistsError(f"{name_of}: {name!r} already exists (pass overwrite=true to replace it)") from None
        return path
