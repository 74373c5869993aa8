"""Completing regions of a leaf from the rest of it: the analysis' peels and its hole fills.

A hole is background enclosed by the leaf (insect damage, a punched hole); a bite out of the
margin is not enclosed and stays. Synthesis builds each new leaf on one exemplar's background
layer, so a hole left there would be repeated, in the same place, in every new leaf drawn on
it: the analysis completes the holes of the backgrounds unless asked to keep them.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Final

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage  # type: ignore[import-untyped]

from ..texture.complete import complete

F32 = NDArray[np.float32]
#: The completion pyramid of a fill. ``"auto"`` also runs the strict pyramid, which only wins on
#: fine periodic structure out of phase; on leaf blades it never did, so it cost a fifth of
#: every peel for the same fill (docs/pipelines/leaves/analysis.md).
FILL_PYRAMID: Final = "interpolate"
#: Width in px of the ring around a hole that is filled with it.
RIM = 3


def fill_region(
    image: F32,
    region: NDArray[np.bool_],
    *,
    seed: int,
    threads: int | None,
    check: Callable[[], None] | None = None,
    opaque: bool = False,
) -> F32:
    """The RGBA ``image`` with the colours of ``region`` completed from the leaf pixels outside
    it; alpha kept, or set to 1 on ``region`` if ``opaque``. ``check`` runs after every
    completion iteration (the analysis' way to stop a worker)."""
    source = (image[..., 3] > 0.5) & ~region
    progress = None if check is None else (lambda done, total: check())
    rgb = complete(
        image[..., :3], region, source_mask=source, pyramid=FILL_PYRAMID, seed=seed, threads=threads, progress=progress
    )
    alpha = np.where(region, np.float32(1.0), image[..., 3]) if opaque else image[..., 3]
    return np.ascontiguousarray(np.concatenate([rgb, alpha[..., None]], axis=2), dtype=np.float32)


def interior_holes(leaf: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Pixels of the enclosed holes of the mask ``leaf`` (4-connected background not reaching
    the image border)."""
    return np.asarray(ndimage.binary_fill_holes(leaf) & ~leaf)


def fill_holes(image: F32, *, seed: int, threads: int | None, check: Callable[[], None] | None = None) -> F32:
    """The RGBA ``image`` with its interior holes completed and made opaque; the image itself
    (not a copy) when it has none."""
    leaf = image[..., 3] > 0.5
    hole = interior_holes(leaf)
    if not hole.any():
        return image
    # The hole's edge on a scan mixes leaf and scanner white over a few pixels, opaque or not:
    # a ring of RIM px around it is filled too, so no pale outline stays where the hole was.
    region = ndimage.binary_dilation(hole, iterations=RIM) & (hole | leaf)
    return fill_region(image, region, seed=seed, threads=threads, check=check, opaque=True)
