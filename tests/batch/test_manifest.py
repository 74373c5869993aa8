"""The files an item wrote, as the manifest hashes and a rerun verifies them."""

from __future__ import annotations

from pathlib import Path

from phloem.batch.manifest import output_files


def test_each_kind_of_output_is_found_with_its_own_sidecar(tmp_path: Path):
    for name in ("a.png", "a.png.json", "s.json", "s.sidecar.json", "m.json"):
        (tmp_path / name).write_text("x")
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "model.json").write_text("x")
    (tmp_path / "m" / ".m.tmp").write_text("x")
    assert output_files(tmp_path / "a.png") == [tmp_path / "a.png", tmp_path / "a.png.json"]
    # a JSON output's sidecar is s.sidecar.json, not s.json.json
    assert output_files(tmp_path / "s.json") == [tmp_path / "s.json", tmp_path / "s.sidecar.json"]
    assert output_files(tmp_path / "m") == [tmp_path / "m" / "model.json", tmp_path / "m.json"]
    assert output_files(tmp_path / "none.png") == []
