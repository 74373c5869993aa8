"""The hand-written stub of phloem._core matches the compiled module."""

from __future__ import annotations

import subprocess
import sys

import pytest


def test_core_stub_matches_the_module():
    pytest.importorskip("mypy")
    r = subprocess.run([sys.executable, "-m", "mypy.stubtest", "phloem._core"], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
