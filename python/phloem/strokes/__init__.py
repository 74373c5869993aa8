"""Stroke-based editing of object structure (Luo, Lin, Shen & Chen): re-draw an object along new strokes.

The stroke model and its files: :class:`Stroke`, :class:`StrokePair`, :class:`StrokeSet`
(JSON ``phloem.strokes``), strokes from SVG drawings (:func:`read_svg`) and from traced
skeletons (:func:`strokes_from_skeleton`).
"""

from __future__ import annotations

from .skeleton import strokes_from_skeleton
from .stroke_set import Stroke, StrokeError, StrokePair, StrokeSet
from .svg import read_svg

__all__ = ["Stroke", "StrokeError", "StrokePair", "StrokeSet", "read_svg", "strokes_from_skeleton"]
