"""Fixtures of the CLI tests."""

from __future__ import annotations

import pytest

from phloem import io


@pytest.fixture()
def exemplar_png(tmp_path, bark):
    p = tmp_path / "ex.png"
    io.write_image(p, bark[:64, :64])
    return p
