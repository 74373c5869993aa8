"""Texture synthesis and image completion on the patch-matching engine.

- :func:`synthesize`: texture optimisation (Kwatra et al. 2005), coarse to fine;
- :func:`by_numbers`: texture-by-numbers (Laitoch 2018 after Fan et al. 2012), with
  :func:`feature_distance_map` for its feature channel;
- :func:`quilt`: graph-cut quilting (Kwatra et al. 2003);
- :func:`complete`: image completion (Wexler, Shechtman, Irani 2007).
"""

from __future__ import annotations

from .by_numbers import ByNumbersResult, by_numbers, feature_distance_map
from .complete import complete
from .quilt import QuiltResult, quilt
from .synthesis import synthesize

__all__ = ["ByNumbersResult", "QuiltResult", "by_numbers", "complete", "feature_distance_map", "quilt", "synthesize"]
