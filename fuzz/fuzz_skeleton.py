"""Fuzz target: skeleton JSON, through ``Skeleton.from_json`` (text) and ``Skeleton.load`` (raw bytes on disk).

Expected: ``SkeletonError`` (a ``ValueError``). Anything else is a crash, and so is a skeleton
that does not survive ``to_json`` → ``from_json`` unchanged, or ``load`` and ``from_json``
disagreeing on whether the same UTF-8 bytes are a skeleton.
"""

from __future__ import annotations

import contextlib

from _common import fuzz, instrumented, json_format, target

with instrumented():
    from phloem.branching import Skeleton
    from phloem.branching.skeleton import SkeletonError


@target
def TestOneInput(data: bytes) -> None:
    loaded = json_format(data, Skeleton)
    if loaded is not None:
        loaded.total_length()
        loaded.bounds()
        if loaded.shape is not None:
            with contextlib.suppress(SkeletonError):
                loaded.check_inside(loaded.shape)


if __name__ == "__main__":
    fuzz(TestOneInput)
