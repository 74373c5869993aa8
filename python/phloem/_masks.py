"""A hole mask read from a mask image, as ``phloem complete`` and the studio read it."""

from __future__ import annotations

import numpy as np


def hole_from_mask(m: np.ndarray, name: str, *, alpha: bool, invert: bool) -> np.ndarray:
    """The hole of ``phloem complete`` from its mask image: white (or, with ``alpha``, not fully
    opaque) pixels, flipped by ``invert``."""
    channels = 1 if m.ndim == 2 else m.shape[2]
    if alpha:
        # Gray+alpha or RGBA; anything else has no alpha, and its colours would be taken for one.
        if channels not in (2, 4):
            raise ValueError(f"mask_alpha: {name} has no alpha channel ({channels} channels); drop --mask-alpha")
        m = m[..., channels - 1]
    elif m.ndim == 3:
        m = m[..., : min(channels, 3)].max(axis=2)
    # With alpha, every pixel that is not fully opaque is filled: soft edges (alpha 0.5-1) kept
    # as they are would leave a pale ring of half-transparent colour around the fill.
    hole: np.ndarray = (m < 1.0 - 0.5 / 65535) if alpha else (m >= 0.5)
    return ~hole if invert else hole
