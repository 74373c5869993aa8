"""The leaves workspace's API: scribbles written as the integer label PNG ``phloem leaves`` reads,
expansion to layers, analysis with synthesis (model folder, new leaves with sidecars, contact
sheet); bad requests."""

from __future__ import annotations

import base64
import json

import numpy as np
import pytest

from phloem import io, leaves
from phloem.studio.workspaces.leaves import LAYER_COLOURS
from phloem.testing import layered_leaf, scribbles_from

from .conftest import run_job

H, W = 160, 96


@pytest.fixture
def leaf_files(project):
    """Two RGBA leaves (transparent around them) and scribbles of all three layers on the first."""
    made = [layered_leaf(variant=v, seed=v) for v in range(2)]
    for v, (img, _) in enumerate(made):
        io.write_image(project.root / "photos" / f"leaf{v}.png", img)
    return made[0][1], scribbles_from(made[0][1], seed=3)


def _label_map(labels: np.ndarray, n: int) -> dict[str, object]:
    h, w = labels.shape
    return {
        "width": w,
        "height": h,
        "n_labels": n,
        "data": base64.b64encode(labels.astype(np.uint8).tobytes()).decode(),
    }


def test_scribbles_are_the_integer_label_png_phloem_leaves_reads(client, project, leaf_files):
    _, sc = leaf_files
    r = client.put("/api/scribbles", params={"path": "photos/leaf0_scribbles.png"}, json=_label_map(sc, 4))
    assert r.status_code == 200, r.text
    labels, n = leaves.read_scribbles(project.root / "photos" / "leaf0_scribbles.png", (H, W))
    assert n == 3 and np.array_equal(labels, sc)
    back = client.get("/api/scribbles", params={"path": "photos/leaf0_scribbles.png", "image": "photos/leaf0.png"})
    assert back.status_code == 200 and back.json() == _label_map(sc, 4)
    r = client.put("/api/scribbles", params={"path": "photos/leaf0_scribbles.png"}, json=_label_map(sc, 4))
    assert r.status_code == 409


@pytest.mark.parametrize(
    ("change", "status", "words"),
    [
        (lambda b: b.update(data="%%%"), 422, "data: not base64"),
        (lambda b: b.update(width=95), 422, "data: expected"),
        (lambda b: b.update(n_labels=2), 422, "not below n_labels"),
        (lambda b: b.update(data=base64.b64encode(bytes(H * W)).decode()), 422, "nothing is scribbled"),
        (lambda b: b.update(n_labels=40), 422, "n_labels"),
    ],
)
def test_bad_scribbles_are_refused_and_nothing_is_written(client, project, leaf_files, change, status, words):
    body = _label_map(leaf_files[1], 4)
    change(body)
    r = client.put("/api/scribbles", params={"path": "s.png"}, json=body)
    assert r.status_code == status and words in r.json()["detail"], r.text
    assert not (project.root / "s.png").exists()
    assert (
        client.put("/api/scribbles", params={"path": "../s.png"}, json=_label_map(leaf_files[1], 4)).status_code == 400
    )


def test_reading_scribbles_of_another_size_or_one_layer_is_a_422(client, project, leaf_files):
    one = (leaf_files[1] == 1).astype(np.uint8)
    client.put("/api/scribbles", params={"path": "one.png"}, json=_label_map(one, 2))
    r = client.get("/api/scribbles", params={"path": "one.png", "image": "photos/leaf0.png"})
    assert r.status_code == 422 and "only one layer" in r.json()["detail"]
    r = client.get("/api/scribbles", params={"path": "one.png", "image": "photos/bar.png"})
    assert r.status_code == 422 and "size" in r.json()["detail"]


def test_expand_writes_the_layers_in_the_page_s_colours(client, project, leaf_files):
    truth, sc = leaf_files
    client.put("/api/scribbles", params={"path": "photos/leaf0_scribbles.png"}, json=_label_map(sc, 4))
    end = run_job(
        client, {"kind": "leaves-expand", "image": "photos/leaf0.png", "scribbles": "photos/leaf0_scribbles.png"}
    )
    assert end["outputs"] == ["photos/leaf0_scribbles_layers.png"]
    rgba = io.read_image(project.root / "photos" / "leaf0_scribbles_layers.png")
    assert rgba.shape == (H, W, 4)
    # the file is itself scribbles; its colours are the page's, layer by layer
    colours = [tuple(int(c[i : i + 2], 16) for i in (1, 3, 5)) for c in LAYER_COLOURS[:3]]
    u8 = np.round(rgba[..., :3] * 255).astype(int)
    for k, col in enumerate(colours, start=1):
        got = (u8 == col).all(axis=2) & (rgba[..., 3] > 0.5)
        assert (got & (truth == k)).sum() > 0.8 * (truth == k).sum(), k  # most of the true layer k
    assert (rgba[..., 3][truth == 0] == 0).all()  # transparent off the leaf
    side = json.loads((project.root / "photos" / "leaf0_scribbles_layers.png.json").read_text())
    assert side["command"] == "studio leaves-expand"


def test_analyze_and_synthesize_write_the_model_new_leaves_and_a_sheet(client, project, leaf_files):
    client.put("/api/scribbles", params={"path": "sc.png"}, json=_label_map(leaf_files[1], 4))
    body = {"kind": "leaves-synthesize", "leaves": ["photos/leaf0.png", "photos/leaf1.png"], "scribbles": "sc.png",
            "count": 2, "points": 40, "seed": 5, "out": "results/oak"}  # fmt: skip
    end = run_job(client, body)
    assert end["outputs"] == ["results/oak/sheet.png", "results/oak/leaf_0000.png", "results/oak/leaf_0001.png"]
    model = leaves.LeafModel.load(project.root / "results" / "oak" / "model")
    assert model.n_exemplars == 2 and model.n_layers == 3
    for name in end["outputs"][1:]:
        leaf = io.read_image(project.root / name)
        assert leaf.shape[2] == 4 and leaf[..., 3].mean() > 0.3  # a leaf, cropped to itself
        assert json.loads((project.root / f"{name}.json").read_text())["parameters"]["leaf_seed"] > 0
    assert io.read_image(project.root / "results" / "oak" / "sheet.png").shape[0] >= 5 * 200  # 4 model rows + leaves
    assert (
        json.loads((project.root / "results" / "oak" / "model.json").read_text())["command"]
        == "studio leaves-synthesize"
    )
    r = client.post("/api/jobs", json=body)
    assert r.status_code == 409 and "already exists" in r.json()["detail"]


@pytest.mark.parametrize(
    ("body", "status", "words"),
    [
        ({"kind": "leaves-expand", "image": "photos/leaf0.png", "scribbles": "none.png"}, 404, "scribbles: no file"),
        ({"kind": "leaves-expand", "image": "photos/none.png", "scribbles": "sc.png"}, 404, "image: no file"),
        ({"kind": "leaves-expand", "image": "photos/bar.png", "scribbles": "sc.png"}, 422, "scribbles: expected"),
        ({"kind": "leaves-expand", "image": "photos/leaf0.png", "scribbles": "../sc.png"}, 400, "scribbles:"),
        ({"kind": "leaves-synthesize", "leaves": ["photos/leaf0.png"], "scribbles": "sc.png"}, 422, "at least two"),
        (
            {
                "kind": "leaves-synthesize",
                "leaves": ["photos/leaf0.png", "photos/leaf1.png"],
                "training": "photos/bar.png",
                "scribbles": "sc.png",
            },
            422,
            "training:",
        ),
        ({"kind": "leaves-synthesize", "leaves": [], "scribbles": "sc.png"}, 422, "leaves"),
        (
            {
                "kind": "leaves-synthesize",
                "leaves": ["photos/leaf0.png", "photos/leaf1.png"],
                "scribbles": "sc.png",
                "count": 0,
            },
            422,
            "count",
        ),
    ],
)
def test_bad_leaves_jobs_are_refused_before_they_are_queued(client, leaf_files, body, status, words):
    client.put("/api/scribbles", params={"path": "sc.png"}, json=_label_map(leaf_files[1], 4))
    r = client.post("/api/jobs", json=body)
    assert r.status_code == status and words in r.json()["detail"], r.text
    assert client.get("/api/jobs").json() == []
