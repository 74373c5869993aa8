"""phloem demo: the bark pipeline on embedded data."""

from __future__ import annotations

from phloem import io
from phloem.cli import main


def test_demo_runs_on_embedded_data(tmp_path):
    out = tmp_path / "bark.png"
    assert main(["demo", "--out", str(out), "--size", "64x64", "-q"]) == 0
    assert io.read_image(out).shape == (64, 64, 3)
