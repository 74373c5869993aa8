"""The batch manifest, ``manifest.jsonl``: one JSON line per finished item (or failed attempt).

Each line records the item, its options and seed, the exact ``phloem`` arguments it ran, its
status, seconds, error and the SHA-256 of every file it wrote. A rerun reads the last line of
each item and skips the items whose files all exist with those hashes. Lines are appended and
synced one at a time, so a batch killed at any point leaves at worst one cut-off last line,
which reading ignores.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from ..io import sidecar_path

__all__ = ["MANIFEST", "Manifest", "file_hashes", "sha256"]

MANIFEST = "manifest.jsonl"


def sha256(path: str | os.PathLike[str]) -> str:
    """The hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def output_files(target: Path) -> list[Path]:
    """The files one item wrote: its ``--out`` file (or the files of an ``--out`` folder, such
    as a leaf model) and its sidecar, or the files of its ``--out-dir`` folder."""
    side = sidecar_path(target)
    found: list[Path] = []
    if target.is_dir():
        found += sorted(p for p in target.rglob("*") if p.is_file() and not p.name.startswith("."))
    elif target.is_file():
        found.append(target)
    if side.is_file():
        found.append(side)
    return found


def file_hashes(target: Path, root: Path) -> dict[str, str]:
    """``{path relative to root: sha256}`` of :func:`output_files`."""
    return {p.relative_to(root).as_posix(): sha256(p) for p in output_files(target)}


class Manifest:
    """``manifest.jsonl`` in an output folder: read the items' last records, append new ones."""

    def __init__(self, out_dir: str | os.PathLike[str]) -> None:
        self.root = Path(out_dir).absolute()
        self.path = self.root / MANIFEST

    def records(self) -> dict[str, dict[str, Any]]:
        """The last record of each item, by item name (a cut-off or foreign line is skipped)."""
        last: dict[str, dict[str, Any]] = {}
        try:
            lines = self.path.read_text(encoding="utf-8").splitlines()
        except FileNotFoundError:
            return last
        except (OSError, UnicodeDecodeError) as e:
            raise ValueError(f"out_dir: cannot read {self.path}: {e}") from None
        for line in lines:
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                continue  # the last line of a batch killed while writing it
            if isinstance(rec, dict) and isinstance(rec.get("item"), str):
                last[rec["item"]] = rec
        return last

    def verified(self, record: Mapping[str, Any] | None) -> bool:
        """Whether ``record`` is a success whose every file still exists with its hash."""
        if record is None or record.get("status") != "ok" or not isinstance(record.get("outputs"), dict):
            return False
        outputs: dict[str, Any] = record["outputs"]
        if not outputs:
            return False
        for rel, digest in outputs.items():
            p = self.root / rel
            try:
                if not p.is_file() or sha256(p) != digest:
                    return False
            except OSError:
                return False
        return True

    def append(self, records: Iterable[Mapping[str, Any]]) -> None:
        """Append records, one synced line each."""
        self.root.mkdir(parents=True, exist_ok=True)
        with open(self.path, "a+b") as f:
            # a batch killed mid-line left no newline: end that line, or the next would join it
            if f.tell() > 0:
                f.seek(-1, os.SEEK_END)
                if f.read(1) != b"\n":
                    f.write(b"\n")
            for rec in records:
                f.write((json.dumps(rec, sort_keys=True) + "\n").encode())
                f.flush()
                os.fsync(f.fileno())
