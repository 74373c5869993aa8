"""The textures and trees workspaces' API: a painted mask as the PNG ``phloem complete`` reads,
synthesis, quilting (with its source map) and hole filling jobs, tree variations from a library
folder; bad requests."""

from __future__ import annotations

import base64
import json

import numpy as np
import pytest

import phloem
from phloem import io

from .conftest import run_job, tree_image


def _mask_body(mask: np.ndarray) -> dict[str, object]:
    h, w = mask.shape
    data = base64.b64encode(mask.astype(np.uint8).tobytes()).decode()
    return {"width": w, "height": h, "n_labels": 2, "data": data}


def test_a_painted_mask_is_white_where_pixels_are_filled_then_the_hole_is_filled(client, project):
    mask = np.zeros((96, 96), np.uint8)
    mask[30:50, 30:60] = 1
    r = client.put("/api/mask", params={"path": "photos/bark_mask.png"}, json=_mask_body(mask))
    assert r.status_code == 200, r.text
    written = io.read_image(project.root / "photos" / "bark_mask.png")
    assert written.ndim == 2 and (written[mask > 0] == 1).all() and (written[mask == 0] == 0).all()
    end = run_job(client, {"kind": "texture-complete", "image": "photos/bark.png", "mask": "photos/bark_mask.png",
                           "out": "results/filled.png"})  # fmt: skip
    assert end["outputs"] == ["results/filled.png"]
    before, after = (
        io.read_image(project.root / "photos" / "bark.png"),
        io.read_image(project.root / "results" / "filled.png"),
    )
    assert np.array_equal(after[mask == 0], before[mask == 0])  # only the hole changes
    assert after[mask > 0].std() > 0.02 and not np.allclose(after[mask > 0], 0)  # filled with texture, not black
    assert (
        json.loads((project.root / "results" / "filled.png.json").read_text())["parameters"]["mask"]
        == "photos/bark_mask.png"
    )


def test_synthesis_and_quilting_write_textures_and_quilting_its_source_map(client, project):
    end = run_job(client, {"kind": "texture-synthesize", "image": "photos/bark.png", "size": [48, 64], "seed": 2})
    assert io.read_image(project.root / end["outputs"][0]).shape == (48, 64, 3)
    end = run_job(client, {"kind": "texture-quilt", "image": "photos/bark.png", "size": [120, 140], "out": "q.png"})
    assert end["outputs"] == ["q.png", "q_sources.png"]
    assert io.read_image(project.root / "q.png").shape == (120, 140, 3)
    src = io.read_image(project.root / "q_sources.png")
    assert src.shape == (120, 140, 3) and src[..., 0].max() <= 1 and len(np.unique(np.round(src[..., 0], 2))) > 20
    assert json.loads((project.root / "q_sources.png.json").read_text())["command"] == "studio texture-quilt"


@pytest.mark.parametrize(
    ("body", "status", "words"),
    [
        ({"kind": "texture-complete", "image": "photos/bark.png", "mask": "none.png"}, 404, "mask: no file"),
        (
            {"kind": "texture-complete", "image": "photos/bark.png", "mask": "photos/bar.png"},
            422,
            "mask: photos/bar.png is 160×60",
        ),
        ({"kind": "texture-complete", "image": "photos/bark.png", "mask": "black.png"}, 422, "marks no pixel"),
        ({"kind": "texture-synthesize", "image": "photos/bark.png", "size": [0, 8]}, 422, "size"),
        ({"kind": "texture-quilt", "image": "photos/bark.png", "size": [8000, 8000]}, 422, "over the pixel limit"),
        ({"kind": "texture-quilt", "image": "../bark.png", "size": [8, 8]}, 400, "image:"),
        ({"kind": "trees-variations", "library": "none"}, 404, "library: no folder"),
        ({"kind": "trees-variations", "library": "photos"}, 422, "no alpha channel"),
        ({"kind": "trees-variations", "library": "../x"}, 400, "library:"),
        ({"kind": "trees-variations", "library": "photos", "count": 0}, 422, "count"),
    ],
)
def test_bad_texture_and_tree_jobs_are_refused_before_they_are_queued(client, project, body, status, words):
    io.write_image(project.root / "black.png", np.zeros((96, 96), np.float32))
    r = client.post("/api/jobs", json=body)
    assert r.status_code == status and words in r.json()["detail"], r.text
    assert client.get("/api/jobs").json() == []


def test_bad_masks_are_refused(client, project):
    body = _mask_body(np.ones((10, 10), np.uint8))
    assert client.put("/api/mask", params={"path": "../m.png"}, json=body).status_code == 400
    assert client.put("/api/mask", params={"path": "m.jpg"}, json=body).status_code == 400
    assert client.put("/api/mask", params={"path": "m.png"}, json={**body, "width": 9}).status_code == 422
    assert not (project.root / "m.png").exists()


def test_tree_variations_are_written_with_sidecars_naming_their_exemplars(client, project):
    (project.root / "trees").mkdir()
    for i, kw in enumerate(({}, {"crown_r": 30, "trunk_w": 14, "trunk_h": 60}, {"crown_r": 50, "trunk_w": 8})):
        io.write_image(project.root / "trees" / f"t{i}.png", tree_image(i, **kw))
    end = run_job(client, {"kind": "trees-variations", "library": "trees", "count": 2, "size": 128, "out": "new"})
    assert end["outputs"] == ["new/tree_0000.png", "new/tree_0001.png"]
    for name in end["outputs"]:
        img = io.read_image(project.root / name)
        assert img.shape == (128, 128, 4) and 0.1 < img[..., 3].mean() < 0.9
        side = json.loads((project.root / f"{name}.json").read_text())
        assert set(side["parameters"]["exemplars"]) <= {"t0.png", "t1.png", "t2.png"}
        assert abs(sum(side["parameters"]["weights"]) - 1) < 1e-4
    assert phloem.io.read_image(project.root / "new" / "tree_0000.png").dtype == np.float32
