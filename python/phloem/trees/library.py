"""The library ``L`` of preprocessed exemplars, from images, a folder or an atlas (Argudo et al. 2017 §3)."""

from __future__ import annotations

import hashlib
import json
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from .. import _files, _json, _memory, io
from .._api import warn_deprecated
from .._validate import check_int
from ._stored import TREE_ARRAYS, StoredTrees
from .atlas import split_atlas
from .classifier import TrunkClassifier
from .preprocessing import Tree, prepare

__all__ = ["Library"]

#: The ``format`` entry of ``library.json``; ``version`` changes when the folder's layout does.
LIBRARY_FORMAT = "phloem.trees.Library"
LIBRARY_VERSION = 1

# The last library Library.load(cache=...) returned in this process, with the signature (files'
# names, sizes and times; options) it was read for: a batch worker runs many items on one
# library and loads it once. One entry: a library can take gigabytes.
_loaded: dict[str, tuple[tuple[Any, ...], Library]] = {}


@dataclass
class Library:
    """A library of preprocessed tree exemplars (paper §3: the library ``L``).

    Build one with :meth:`from_images` or :meth:`load`; all trees share one size and
    one contour split, so their contours can be combined.

    Attributes
    ----------
    trees : sequence of Tree
        A list; for a library read from a folder (:meth:`load_prepared`, ``load(cache=)``) a
        sequence that reads each tree from the folder when it is first used.
    names : list of str
        One name per tree (file name, with ``[i]`` for the i-th tree of an atlas).
    """

    trees: Sequence[Tree]
    names: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        if isinstance(self.trees, StoredTrees):  # checked tree by tree as they are read
            self.names = list(self.names)
            if len(self.names) != len(self.trees):
                raise ValueError(f"names: expected {len(self.trees)} names, got {len(self.names)}")
            return
        self.trees = list(self.trees)
        if not self.trees:
            raise ValueError("trees: a library needs at least one tree")
        if not all(isinstance(t, Tree) for t in self.trees):
            raise TypeError("trees: expected phloem.trees.Tree objects (see phloem.trees.prepare)")
        self.names = list(self.names) or [f"tree{i}" for i in range(len(self.trees))]
        if len(self.names) != len(self.trees):
            raise ValueError(f"names: expected {len(self.trees)} names, got {len(self.names)}")
        first = self.trees[0]
        for name, t in zip(self.names, self.trees):
            if (
                t.image.shape != first.image.shape
                or t.split != first.split
                or len(t.simplified) != len(first.simplified)
            ):
                raise ValueError(f"trees: {name!r} was prepared with another size, split or m than {self.names[0]!r}")

    def __len__(self) -> int:
        return len(self.trees)

    def __getitem__(self, i: int) -> Tree:
        return self.trees[i]

    @property
    def size(self) -> int:
        """Side of the (square) normalised images."""
        return int(self.trees[0].image.shape[0])

    @classmethod
    def from_images(
        cls,
        images: Sequence[Any],
        *,
        names: Sequence[str] | None = None,
        size: int = 1024,
        alpha_threshold: float = 0.5,
        classifier: TrunkClassifier | None = None,
        progress: Any = None,
        max_memory: int | None = None,
    ) -> Library:
        """Preprocess RGBA images (one tree each) into a library.

        Parameters
        ----------
        images : sequence of (M, N, 4) ndarray
        names : sequence of str, optional
        size, alpha_threshold : optional
            See :func:`normalize`.
        classifier : TrunkClassifier, optional
            Crown/trunk segmentation by this classifier instead of :func:`segment`.
        progress : callable, optional
            ``progress(done, total)`` after each tree.
        max_memory : int, optional
            Refuse (:class:`phloem.MemoryLimitError`) before preparing a tree that would take the
            estimated memory of the library over this many bytes (default None: 75% of the machine's).

        Examples
        --------
        >>> import numpy as np, phloem
        >>> img = np.zeros((120, 80, 4), np.float32)
        >>> img[10:70, 10:70] = 1.0; img[70:110, 35:45] = 1.0
        >>> lib = phloem.trees.Library.from_images([img, img[:, ::-1]], size=128)
        >>> len(lib), lib.size, lib.names
        (2, 128, ['tree0', 'tree1'])
        """
        imgs = list(images)
        out = []
        side = check_int(size, "size", 2)
        for i, img in enumerate(imgs):
            _memory.check(_memory.trees(side, i + 1), max_memory, "size", f"{i + 1} trees of {side}×{side}")
            try:
                out.append(prepare(img, size=size, alpha_threshold=alpha_threshold, classifier=classifier))
            except ValueError as exc:
                label = names[i] if names is not None and i < len(names) else f"images[{i}]"
                raise ValueError(f"{label}: {exc}") from None
            if progress is not None:
                progress(i + 1, len(imgs))
        return cls(out, list(names) if names is not None else [])

    # -- prepared libraries -------------------------------------------------------------------
    def files(self, *, key: str = "") -> dict[str, bytes]:
        """The folder :meth:`save` writes, as file name → bytes: ``library.json`` (names, size,
        split, ``key``) and ``trees.npz`` (every array of every :class:`Tree`, lossless)."""
        from .. import __version__

        meta = {
            "format": LIBRARY_FORMAT,
            "version": LIBRARY_VERSION,
            "phloem_version": __version__,
            "key": key,
            "names": list(self.names),
            "size": self.size,
            "split": list(self.trees[0].split),
            "n_trees": len(self),
        }
        arrays: dict[str, Any] = {
            "pins": np.array([t.pins for t in self.trees], np.int64),
            "dilation": np.array([t.dilation for t in self.trees], np.int64),
        }
        for i, t in enumerate(self.trees):
            for name in TREE_ARRAYS:
                arrays[f"{name}_{i}"] = getattr(t, name)
        return {"library.json": (json.dumps(meta, indent=1) + "\n").encode(), "trees.npz": _files.npz_bytes(arrays)}

    def save(self, path: str | os.PathLike[str], *, overwrite: bool = False, key: str = "") -> None:
        """Write the prepared library to the folder ``path`` (``library.json``, ``trees.npz``),
        so that :meth:`load_prepared` reads it back without preparing any tree again.

        Both files appear together or neither does; an existing file is replaced only with
        ``overwrite``. ``key`` is stored for :meth:`load_prepared` to check (``load(cache=)``
        stores the hash of the inputs and options there).

        Examples
        --------
        >>> import tempfile, numpy as np, phloem
        >>> img = np.zeros((120, 80, 4), np.float32)
        >>> img[10:70, 10:70] = 1.0; img[70:110, 35:45] = 1.0
        >>> lib = phloem.trees.Library.from_images([img, img[:, ::-1]], size=128)
        >>> with tempfile.TemporaryDirectory() as d:
        ...     lib.save(d, overwrite=True)
        ...     back = phloem.trees.Library.load_prepared(d)
        >>> back.names == lib.names and all(np.array_equal(a.image, b.image) for a, b in zip(back, lib))
        True
        """
        _files.write_folder(path, self.files(key=key), overwrite)

    @classmethod
    def load_prepared(cls, path: str | os.PathLike[str], *, key: str | None = None) -> Library:
        """Read a library written by :meth:`save`.

        Parameters
        ----------
        path : path-like
            The folder.
        key : str, optional
            Refuse (``ValueError``) a folder saved with another key: a cache made from other
            images or options.

        Raises
        ------
        ValueError
            One line naming the file, if the folder is missing, foreign, damaged or stale.
            The trees are read when first used (a variation reads its few exemplars, not the
            library), so a tree damaged after the first raises then.
        """
        folder = Path(path)
        if not folder.is_dir():
            raise ValueError(f"path: {folder} is not a folder written by Library.save")
        meta = _json.read_json(folder / "library.json", "path")
        if not isinstance(meta, dict) or meta.get("format") != LIBRARY_FORMAT:
            raise ValueError(f"path: {folder / 'library.json'} is not a phloem tree library")
        if meta.get("version") != LIBRARY_VERSION:
            raise ValueError(
                f"path: {folder / 'library.json'} has library version {meta.get('version')!r}; "
                f"this phloem reads {LIBRARY_VERSION}"
            )
        if key is not None and meta.get("key") != key:
            raise ValueError(f"path: {folder} was prepared from other images or options (stale)")
        try:
            n = int(meta["n_trees"])
            names = [str(v) for v in meta["names"]]
            a, b, c = (int(v) for v in meta["split"])
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"path: {folder / 'library.json'} lacks a field or has one of the wrong type") from None
        return cls(StoredTrees(folder / "trees.npz", n, (a, b, c)), names)

    @classmethod
    def load(
        cls,
        path: str | os.PathLike[str],
        *,
        atlas: Literal["auto", "yes", "no"] = "auto",
        size: int = 1024,
        alpha_threshold: float = 0.5,
        skip_bad: bool = False,
        classifier: TrunkClassifier | None = None,
        max_pixels: int = io.DEFAULT_MAX_PIXELS,
        progress: Any = None,
        max_memory: int | None = None,
        cache: str | os.PathLike[str] | None = None,
    ) -> Library:
        """Read a folder of PNG/TIFF/WebP images (sorted by name), or one image, into a library.

        Parameters
        ----------
        path : path-like
            A folder, or one image (typically an atlas of several trees).
        atlas : {"auto", "yes", "no"}, optional
            ``"yes"``: every image is an atlas of several trees (:func:`split_atlas`);
            ``"no"``: one tree per image; ``"auto"`` (default): split every image and keep
            all its pieces (an image of one tree gives one piece). ``None``, ``True`` and
            ``False``, the old spellings of these, still work (deprecated).
        size, alpha_threshold : optional
            See :func:`normalize`.
        skip_bad : bool, optional
            Skip images that cannot be used (no alpha, fully transparent, no usable contour)
            instead of raising.
        classifier : TrunkClassifier, optional
            Crown/trunk segmentation by this classifier instead of :func:`segment`.
        max_pixels : int, optional
            Refuse images with more pixels (see :func:`phloem.io.read_image`).
        progress : callable, optional
            ``progress(done, total)`` after each image.
        max_memory : int, optional
            Refuse (:class:`phloem.MemoryLimitError`) before preparing a tree that would take the
            estimated memory of the library over this many bytes (default None: 75% of the machine's).
        cache : path-like, optional
            A folder for the prepared library (:meth:`save`), one entry per source and options:
            if it holds one made from the same image bytes, options and phloem version (a
            SHA-256 of them all), it is read instead of preparing every tree again; if not
            (missing, or stale: an image or an option changed), the library is prepared and
            saved there. In one process the last library is also kept in memory.

        Raises
        ------
        ValueError
            If an image cannot be used (unless ``skip_bad``) or no tree is found.
        """
        if atlas is None or isinstance(atlas, bool):
            new = {None: "auto", True: "yes", False: "no"}[atlas]
            warn_deprecated(f"atlas={atlas} is deprecated and goes in the next release; use {new!r}")
            atlas = new
        if atlas not in ("auto", "yes", "no"):
            raise ValueError(f"atlas: expected 'auto', 'yes' or 'no', got {atlas!r}")
        folder = Path(path)
        if folder.is_dir():
            # what read_image reads, less JPEG: it has no alpha channel, and trees need one
            suffixes = set(io.IMAGE_SUFFIXES) - {".jpg", ".jpeg"}
            files = sorted(p for p in folder.iterdir() if p.suffix.lower() in suffixes)
            if not files:
                raise ValueError(f"path: {folder} has no PNG, TIFF or WebP images")
        elif folder.is_file():
            files = [folder]
        else:
            raise ValueError(f"path: {folder} does not exist")
        side = check_int(size, "size", 2)
        options = {"atlas": atlas, "size": side, "alpha_threshold": float(alpha_threshold), "skip_bad": bool(skip_bad),
                   "max_pixels": int(max_pixels), "classifier": None if classifier is None else classifier.to_dict()}  # fmt: skip
        if cache is not None:
            lib = cls._cached(folder, files, options, Path(cache))
            if lib is None:
                lib = cls._prepare_files(files, folder, atlas, side, alpha_threshold, skip_bad, classifier, max_pixels,
                                         progress, max_memory)  # fmt: skip
                lib._store(folder, files, options, Path(cache))
            elif progress is not None:
                progress(len(files), len(files))
            _memory.check(_memory.trees(side, len(lib)), max_memory, "size", f"{len(lib)} trees of {side}×{side}")
            return lib
        return cls._prepare_files(files, folder, atlas, side, alpha_threshold, skip_bad, classifier, max_pixels,
                                  progress, max_memory)  # fmt: skip

    @staticmethod
    def _signature(files: Sequence[Path], options: dict[str, Any]) -> tuple[Any, ...]:
        stats = [(str(f.absolute()), f.stat().st_size, f.stat().st_mtime_ns) for f in files]
        return (json.dumps(options, sort_keys=True), *stats)

    @staticmethod
    def _key(files: Sequence[Path], options: dict[str, Any]) -> str:
        """SHA-256 of the images' names and bytes, the options and the phloem version."""
        from .. import __version__

        h = hashlib.sha256(json.dumps({"options": options, "phloem": __version__, "format": LIBRARY_VERSION},
                                      sort_keys=True).encode())  # fmt: skip
        for f in files:
            h.update(f.name.encode() + b"\0")
            h.update(hashlib.sha256(f.read_bytes()).digest())
        return h.hexdigest()

    @staticmethod
    def _entry(folder: Path, options: dict[str, Any], cache: Path) -> Path:
        """The cache entry of a source and its options: one per pair, so a stale one is replaced."""
        where = hashlib.sha256(json.dumps([str(folder.absolute()), options], sort_keys=True).encode()).hexdigest()
        return cache / f"{re.sub(r'[^A-Za-z0-9._-]+', '_', folder.name) or 'library'}-{where[:12]}"

    @classmethod
    def _cached(cls, folder: Path, files: Sequence[Path], options: dict[str, Any], cache: Path) -> Library | None:
        entry = cls._entry(folder, options, cache)
        signature = cls._signature(files, options)
        kept = _loaded.get(str(entry))
        if kept is not None and kept[0] == signature:
            return kept[1]
        try:
            lib = cls.load_prepared(entry, key=cls._key(files, options))
        except ValueError:  # missing, stale or damaged: prepare again
            return None
        _loaded.clear()
        _loaded[str(entry)] = (signature, lib)
        return lib

    def _store(self, folder: Path, files: Sequence[Path], options: dict[str, Any], cache: Path) -> None:
        entry = self._entry(folder, options, cache)
        if cache.exists() and not cache.is_dir():
            raise ValueError(f"cache: {cache} exists and is not a folder")
        cache.mkdir(parents=True, exist_ok=True)
        self.save(entry, overwrite=True, key=self._key(files, options))
        _loaded.clear()
        _loaded[str(entry)] = (self._signature(files, options), self)

    @classmethod
    def _prepare_files(
        cls,
        files: Sequence[Path],
        folder: Path,
        atlas: str,
        side: int,
        alpha_threshold: float,
        skip_bad: bool,
        classifier: TrunkClassifier | None,
        max_pixels: int,
        progress: Any,
        max_memory: int | None,
    ) -> Library:
        size = side
        trees_: list[Tree] = []
        names: list[str] = []
        for k, f in enumerate(files):
            try:
                img = io.read_image(f, max_pixels=max_pixels)
                if img.ndim != 3 or img.shape[2] != 4:
                    raise ValueError("expected an RGBA image (trees need an alpha channel)")
                pieces = [img] if atlas == "no" else split_atlas(img, alpha_threshold=alpha_threshold)
                for i, piece in enumerate(pieces):
                    n = len(trees_) + 1
                    _memory.check(_memory.trees(side, n), max_memory, "size", f"{n} trees of {side}×{side}")
                    trees_.append(prepare(piece, size=size, alpha_threshold=alpha_threshold, classifier=classifier))
                    names.append(f.name if len(pieces) == 1 else f"{f.name}[{i}]")
            except _memory.MemoryLimitError:
                raise
            except ValueError as exc:
                if not skip_bad:
                    raise ValueError(f"{f}: {exc}") from None
            if progress is not None:
                progress(k + 1, len(files))
        if not trees_:
            raise ValueError(f"path: no usable tree in {folder}")
        return cls(trees_, names)
