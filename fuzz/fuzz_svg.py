"""Fuzz target: SVG stroke drawings, through ``strokes.read_svg`` (the whole drawing and one layer).

Expected: ``StrokeError`` (a ``ValueError``). Anything else is a crash, and so is a stroke that is
not finite, or a layer's strokes that are not among the whole drawing's.
"""

from __future__ import annotations

import numpy as np
from _common import fuzz, instrumented, target, temp_file

with instrumented():
    from phloem.strokes import StrokeError, read_svg


@target
def TestOneInput(data: bytes) -> None:
    path = temp_file(data, ".svg")
    try:
        strokes = read_svg(path)
    except StrokeError:
        return
    for s in strokes:
        assert np.isfinite(s.points).all() and s.length() > 0, "a stroke that is not finite"
    try:
        layer = read_svg(path, layer="source")
    except StrokeError:
        return
    assert all(s in strokes for s in layer), "a layer's stroke is not in the drawing"


if __name__ == "__main__":
    fuzz(TestOneInput)
