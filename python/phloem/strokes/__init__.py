"""Stroke-based editing of object structure (Luo, Lin, Shen & Chen): re-draw an object along new strokes.

The stroke model and its files: :class:`Stroke`, :class:`StrokePair`, :class:`StrokeSet`
(JSON ``phloem.strokes``), strokes from SVG drawings (:func:`read_svg`) and from traced
skeletons (:func:`strokes_from_skeleton`); the object re-drawn along target strokes
(:func:`edit`), and pictures of both (:func:`draw`, :func:`contact_sheet`).
"""

from __future__ import annotations

from .sampling import Sampling
from .sheet import contact_sheet, draw
from .skeleton import strokes_from_skeleton
from .stroke_set import Stroke, StrokeError, StrokePair, StrokeSet
from .svg import read_svg, read_svg_widths
from .synthesis import EditResult, edit

__all__ = [
    "EditResult",
    "Sampling",
    "Stroke",
    "StrokeError",
    "StrokePair",
    "StrokeSet",
    "contact_sheet",
    "draw",
    "edit",
    "read_svg",
    "read_svg_widths",
    "strokes_from_skeleton",
]
