"""Interior holes of a leaf (insect damage, punched holes): found and completed.

A hole is background enclosed by the leaf (alpha ≤ 0.5 inside the leaf's filled outline); a
bite out of the margin is not enclosed and stays. Synthesis builds each new leaf on one
exemplar's background layer, so a hole left there would be repeated, in the same place, in
every new leaf drawn on it: the analysis completes the holes of the backgrounds unless asked
to keep them.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage  # type: ignore[import-untyped]

from ..texture.complete import complete

F32 = NDArray[np.float32]
#: Width in px of the ring around a hole that is filled with it.
RIM = 3


def interior_holes(alpha: NDArray[np.floating]) -> NDArray[np.bool_]:
    """Pixels of the enclosed holes of the leaf ``alpha > 0.5`` (4-connected background not
    reaching the image border)."""
    leaf = np.asarray(alpha) > 0.5
    return np.asarray(ndimage.binary_fill_holes(leaf) & ~leaf)


def fill_holes(image: F32, *, seed: int, threads: int | None, check: Callable[[], None] | None = None) -> F32:
    """The RGBA ``image`` with its interior holes completed from its leaf pixels and made opaque;
    the image itself (not a copy) when it has none. ``check`` runs after every completion
    iteration (the analysis' way to stop a worker)."""
    hole = interior_holes(image[..., 3])
    if not hole.any():
        return image
    leaf = image[..., 3] > 0.5
    # The hole's edge on a scan mixes leaf and scanner white over a few pixels, opaque or not:
    # a ring of RIM px around it is filled too, so no pale outline stays where the hole was.
    fill = ndimage.binary_dilation(hole, iterations=RIM) & (hole | leaf)
    progress = None if check is None else (lambda done, total: check())
    rgb = complete(image[..., :3], fill, source_mask=leaf & ~fill, seed=seed, threads=threads, progress=progress)
    alpha = np.where(fill, np.float32(1.0), image[..., 3])
    return np.ascontiguousarray(np.concatenate([rgb, alpha[..., None]], axis=2), dtype=np.float32)
