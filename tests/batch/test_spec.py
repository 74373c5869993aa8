"""phloem.batch.load_spec: specs are checked against the sub-command's own parser, with one
line naming the key that is wrong."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import phloem.data
from phloem.batch import load_spec, run

BRICK = phloem.data.path("brick.png")


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ({"inputs": [BRICK], "seeds": [0]}, r"^job: missing"),
        ({"job": "synth", "inputs": [BRICK], "seeds": [0]}, r"^job: 'synth' is no phloem sub-command .* synthesize"),
        ({"job": "branching", "inputs": [BRICK], "seeds": [0]}, r"^job: 'branching' needs an action: .*branching run"),
        ({"job": "studio", "inputs": [BRICK], "seeds": [0]}, r"^job: 'phloem studio' writes no --out"),
        ({"job": "batch", "inputs": [BRICK], "seeds": [0]}, r"^job: a batch runs other sub-commands, not 'batch'"),
        ({"job": "synthesize", "inputs": [], "seeds": [0]}, r"^inputs: expected a list of paths or globs"),
        ({"job": "synthesize", "inputs": ["*.nothing"], "seeds": [0]}, r"^inputs: '\*\.nothing' matches no file"),
        ({"job": "synthesize", "inputs": [BRICK], "seeds": "0-9"}, r"^seeds: expected .* FIRST\.\.LAST"),
        ({"job": "synthesize", "inputs": [BRICK], "seeds": "9..0"}, r"^seeds: expected"),
        ({"job": "synthesize", "inputs": [BRICK], "seeds": [1, 1]}, r"^seeds: expected distinct seeds"),
        ({"job": "synthesize", "inputs": [BRICK], "seeds": [0], "param": {}}, r"^param: unknown key"),
        ({"job": "synthesize", "inputs": [BRICK], "seeds": [0], "params": {"sise": 3}},
         r"^params\.sise: not an option of 'phloem synthesize'; expected one of .*--size"),
        ({"job": "synthesize", "inputs": [BRICK], "seeds": [0], "params": {"size": "0x5"}},
         r"^params\.size: expected WxH"),
        ({"job": "synthesize", "inputs": [BRICK], "seeds": [0], "params": {"size": 8, "patch-size": "x"}},
         r"^params\.patch_size: invalid int value"),
        ({"job": "synthesize", "inputs": [BRICK], "seeds": [0], "params": {"size": 8, "out": "a.png"}},
         r"^params\.out: is set by the batch"),
        ({"job": "synthesize", "inputs": [BRICK], "seeds": [0], "params": {"size": 8, "seed": 3}},
         r"^params\.seed: is set by the batch"),
        ({"job": "trees", "inputs": [BRICK], "seeds": [0], "params": {"sheet": "mine.png"}},
         r"^params\.sheet: is named by the batch for each item; give true to write it, got 'mine.png'"),
        ({"job": "synthesize", "inputs": [BRICK], "seeds": [0]}, r"^params: 'phloem synthesize' does not accept.*--size"),
        ({"job": "complete", "inputs": [BRICK], "seeds": [0]}, r"^params: 'phloem complete' needs MASK: .*params\.mask"),
        ({"job": "trees", "inputs": [BRICK], "seeds": [0], "params": {"histogram": "yes"}},
         r"^params\.histogram: expected true or false"),
    ],
)  # fmt: skip
def test_spec_errors(spec, message):
    with pytest.raises(ValueError, match=message):
        load_spec(spec)


def test_spec_files_and_items(tmp_path: Path):
    (tmp_path / "in").mkdir()
    for name in ("b.png", "a.png"):
        (tmp_path / "in" / name).write_bytes(Path(BRICK).read_bytes())
    (tmp_path / "spec.yaml").write_text(
        "job: quilt\ninputs: [in/*.png]\nparams: {size: 48x40, block: 16}\nseeds: 3..4\n"
    )
    spec = load_spec(tmp_path / "spec.yaml")
    assert [Path(p).name for p in spec.inputs] == ["a.png", "b.png"]  # relative to the spec, sorted
    assert [(Path(it.input).name, it.seed) for it in spec.items] == [
        ("a.png", 3),
        ("a.png", 4),
        ("b.png", 3),
        ("b.png", 4),
    ]
    item = spec.items[0]
    assert item.name.startswith("a-quilt-") and item.name.endswith("-s3")
    argv = item.argv(tmp_path / "out")
    assert argv[:2] == ["quilt", str(tmp_path / "in" / "a.png")]
    assert argv[argv.index("--out") + 1] == str(tmp_path / "out" / f"{item.name}.png")
    assert argv[argv.index("--seed") + 1] == "3" and argv[argv.index("--size") + 1] == "48x40"
    # the options' hash is in the name: other options, other files; the same spec, the same names
    other = load_spec({**json.loads(json.dumps({"job": "quilt", "inputs": [str(tmp_path / "in" / "a.png")],
                                               "params": {"size": "48x40", "block": 20}, "seeds": [3]}))})  # fmt: skip
    assert other.items[0].name != item.name
    assert [it.name for it in load_spec(tmp_path / "spec.yaml").items] == [it.name for it in spec.items]
    (tmp_path / "bad.yaml").write_text("job: [quilt\n")
    with pytest.raises(ValueError, match=r"^spec: .*bad.yaml is not valid YAML at line 2"):
        load_spec(tmp_path / "bad.yaml")
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(ValueError, match=r"^spec: .*bad.json is not valid JSON"):
        load_spec(tmp_path / "bad.json")
    with pytest.raises(ValueError, match=r"^spec: expected a \.yaml, \.yml or \.json file"):
        load_spec(tmp_path / "spec.txt")
    # a second positional is a param by name, relative to the spec
    (tmp_path / "mask.png").write_bytes(Path(BRICK).read_bytes())
    comp = load_spec({"job": "complete", "inputs": ["in/a.png"], "params": {"mask": "mask.png"}, "seeds": [0]},
                     base=tmp_path)  # fmt: skip
    assert comp.items[0].argv(tmp_path)[1:3] == [str(tmp_path / "in" / "a.png"), str(tmp_path / "mask.png")]


def test_run_argument_errors(tmp_path: Path):
    spec = {"job": "synthesize", "inputs": [BRICK], "params": {"size": 8}, "seeds": [0]}
    with pytest.raises(ValueError, match=r"^workers: expected a positive number"):
        run(spec, out_dir=tmp_path / "o", workers=0)
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match=r"^out_dir: .*file exists and is not a folder"):
        run(spec, out_dir=tmp_path / "file")


def test_shared_cache_of_a_trees_batch(tmp_path: Path):
    """A trees batch gives every item one library cache: the out folder's, or the one params name."""
    out = tmp_path / "out"
    spec = load_spec({"job": "trees", "inputs": [BRICK], "seeds": [0, 1], "params": {"size": 32, "n-variations": 1}})
    extra, cache = spec.shared_cache(out)
    assert extra == ["--library-cache", str(out / ".phloem-cache")] and cache == out / ".phloem-cache"
    assert all(it.argv(out, extra=extra).count("--library-cache") == 1 for it in spec.items)
    mine = load_spec(
        {
            "job": "trees",
            "inputs": [BRICK],
            "seeds": [0],
            "params": {"size": 32, "n-variations": 1, "library-cache": str(tmp_path / "k")},
        }
    )
    assert mine.shared_cache(out) == ([], tmp_path / "k")
    assert load_spec({"job": "synthesize", "inputs": [BRICK], "seeds": [0], "params": {"size": 8}}).shared_cache(
        out
    ) == ([], None)
