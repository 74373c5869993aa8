"""phloem leaves extract|analyze|synthesize|run: files, sidecars, no silent overwrite, errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from phloem import io
from phloem.cli import main
from phloem.testing import layered_leaf, scribbles_from

_FAST = ["--points", "40", "--epsilon", "10", "-q"]


def _scan(leaf: np.ndarray, pad: int = 12) -> np.ndarray:
    """The leaf on white paper, as a scanner gives it."""
    a = leaf[..., 3:]
    rgb = leaf[..., :3] * a + 0.96 * (1 - a)
    return np.pad(rgb, ((pad, pad), (pad, pad), (0, 0)), constant_values=0.96)


@pytest.fixture()
def files(tmp_path):
    paths = []
    for v in range(2):
        leaf, labels = layered_leaf(variant=v, seed=v)
        io.write_image(tmp_path / f"leaf{v}.png", leaf)
        paths.append(tmp_path / f"leaf{v}.png")
        if v == 0:
            io.write_image(tmp_path / "scribbles.png", scribbles_from(labels, seed=1).astype(np.uint8))
    return paths, tmp_path / "scribbles.png"


def test_run_writes_leaves_sidecars_model_and_sheet(tmp_path, files) -> None:
    leaves_in, sc = files
    out, model, sheet = tmp_path / "new", tmp_path / "model", tmp_path / "sheet.png"
    args = ["leaves", "run", *map(str, leaves_in), "--scribbles", str(sc), "--count", "2", "--out-dir", str(out)]
    assert main([*args, "--model-out", str(model), "--sheet", str(sheet), "--seed", "3", *_FAST]) == 0
    assert sorted(p.name for p in out.iterdir()) == [f"leaf_{i:04d}.png{s}" for i in range(2) for s in ("", ".json")]
    img = io.read_image(out / "leaf_0001.png")
    assert img.shape[2] == 4 and img[..., 3].max() == 1.0 and img[0, 0, 3] == 0.0
    meta = json.loads((out / "leaf_0001.png.json").read_text())
    assert meta["command"] == "leaves run" and meta["seed"] == 3 and "leaf_seed" in meta["details"]
    assert sorted(p.name for p in model.iterdir()) == ["exemplar_000.npz", "exemplar_001.npz", "model.json"]
    side = json.loads((tmp_path / "model.json").read_text())
    assert (
        side["command"] == "leaves analyze" and len(side["details"]["leaves"]) == 2 and len(side["details"]["lam"]) == 2
    )
    assert io.read_image(sheet).shape[0] >= 5 * 200

    # a new leaf is remade alone from its sidecar's seed, by synthesize on the saved model
    again = tmp_path / "again"
    seed = str(meta["details"]["leaf_seed"])
    assert main(["leaves", "synthesize", str(model), "--count", "1", "--out-dir", str(again), "--seed", "0", "-q"]) == 0
    assert main(["leaves", "synthesize", str(model), "--count", "1", "--out-dir", str(again), "--prefix", "x", "-q",
                 "--seed", seed]) == 0  # fmt: skip


def test_synthesize_replays_a_leaf_exactly(tmp_path, files) -> None:
    leaves_in, sc = files
    model = tmp_path / "model"
    assert main(["leaves", "analyze", *map(str, leaves_in), "--scribbles", str(sc), "--out", str(model), *_FAST]) == 0
    a, b = tmp_path / "a", tmp_path / "b"
    assert main(["leaves", "synthesize", str(model), "--count", "2", "--out-dir", str(a), "--seed", "9", "-q"]) == 0
    assert main(["leaves", "synthesize", str(model), "--count", "2", "--out-dir", str(b), "--seed", "9", "-q"]) == 0
    for name in ("leaf_0000.png", "leaf_0001.png"):
        assert (a / name).read_bytes() == (b / name).read_bytes()
    assert (a / "leaf_0000.png").read_bytes() != (a / "leaf_0001.png").read_bytes()


def test_extract_cuts_each_leaf_of_a_scan(tmp_path) -> None:
    leaf, _ = layered_leaf()
    two = np.concatenate([_scan(leaf), _scan(layered_leaf(variant=1)[0])], axis=1)
    io.write_image(tmp_path / "scan.png", two)
    assert main(["leaves", "extract", str(tmp_path / "scan.png"), "--out-dir", str(tmp_path / "cut"), "-q"]) == 0
    names = sorted(p.name for p in (tmp_path / "cut").iterdir())
    assert names == ["scan_0.png", "scan_0.png.json", "scan_1.png", "scan_1.png.json"]
    assert io.read_image(tmp_path / "cut" / "scan_0.png").shape[2] == 4


def test_nothing_is_overwritten_without_force(tmp_path, files, capsys) -> None:
    leaves_in, sc = files
    model = tmp_path / "model"
    args = ["leaves", "analyze", *map(str, leaves_in), "--scribbles", str(sc), "--out", str(model), *_FAST]
    assert main(args) == 0
    before = (model / "model.json").read_bytes()
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "already exists" in err and err.count("\n") == 1
    assert (model / "model.json").read_bytes() == before
    assert main([*args, "--force"]) == 0


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--training", "7"], "--training: the LEAF files hold 2 leaves"),
        (["--order", "1,x"], "--order: expected comma-separated"),
        (["--order", "1,1,3"], "--order: expected a permutation"),
    ],
)
def test_bad_options_are_one_line_errors(tmp_path, files, capsys, extra, message) -> None:
    leaves_in, sc = files
    args = ["leaves", "analyze", *map(str, leaves_in), "--scribbles", str(sc), "--out", str(tmp_path / "m"), *_FAST]
    assert main([*args, *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "m").exists()


def test_one_leaf_only_and_a_bad_model_folder(tmp_path, files, capsys) -> None:
    leaves_in, sc = files
    assert (
        main(["leaves", "analyze", str(leaves_in[0]), "--scribbles", str(sc), "--out", str(tmp_path / "m"), *_FAST])
        == 2
    )
    assert "at least 2 leaves" in capsys.readouterr().err
    (tmp_path / "bad").mkdir()
    assert (
        main(["leaves", "synthesize", str(tmp_path / "bad"), "--count", "1", "--out-dir", str(tmp_path / "o"), "-q"])
        == 2
    )
    err = capsys.readouterr().err
    assert "model.json" in err and err.count("\n") == 1
    assert not (tmp_path / "o").exists()


def test_synthesize_reads_a_model_once_per_process_until_it_changes(tmp_path, files, monkeypatch) -> None:
    # a batch worker runs many synthesize items of one model: it is read once, and again if rewritten
    from phloem import leaves

    leaves_in, sc = files
    model = tmp_path / "model"
    assert main(["leaves", "analyze", *map(str, leaves_in), "--scribbles", str(sc), "--out", str(model), *_FAST]) == 0
    reads = []
    real = leaves.LeafModel.load
    monkeypatch.setattr(leaves.LeafModel, "load", lambda path: reads.append(path) or real(path))

    def synth(out: str, seed: str) -> bytes:
        args = ["leaves", "synthesize", str(model), "--count", "1", "--out-dir", str(tmp_path / out), "--seed", seed]
        assert main([*args, "-q"]) == 0
        return (tmp_path / out / "leaf_0000.png").read_bytes()

    first = synth("a", "1")
    assert synth("b", "1") == first and synth("c", "2") != first
    assert len(reads) == 1
    meta = json.loads((model / "model.json").read_text())
    (model / "model.json").write_text(json.dumps(meta, indent=2))  # the same model, rewritten
    assert synth("d", "1") == first and len(reads) == 2
