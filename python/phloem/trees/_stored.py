"""The trees of a saved library, each read from its ``trees.npz`` on first use.

A variation combines two exemplars of hundreds, so a process that makes a few trees from a
prepared library should not inflate all of them first (docs/pipelines/trees.md). The archive
stays open; a tree's arrays are read and checked against the library's first tree when it is
first asked for, then kept.
"""

from __future__ import annotations

import threading
import zipfile
import zlib
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, overload

import numpy as np

from .preprocessing import Tree

#: The array fields of :class:`Tree` that :meth:`Library.save` stores per tree.
TREE_ARRAYS = ("image", "trunk", "contour", "resampled", "simplified", "outline")

_UNREADABLE = (OSError, KeyError, IndexError, ValueError, zipfile.BadZipFile, EOFError, zlib.error)


class StoredTrees(Sequence[Tree]):
    """``n`` trees in the archive ``path`` (written by ``Library.files``), read one at a time.

    Raises ``ValueError`` naming ``path`` when the archive or the first tree cannot be read,
    and, on first use, when a later tree cannot be read or does not match the first.
    """

    def __init__(self, path: Path, n: int, split: tuple[int, int, int]) -> None:
        self.path = path
        self._split = split
        self._lock = threading.Lock()
        try:
            self._zip = zipfile.ZipFile(path)
        except _UNREADABLE as e:
            raise self._error(e) from None
        try:
            names = set(self._zip.namelist())
            wanted = {f"{a}_{i}.npy" for i in range(n) for a in TREE_ARRAYS} | {"pins.npy", "dilation.npy"}
            if not wanted <= names:
                raise KeyError(sorted(wanted - names)[0])
            self._pins = self._array("pins")
            self._dilation = self._array("dilation")
            if self._pins.shape != (n, 3) or self._dilation.shape != (n,):
                raise ValueError("pins or dilation of the wrong shape")
            self._trees: list[Tree | None] = [None] * n
            self._trees[0] = self._read(0)
        except _UNREADABLE as e:
            self._zip.close()
            raise self._error(e) from None

    def _error(self, e: BaseException) -> ValueError:
        return ValueError(f"path: {self.path} cannot be read as a prepared tree library ({type(e).__name__})")

    def _array(self, name: str) -> np.ndarray:
        with self._zip.open(f"{name}.npy") as f:
            out: np.ndarray = np.lib.format.read_array(f, allow_pickle=False)
        return out

    def _read(self, i: int) -> Tree:
        t = Tree(
            **{a: self._array(f"{a}_{i}") for a in TREE_ARRAYS},
            pins=(int(self._pins[i, 0]), int(self._pins[i, 1]), int(self._pins[i, 2])),
            split=self._split,
            dilation=int(self._dilation[i]),
        )
        first = self._trees[0] if i else None
        if first is not None and (t.image.shape != first.image.shape or len(t.simplified) != len(first.simplified)):
            raise ValueError(f"tree {i} was prepared with another size or m than tree 0")
        return t

    def __len__(self) -> int:
        return len(self._trees)

    @overload
    def __getitem__(self, i: int) -> Tree: ...
    @overload
    def __getitem__(self, i: slice) -> list[Tree]: ...
    def __getitem__(self, i: int | slice) -> Tree | list[Tree]:
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        k = range(len(self))[i]  # IndexError, negative indices
        t = self._trees[k]
        if t is None:
            with self._lock:
                t = self._trees[k]
                if t is None:
                    try:
                        t = self._read(k)
                    except _UNREADABLE as e:
                        raise ValueError(
                            f"path: {self.path} cannot be read as a prepared tree library "
                            f"(tree {k}: {type(e).__name__}); delete it to prepare the library again"
                        ) from None
                    self._trees[k] = t
        return t

    def __iter__(self) -> Iterator[Tree]:
        return (self[k] for k in range(len(self)))

    def __reduce__(self) -> tuple[Any, ...]:
        # an open archive does not pickle: a pickled library carries its trees
        return (list, (list(self),))
