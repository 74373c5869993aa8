"""Texture synthesis and image completion on the patch-matching engine.

- :func:`synthesize`: texture optimisation (Kwatra et al. 2005), coarse to fine;
- :func:`by_numbers`: texture-by-numbers (Laitoch 2018 after Fan et al. 2012), with
  :func:`feature_distance_map` for its feature channel;
- :func:`quilt`: graph-cut quilting (Kwatra et al. 2003);
- :func:`complete`: image completion (Wexler, Shechtman, Irani 2007).
"""

from __future__ import annotations

from .by_numbers import by_numbers, feature_distance_map
from .complete import complete
from .quilt import quilt
from .synthesis import synthesize

__all__ = ["by_numbers", "complete", "feature_distance_map", "quilt", "synthesize"]

# Branching's own gap-filling loop still uses these internals; they go when it calls complete().
from . import _pyramid
from .complete import WEXLER_GAMMA as WEXLER_GAMMA
from .complete import WEXLER_SIGMA_PERCENTILE as WEXLER_SIGMA_PERCENTILE
from .complete import _fill_inward as _fill_inward
from .complete import _patch_masks as _patch_masks

_downsample = _pyramid.downsample
_upsample_field = _pyramid.upsample_field
