"""Helpers for phloem's own tests and benchmarks (and for users who test code built on phloem).

``shared_file`` finds a file of the project's optional real-image collection, whose folder is
``$PHLOEM_SHARED_DATA`` (the test suite's ``conftest.py`` points it at ``../shared/data`` beside a
checkout), and skips the calling test when it is absent, as it is in CI.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["shared_data", "shared_file"]


def shared_data() -> Path | None:
    """The folder of the optional real-image collection, or None when it is not there."""
    root = os.environ.get("PHLOEM_SHARED_DATA")
    if not root:
        return None
    p = Path(root)
    return p if p.is_dir() else None


def shared_file(*parts: str) -> Path:
    """A file of the real-image collection, or skip the running test when it is not available."""
    import pytest

    root = shared_data()
    p = (root or Path("<PHLOEM_SHARED_DATA unset>")).joinpath(*parts)
    if root is None or not p.exists():
        pytest.skip(f"{p} is not available")
    return p
