"""phloem.testing: the real-image collection is found or skipped cleanly, and the scenes are what they say."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from phloem import testing


def test_shared_data_follows_the_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "bark").mkdir()
    (tmp_path / "bark" / "a.png").write_bytes(b"")
    monkeypatch.setenv("PHLOEM_SHARED_DATA", str(tmp_path))
    assert testing.shared_data() == tmp_path
    assert testing.shared_path("bark", "a.png") == tmp_path / "bark" / "a.png"
    assert testing.shared_file("bark", "a.png").exists()
    monkeypatch.setenv("PHLOEM_SHARED_DATA", str(tmp_path / "missing"))
    assert testing.shared_data() is None
    assert not testing.shared_path("bark", "a.png").exists()


def test_shared_file_skips_when_the_file_is_absent(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PHLOEM_SHARED_DATA", str(tmp_path))
    with pytest.raises(pytest.skip.Exception, match="not available"):
        testing.shared_file("no", "such.png")


def test_river_scene_draws_water_along_its_skeleton() -> None:
    sk = testing.river_skeleton((120, 200), seed=1, scale=0.5)
    img = testing.river_picture(sk, seed=1)
    assert img.shape == (120, 200, 3) and img.dtype == np.float32
    on = sk.mask()
    assert img[on][:, 2].mean() > img[~on][:, 2].mean()  # the channel is bluer than the land
    assert img[on].sum(axis=1).mean() < img[~on].sum(axis=1).mean()  # and darker


def test_channel_scene_and_longest_path() -> None:
    img, sk = testing.channel_scene()
    assert img.shape == sk.shape == (128, 224)
    path = testing.longest_path(sk.mask())
    assert path.shape[1] == 2 and len(path) > 150  # the main branch runs about 210 px
