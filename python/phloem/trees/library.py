"""The library ``L`` of preprocessed exemplars, from images, a folder or an atlas (Argudo et al. 2017 §3)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from .. import _memory, io
from .._api import warn_deprecated
from .._validate import check_int
from .atlas import split_atlas
from .classifier import TrunkClassifier
from .preprocessing import Tree, prepare

__all__ = ["Library"]


@dataclass
class Library:
    """A library of preprocessed tree exemplars (paper §3: the library ``L``).

    Build one with :meth:`from_images` or :meth:`load`; all trees share one size and
    one contour split, so their contours can be combined.

    Attributes
    ----------
    trees : list of Tree
    names : list of str
        One name per tree (file name, with ``[i]`` for the i-th tree of an atlas).
    """

    trees: list[Tree]
    names: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
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
        trees_: list[Tree] = []
        names: list[str] = []
        side = check_int(size, "size", 2)
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
