"""Measures of result quality that the papers use, so tests and users can score an output.

So far: patch coherence to an exemplar (how well every patch of an output is explained by some
patch of the exemplar — the quantity texture optimisation minimises, Kwatra et al. 2005, Eq. 1).
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from . import patch as _patch
from ._validate import as_image, as_mask, check_patch_size

__all__ = ["patch_coherence", "coherence_map"]


def coherence_map(
    image: Any,
    exemplar: Any,
    *,
    patch_size: int = 7,
    method: Literal["patchmatch", "exact"] = "patchmatch",
    mask: Any = None,
    seed: int = 0,
    threads: int | None = None,
) -> NDArray[np.float32]:
    """Per-pixel distance of each ``image`` patch to its nearest ``exemplar`` patch.

    Distances are mean squared differences per value (the patch SSD divided by the number of
    values compared), so they do not depend on patch size or channel count. PatchMatch uses 8
    iterations over a 3-level pyramid; pass ``method="exact"`` for the exact value on small
    images.

    Parameters
    ----------
    image, exemplar : (M, N[, C]) array_like
        The output and the example, with the same channel count.
    patch_size : int, optional
        Patch side, odd (default 7).
    method : {"patchmatch", "exact"}, optional
        Search used to find the nearest patches.
    mask : (M, N) array_like of bool, optional
        Pixels of ``image`` to score (default all); NaN elsewhere.

    Returns
    -------
    distance : (M, N) ndarray of float32
    """
    img = as_image(image, "image")
    ex = as_image(exemplar, "exemplar")
    p = check_patch_size(patch_size)
    m = None if mask is None else as_mask(mask, "mask", img.shape[:2])
    _, dist = _patch.nnf(
        ex, img, patch_size=p, iterations=8, levels=3, method=method, target_mask=m, seed=seed, threads=threads
    )
    h, w = img.shape[:2]
    # Number of values compared at each pixel (patches are clipped at the image border).
    r = p // 2
    ny = np.minimum(np.arange(h), r) + np.minimum(h - 1 - np.arange(h), r) + 1
    nx = np.minimum(np.arange(w), r) + np.minimum(w - 1 - np.arange(w), r) + 1
    out = dist / (ny[:, None] * nx[None, :] * img.shape[2]).astype(np.float32)
    if m is not None:
        out[~m] = np.nan
    return np.asarray(out, dtype=np.float32)


def patch_coherence(image: Any, exemplar: Any, **kwargs: Any) -> float:
    """Mean of :func:`coherence_map`: 0 when every patch of ``image`` occurs in ``exemplar``.

    Takes the same keyword arguments as :func:`coherence_map`. Lower is better.

    Examples
    --------
    >>> import phloem
    >>> bark = phloem.data.bark()[:64, :64, :3]
    >>> phloem.metrics.patch_coherence(bark[8:40, 8:40], bark, patch_size=5)
    0.0
    """
    return float(np.nanmean(coherence_map(image, exemplar, **kwargs)))
