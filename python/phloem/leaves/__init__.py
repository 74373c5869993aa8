"""Leaves: more of the same by structural layering (Assa & Cohen-Or).

So far the colour term of layer induction, :func:`color_distance` (Eq. 1).
"""

from __future__ import annotations

# colour similarity (Eq. 1)
from .color import color_distance

__all__ = [
    "color_distance",
]
