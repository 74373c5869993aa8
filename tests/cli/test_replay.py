"""phloem replay / --from-json / phloem.replay: every sub-command that writes a sidecar replays to
the same bytes; sidecars record resolved values; changed inputs, bad sidecars and existing outputs
are refused in one line."""

from __future__ import annotations

import argparse
import hashlib
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

import phloem
from phloem import io
from phloem.cli import build_parser, main
from phloem.strokes import StrokeSet
from phloem.testing import layered_leaf, scribbles_from

_LEAVES_FAST = ["--points", "40", "--epsilon", "10"]


def _run(argv: list[str]) -> None:
    assert main([*argv, "-q"]) == 0, argv


def _river(path: Path) -> None:
    """A dark river on a noisy green: traced with --kind auto, which resolves to 'dark'."""
    img = np.full((96, 128, 3), (0.55, 0.6, 0.35), np.float32)
    img += np.random.default_rng(0).normal(0, 0.03, img.shape).astype(np.float32)
    for a, b, t in [((4, 90), (64, 48), 7), ((64, 48), (124, 8), 5), ((64, 48), (80, 92), 4)]:
        cv2.line(img, a, b, (0.1, 0.15, 0.4), t)
    io.write_image(path, img.clip(0, 1))


def _tree(path: Path, crown: int, trunk: int) -> None:
    img = np.zeros((120, 100, 4), np.float32)
    yy, xx = np.mgrid[:120, :100]
    img[(yy - 45) ** 2 + (xx - 50) ** 2 < crown**2] = (0.1, 0.6, 0.2, 1.0)
    img[70:118, 50 - trunk : 50 + trunk] = (0.4, 0.3, 0.1, 1.0)
    io.write_image(path, img)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Small input files for every sub-command, in one folder the runs only read."""
    d = tmp_path_factory.mktemp("in")
    bark = phloem.data.bark()[..., :3]
    io.write_image(d / "ex.png", bark[:64, :64])
    hole = np.zeros((64, 64), np.float32)
    hole[24:36, 20:40] = 1
    io.write_image(d / "hole.png", hole)
    _river(d / "river.png")
    _run(["branching", "trace", str(d / "river.png"), "--sigmas", "2", "3", "--out", str(d / "river.json")])
    _run(["branching", "grow", str(d / "river.json"), "--out", str(d / "new.json"), "--seed", "1"])
    (d / "lib").mkdir()
    for i, (c, t) in enumerate([(30, 4), (40, 6), (25, 3)]):
        _tree(d / "lib" / f"t{i}.png", c, t)
    for v in range(2):
        leaf, labels = layered_leaf(variant=v, seed=v)
        io.write_image(d / f"leaf{v}.png", leaf)
        if v == 0:
            io.write_image(d / "scribbles.png", scribbles_from(labels, seed=1).astype(np.uint8))
    leaves = [str(d / "leaf0.png"), str(d / "leaf1.png"), "--scribbles", str(d / "scribbles.png"), *_LEAVES_FAST]
    _run(["leaves", "analyze", *leaves, "--out", str(d / "model")])
    bar = np.zeros((60, 160, 4), np.float32)
    bar[20:41, 10:150] = [0.5, 0.4, 0.3, 1.0]
    bar[20:41, 10:150:6, :3] = 0.2
    io.write_image(d / "bar.png", bar)
    StrokeSet.from_lists([[[12, 30], [147, 30]]], [[[20, 70], [60, 20], [100, 60]]], target_size=(80, 110)).save(
        d / "strokes.json"
    )
    return d


# sub-command: (its arguments, {in} for the inputs' folder and {out} for the output folder; the
# sidecar to replay and the main output, both relative to {out})
_LEAVES = "{in}/leaf0.png {in}/leaf1.png --scribbles {in}/scribbles.png --points 40 --epsilon 10"
CASES = {
    "synthesize": ("synthesize {in}/ex.png --size 40x32 --out {out}/s.png", "s.png.json", "s.png"),
    "quilt": ("quilt {in}/ex.png --size 72 --out {out}/q.png --seed 3", "q.png.json", "q.png"),
    "complete": ("complete {in}/ex.png {in}/hole.png --out {out}/c.png", "c.png.json", "c.png"),
    "bark": (
        "bark --size 40 --out {out}/b.png --keep-intermediates --cylinder-preview {out}/cyl.png --seed 2",
        "b.png.json",
        "b.png",
    ),
    "demo": ("demo --size 32 --out {out}/d.png", "d.png.json", "d.png"),
    "trees": (
        "trees {in}/lib --n-variations 2 --size 64 --out-dir {out}/trees --sheet {out}/sheet.png --seed 5",
        "trees/tree_0001.png.json",
        "trees",
    ),
    "branching trace": (
        "branching trace {in}/river.png --sigmas 2 3 --out {out}/t.json --overlay {out}/ov.png",
        "t.sidecar.json",
        "t.json",
    ),
    "branching grow": (
        "branching grow {in}/river.json --out {out}/g.json --preview {out}/p.png --histograms {out}/h.png --seed 4",
        "g.sidecar.json",
        "g.json",
    ),
    "branching render": (
        "branching render {in}/river.png {in}/river.json {in}/new.json --out {out}/r.png --fragment-map {out}/fm.png",
        "r.png.json",
        "r.png",
    ),
    "branching run": (
        "branching run {in}/river.png --sigmas 2 3 --out {out}/n.png --seed 2",
        "n_skeleton.sidecar.json",
        "n.png",
    ),
    "leaves extract": ("leaves extract {in}/leaf0.png --out-dir {out}/cut", "cut/leaf0_0.png.json", "cut"),
    "leaves analyze": (
        f"leaves analyze {_LEAVES} --out {{out}}/model",
        "model.json",
        "model",
    ),
    "leaves synthesize": (
        "leaves synthesize {in}/model --count 2 --out-dir {out}/new --seed 3",
        "new/leaf_0000.png.json",
        "new",
    ),
    "leaves run": (
        f"leaves run {_LEAVES} --count 1 --out-dir {{out}}/new --model-out {{out}}/model",
        "new/leaf_0000.png.json",
        "new",
    ),
    "strokes edit": (
        "strokes edit {in}/bar.png {in}/strokes.json --out {out}/e.png --sheet {out}/sheet.png",
        "e.png.json",
        "e.png",
    ),
    "strokes draw": (
        "strokes draw {in}/bar.png {in}/strokes.json --side target --out {out}/w.png",
        "w.png.json",
        "w.png",
    ),
}


def _first_run(name: str, inputs: Path, out: Path) -> list[str]:
    line, _, _ = CASES[name]
    out.mkdir(parents=True, exist_ok=True)
    argv = [a.replace("{in}", str(inputs)).replace("{out}", str(out)) for a in line.split()]
    _run(argv)
    return argv


def _options(command: str) -> set[str]:
    """The options of a sub-command a sidecar records: all but machine, terminal, cache and seed ones."""
    p = build_parser()
    for word in command.split():
        p = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction)).choices[word]
    machine = {"help", "seed", "threads", "max_pixels", "max_memory", "quiet", "force", "from_json", "library_cache"}
    return {a.dest for a in p._actions if a.help != argparse.SUPPRESS and a.dest not in machine}


def _files(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _assert_same_bytes(a: Path, b: Path) -> None:
    """Every file under ``a`` is under ``b`` with the same bytes, but for the paths of ``a`` in the
    sidecars, which name the outputs under ``b``."""
    first, again = _files(a), _files(b)
    assert sorted(first) == sorted(again)
    for name, data in first.items():
        assert data.replace(str(a).encode(), str(b).encode()) == again[name], name


@pytest.mark.parametrize("name", sorted(CASES))
def test_replay_writes_the_same_bytes(name: str, inputs: Path, tmp_path: Path) -> None:
    _first_run(name, inputs, tmp_path / "a")
    _, side, main_out = CASES[name]
    meta = json.loads((tmp_path / "a" / side).read_text())
    assert meta["command"] == name and meta["sidecar_version"] == io.SIDECAR_VERSION
    assert set(meta["parameters"]) == _options(name)  # every option, and nothing that is not one
    assert main(["replay", str(tmp_path / "a" / side), "--out", str(tmp_path / "b" / main_out), "-q"]) == 0
    _assert_same_bytes(tmp_path / "a", tmp_path / "b")


@pytest.mark.parametrize("way", ["python", "from-json"])
def test_replay_from_python_and_from_json(way: str, inputs: Path, tmp_path: Path) -> None:
    _first_run("branching grow", inputs, tmp_path / "a")
    side, new = tmp_path / "a" / "g.sidecar.json", tmp_path / "b" / "g.json"
    if way == "python":
        assert phloem.replay(side, out=new) == new
    else:
        assert main(["branching", "grow", "--from-json", str(side), "--out", str(new), "-q"]) == 0
    _assert_same_bytes(tmp_path / "a", tmp_path / "b")


def test_sidecars_record_resolved_values_threads_and_input_hashes(inputs: Path, tmp_path: Path) -> None:
    out = tmp_path / "a"
    for name in ("synthesize", "quilt", "branching trace", "branching run"):
        _first_run(name, inputs, out)
    meta = json.loads((out / "s.png.json").read_text())
    assert meta["parameters"]["levels"] == 2  # asked: None, "from the exemplar size"
    assert isinstance(meta["threads"], int) and meta["threads"] >= 1
    digest = hashlib.sha256((inputs / "ex.png").read_bytes()).hexdigest()
    assert meta["inputs"] == [{"path": str(inputs / "ex.png"), "sha256": digest}]
    assert meta["phloem_version"] == phloem.__version__ and meta["seed"] == 0
    quilt = json.loads((out / "q.png.json").read_text())["parameters"]
    assert (quilt["block"], quilt["overlap"]) == (32, 8)  # half the 64-pixel exemplar, a quarter of that
    trace = json.loads((out / "t.sidecar.json").read_text())
    assert trace["parameters"]["kind"] == "dark" and trace["details"]["branches"] >= 2
    run = json.loads((out / "n.png.json").read_text())["parameters"]
    assert run["kind"] == "dark" and run["size"] == [96, 128] and run["m"] == 4 and run["course"] == 32
    # straight channels: their heading statistics are known (drift_noise under 0.125), so
    # course_defaults turned both on, and the sidecar records them as used
    assert run["coarse_history"] == 2.0 and run["total_turn"] == 2.0 and run["repel_border"] is True
    assert run["turn_bound"] == 5.0  # with the total turn, its bound, recorded as fitted
    assert run["h"] > 0


def test_json_outputs_have_sidecar_json_sidecars_and_old_names_are_found(tmp_path: Path) -> None:
    assert io.sidecar_path(tmp_path / "skel.json") == tmp_path / "skel.sidecar.json"
    assert io.sidecar_path(tmp_path / "o.png") == tmp_path / "o.png.json"
    assert io.find_sidecar(tmp_path / "skel.json") is None
    (tmp_path / "skel.json.json").write_text("{}")  # written before sidecar layout 2
    assert io.find_sidecar(tmp_path / "skel.json") == tmp_path / "skel.json.json"
    (tmp_path / "skel.sidecar.json").write_text("{}")
    assert io.find_sidecar(tmp_path / "skel.json") == tmp_path / "skel.sidecar.json"


def test_a_changed_input_is_refused_unless_allowed(inputs: Path, tmp_path: Path, capsys) -> None:
    _first_run("synthesize", inputs, tmp_path / "a")
    side = tmp_path / "a" / "s.png.json"
    meta = json.loads(side.read_text())
    ex = tmp_path / "ex.png"
    io.write_image(ex, phloem.data.bark()[64:128, :64, :3])
    meta["inputs"][0]["path"] = meta["parameters"]["input"] = str(ex)
    side.write_text(json.dumps(meta))
    new = tmp_path / "b" / "s.png"
    capsys.readouterr()
    assert main(["replay", str(side), "--out", str(new), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"input {ex} has changed" in err and "--allow-changed-inputs" in err
    assert not (tmp_path / "b").exists()
    assert main(["replay", str(side), "--out", str(new), "--allow-changed-inputs", "-q"]) == 0
    assert new.read_bytes() != (tmp_path / "a" / "s.png").read_bytes()


def test_no_overwrite_without_force(inputs: Path, tmp_path: Path, capsys) -> None:
    _first_run("quilt", inputs, tmp_path / "a")
    side, out = tmp_path / "a" / "q.png.json", tmp_path / "a" / "q.png"
    before = out.read_bytes()
    out.write_bytes(b"not the output")
    capsys.readouterr()
    assert main(["replay", str(side), "-q"]) == 2  # to the recorded paths, which exist
    assert "already exists" in capsys.readouterr().err and out.read_bytes() == b"not the output"
    with pytest.raises(FileExistsError):
        phloem.replay(side)
    assert main(["replay", str(side), "--force", "-q"]) == 0
    assert out.read_bytes() == before


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("{not json", "s.json line 1"),
        ("[1, 2]", "expected a JSON object"),
        ('{"command": "quilt"}', "'parameters' is missing"),
        ('{"sidecar_version": 9, "command": "quilt", "parameters": {}}', "sidecar_version 9"),
        ('{"sidecar_version": 2, "command": "studio", "parameters": {}, "inputs": []}', "'phloem studio' is not"),
        ('{"sidecar_version": 2, "command": "quilt", "parameters": {"size": "big"}, "inputs": []}', "valid 'phloem"),
        ('{"sidecar_version": 2, "command": "quilt", "parameters": {}, "inputs": [{"path": 1}]}', "inputs[0]"),
        ('{"sidecar_version": 2, "command": "demo", "seed": -1, "parameters": {}, "inputs": []}', "'seed' must be"),
        (
            '{"sidecar_version": 2, "command": "branching grow", "parameters": {"repel_border": "yes"}, "inputs": []}',
            "'repel_border' must be true, false or null",
        ),
    ],
)
def test_a_malformed_sidecar_is_one_line(text: str, message: str, tmp_path: Path, capsys) -> None:
    side = tmp_path / "s.json"
    side.write_text(text)
    assert main(["replay", str(side), "--out", str(tmp_path / "o.png"), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("phloem replay: error: ") and err.count("\n") == 1 and message in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.json"]


def test_from_json_names_its_command_and_another_version_warns(inputs: Path, tmp_path: Path, capsys) -> None:
    _first_run("synthesize", inputs, tmp_path / "a")
    side = tmp_path / "a" / "s.png.json"
    capsys.readouterr()
    assert main(["quilt", "--from-json", str(side), "--out", str(tmp_path / "q.png"), "-q"]) == 2
    assert "records 'phloem synthesize', not 'phloem quilt'" in capsys.readouterr().err
    meta = json.loads(side.read_text())
    meta["phloem_version"] = "0.0.1"
    side.write_text(json.dumps(meta))
    assert main(["replay", str(side), "--out", str(tmp_path / "b" / "s.png"), "-q"]) == 0
    err = capsys.readouterr().err
    assert "warning:" in err and "phloem 0.0.1" in err and err.count("\n") == 1
    assert (tmp_path / "b" / "s.png").read_bytes() == (tmp_path / "a" / "s.png").read_bytes()


def test_a_layout_1_sidecar_replays_with_a_warning(inputs: Path, tmp_path: Path) -> None:
    """Sidecars from before layout 2 had no version, hashes or threads, and details in parameters."""
    _first_run("quilt", inputs, tmp_path / "a")
    meta = json.loads((tmp_path / "a" / "q.png.json").read_text())
    old = {k: meta[k] for k in ("phloem_version", "command", "seed", "output")}
    old["parameters"] = {**meta["parameters"], "exemplars": ["found by the run"]}
    (tmp_path / "old.json").write_text(json.dumps(old))
    with pytest.warns(UserWarning, match="without input hashes"):
        phloem.replay(tmp_path / "old.json", out=tmp_path / "b" / "q.png")
    assert (tmp_path / "b" / "q.png").read_bytes() == (tmp_path / "a" / "q.png").read_bytes()
