"""Fuzz target: stroke-set JSON, through ``StrokeSet.from_json`` (text) and ``StrokeSet.load`` (raw bytes on disk).

Expected: ``StrokeError`` (a ``ValueError``). Anything else is a crash, and so is a stroke set
that does not survive ``to_json`` → ``from_json`` unchanged, or ``load`` and ``from_json``
disagreeing on whether the same UTF-8 bytes are a stroke set.
"""

from __future__ import annotations

from _common import fuzz, instrumented, json_format, target

with instrumented():
    from phloem.strokes import StrokeSet


@target
def TestOneInput(data: bytes) -> None:
    loaded = json_format(data, StrokeSet)
    if loaded is not None:
        for pair in loaded.pairs:
            for stroke in (pair.source, pair.target):
                t = stroke.tangents()
                assert ((t * t).sum(1) > 0.999).all(), "a tangent is not a unit vector"
                assert stroke.length() > 0


if __name__ == "__main__":
    fuzz(TestOneInput)
