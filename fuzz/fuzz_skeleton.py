"""Fuzz target: skeleton JSON, through ``Skeleton.from_json`` (text) and ``Skeleton.load`` (raw bytes on disk).

Expected: ``SkeletonError`` (a ``ValueError``). Anything else is a crash, and so is a skeleton
that does not survive ``to_json`` → ``from_json`` unchanged, or ``load`` and ``from_json``
disagreeing on whether the same UTF-8 bytes are a skeleton.
"""

from __future__ import annotations

import contextlib

from _common import fuzz, instrumented, target, temp_file

with instrumented():
    from phloem.branching import Skeleton
    from phloem.branching.skeleton import SkeletonError


@target
def TestOneInput(data: bytes) -> None:
    loaded: Skeleton | None
    try:
        loaded = Skeleton.load(temp_file(data, ".json"))
    except SkeletonError:
        loaded = None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = None
    if text is not None:
        parsed: Skeleton | None
        try:
            parsed = Skeleton.from_json(text)
        except SkeletonError:
            parsed = None
        assert (parsed is None) == (loaded is None), "load and from_json disagree"
    if loaded is not None:
        assert Skeleton.from_json(loaded.to_json()) == loaded, "to_json/from_json round trip changed the skeleton"
        loaded.total_length()
        loaded.bounds()
        if loaded.shape is not None:
            with contextlib.suppress(SkeletonError):
                loaded.check_inside(loaded.shape)


if __name__ == "__main__":
    fuzz(TestOneInput)
