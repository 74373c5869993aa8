"""The studio's HTTP API with FastAPI's test client: every endpoint, the token, bad requests,
path traversal, oversized uploads."""

from __future__ import annotations

import base64
import json
import os
from pathlib import Path

import numpy as np
import pytest

import phloem
from phloem import bark, io
from phloem.strokes import StrokeSet

from .conftest import TOKEN, bar_photo, finish_job, png_bytes, run_job

STROKES = {
    "format": "phloem.strokes",
    "version": 1,
    "source_shape": [60, 160],
    "target_size": [100, 160],
    "pairs": [{"source": [[12, 30], [147, 30]], "target": [[20, 80], [60, 20], [120, 60]]}],
}


# -- token ------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "url", ["/", "/static/app.js", "/openapi.json", "/api/info", "/api/files", "/api/jobs", "/api/jobs/x/events"]
)
def test_every_request_needs_the_token(client, url):
    r = client.get(url, headers={"X-Phloem-Token": ""})
    assert r.status_code == 401 and "token: missing" in r.json()["detail"]
    r = client.get(url, headers={"X-Phloem-Token": "wrong"})
    assert r.status_code == 403 and "token: wrong" in r.json()["detail"]


def test_the_token_may_come_in_the_query(client):
    assert client.get(f"/api/info?token={TOKEN}", headers={"X-Phloem-Token": ""}).status_code == 200
    assert client.get("/api/info?token=nope", headers={"X-Phloem-Token": ""}).status_code == 403


def test_a_post_without_the_token_changes_nothing(client, project):
    r = client.put("/api/strokes?path=s.json", json=STROKES, headers={"X-Phloem-Token": "wrong"})
    assert r.status_code == 403 and not (project.root / "s.json").exists()


# -- page and API description -------------------------------------------------------------------
def test_the_page_carries_the_token_and_its_scripts(client):
    r = client.get("/")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    assert (
        r.headers["referrer-policy"] == "no-referrer"
        and "frame-ancestors 'none'" in r.headers["content-security-policy"]
    )
    assert f'content="{TOKEN}"' in r.text and f"static/app.js?token={TOKEN}" in r.text and "{{" not in r.text
    assert "EventSource" in client.get("/static/app.js").text
    assert client.get("/static/style.css").headers["content-type"].startswith("text/css")
    assert client.get("/static/index.html").status_code == 404  # only the listed assets, never the template


def test_openapi_describes_every_endpoint_and_the_job_kinds(client):
    doc = client.get("/openapi.json").json()
    assert {"/api/info", "/api/files", "/api/file", "/api/upload", "/api/strokes", "/api/labels", "/api/jobs",
            "/api/jobs/{job_id}", "/api/jobs/{job_id}/cancel", "/api/jobs/{job_id}/events"} <= set(doc["paths"])  # fmt: skip
    kinds = {"StrokesEditJob", "BarkLabelsJob", "BarkTextureJob"}
    assert kinds <= set(doc["components"]["schemas"])
    assert client.get("/docs").status_code == 404 and client.get("/redoc").status_code == 404  # CDN pages: off


def test_info_and_file_list(client, project):
    info = client.get("/api/info").json()
    assert (
        info["workspaces"] == ["strokes", "bark", "branching", "leaves", "trees", "textures"]
        and info["max_pixels"] == project.max_pixels
    )
    (project.root / ".hidden").mkdir()
    (project.root / ".hidden" / "x.png").write_bytes(b"")
    (project.root / "notes.txt").write_text("x")
    names = {f["path"]: f["kind"] for f in client.get("/api/files").json()}
    assert names == {"photos/bar.png": "image", "photos/bark.png": "image"}


def test_a_file_is_served_as_it_is(client, project):
    r = client.get("/api/file", params={"path": "photos/bar.png"})
    assert r.status_code == 200 and r.content == (project.root / "photos" / "bar.png").read_bytes()
    assert client.get("/api/file", params={"path": "photos/none.png"}).status_code == 404


# -- path traversal -----------------------------------------------------------------------------
BAD_NAMES = ["../outside.png", "photos/../../outside.png", "/etc/passwd.png", "photos//bar.png", ".hidden.png",
             "photos/./bar.png", "a\\..\\b.png", "", "x.png\x00.json", "%2e%2e/outside.png", "photos/bar.png/"]  # fmt: skip


@pytest.mark.parametrize("name", BAD_NAMES)
def test_names_outside_the_project_are_refused(client, project, name):
    (project.root.parent / "outside.png").write_bytes((project.root / "photos" / "bar.png").read_bytes())
    r = client.get("/api/file", params={"path": name})
    assert r.status_code == 400 and r.json()["detail"].startswith("path: "), r.text
    r = client.put("/api/strokes", params={"path": name}, json=STROKES)
    assert r.status_code == 400
    r = client.post("/api/upload", params={"path": name}, files={"file": ("a.png", png_bytes(bar_photo()))})
    assert r.status_code == 400
    assert sorted(p.name for p in project.root.parent.iterdir()) == ["outside.png", "project"]


def test_symbolic_links_out_of_the_project_are_refused(client, project):
    outside = project.root.parent / "outside"
    outside.mkdir()
    phloem.io.write_image(outside / "secret.png", bar_photo())
    os.symlink(outside, project.root / "link")
    os.symlink(outside / "secret.png", project.root / "photos" / "alias.png")
    for name in ("link/secret.png", "photos/alias.png"):
        r = client.get("/api/file", params={"path": name})
        assert r.status_code == 400 and "outside the project" in r.json()["detail"]
    r = client.put("/api/strokes", params={"path": "link/s.json"}, json=STROKES)
    assert r.status_code == 400 and not (outside / "s.json").exists()
    r = client.post("/api/jobs", json={"kind": "bark-labels", "image": "photos/alias.png"})
    assert r.status_code == 400
    assert "photos/alias.png" not in {f["path"] for f in client.get("/api/files").json()}


def test_the_scratch_folder_may_not_lead_out_of_the_project(client, project):
    outside = project.root.parent / "outside"
    outside.mkdir()
    os.symlink(outside, project.root / ".phloem-studio")
    r = client.post("/api/upload", params={"path": "x.png"}, files={"file": ("x.png", png_bytes(bar_photo()))})
    assert r.status_code == 400 and "plain folder" in r.json()["detail"]
    assert not list(outside.iterdir()) and not (project.root / "x.png").exists()


def test_a_suffix_the_endpoint_does_not_serve_is_refused(client, project):
    (project.root / "notes.txt").write_text("x")
    r = client.get("/api/file", params={"path": "notes.txt"})
    assert r.status_code == 400 and "must end in one of" in r.json()["detail"]


# -- uploads ------------------------------------------------------------------------------------
def test_an_uploaded_image_is_checked_and_saved(client, project):
    data = png_bytes(bar_photo())
    r = client.post("/api/upload", params={"path": "up/bar.png"}, files={"file": ("bar.png", data)})
    assert r.status_code == 200, r.text
    assert r.json() == {"path": "up/bar.png", "width": 160, "height": 60}
    assert (project.root / "up" / "bar.png").read_bytes() == data
    r = client.post("/api/upload", params={"path": "up/bar.png"}, files={"file": ("bar.png", data[:0] + data)})
    assert r.status_code == 409 and "already exists" in r.json()["detail"]
    other = png_bytes(bar_photo()[::-1])
    r = client.post("/api/upload", params={"path": "up/bar.png", "overwrite": "true"}, files={"file": ("b.png", other)})
    assert r.status_code == 200 and (project.root / "up" / "bar.png").read_bytes() == other
    assert not list((project.root / ".phloem-studio").iterdir())  # no temporary left behind


@pytest.mark.parametrize(
    ("data", "status", "words"),
    [
        (b"not an image at all", 422, "file:"),
        (png_bytes(np.zeros((600, 500), np.float32)), 422, "pixels"),  # 300 000 px > 200 000, a few KB
        (png_bytes(np.random.default_rng(0).random((300, 400, 3))), 413, "upload limit"),  # 120 000 px, >300 KB
    ],
    ids=["garbage", "too-many-pixels", "too-many-bytes"],
)
def test_bad_uploads_are_refused_and_nothing_is_written(client, project, data, status, words):
    r = client.post("/api/upload", params={"path": "x.png"}, files={"file": ("x.png", data)})
    assert r.status_code == status and words in r.json()["detail"], r.text
    assert not (project.root / "x.png").exists()


def test_a_truncated_png_is_refused(client, project):
    data = png_bytes(bar_photo())
    r = client.post("/api/upload", params={"path": "x.png"}, files={"file": ("x.png", data[: len(data) // 2])})
    assert r.status_code == 422 and not (project.root / "x.png").exists()


def test_a_declared_body_over_the_limit_is_refused_before_it_is_read(client):
    r = client.post("/api/upload?path=x.png", content=b"x" * 10, headers={"Content-Length": str(10**9)})
    assert r.status_code == 413 and "upload limit" in r.json()["detail"]


def test_an_upload_without_a_file_is_a_422_naming_it(client):
    r = client.post("/api/upload", params={"path": "x.png"})
    assert r.status_code == 422 and r.json()["detail"].startswith("file: ")


# -- strokes --------------------------------------------------------------------------------------
def test_strokes_are_written_as_the_cli_reads_them(client, project):
    r = client.put("/api/strokes", params={"path": "s/strokes.json"}, json=STROKES)
    assert r.status_code == 200, r.text
    on_disk = StrokeSet.load(project.root / "s" / "strokes.json")
    assert on_disk == StrokeSet.from_dict(STROKES)
    assert client.get("/api/strokes", params={"path": "s/strokes.json"}).json() == on_disk.to_dict()
    r = client.put("/api/strokes", params={"path": "s/strokes.json"}, json={**STROKES, "target_size": [200, 200]})
    assert r.status_code == 409
    assert StrokeSet.load(project.root / "s" / "strokes.json").target_size == (100, 160)
    r = client.put("/api/strokes", params={"path": "s/strokes.json", "overwrite": True}, json={**STROKES, "target_size": [200, 200]})  # fmt: skip
    assert r.status_code == 200 and StrokeSet.load(project.root / "s" / "strokes.json").target_size == (200, 200)


@pytest.mark.parametrize(
    ("doc", "words"),
    [
        ({**STROKES, "pairs": []}, "pairs"),
        ({**STROKES, "format": "other"}, "format"),
        ({**STROKES, "source_shape": [10, 10]}, "outside"),
        ({**STROKES, "pairs": [{"source": [[1, 1]], "target": [[1, 1], [5, 5]]}]}, "pairs[0]"),
    ],
)
def test_a_bad_stroke_document_is_a_422_and_writes_nothing(client, project, doc, words):
    r = client.put("/api/strokes", params={"path": "s.json"}, json=doc)
    assert r.status_code == 422 and words in r.json()["detail"], r.text
    assert not (project.root / "s.json").exists()


def test_a_body_that_is_not_json_is_a_422(client):
    r = client.put("/api/strokes?path=s.json", content=b"{oops", headers={"Content-Type": "application/json"})
    assert r.status_code == 422


def test_reading_a_bad_stroke_file_is_a_422(client, project):
    (project.root / "bad.json").write_text("[[[")
    assert client.get("/api/strokes", params={"path": "bad.json"}).status_code == 422
    assert client.get("/api/strokes", params={"path": "none.json"}).status_code == 404


# -- label maps ---------------------------------------------------------------------------------
def _labels_body(lab: np.ndarray, n: int) -> dict[str, object]:
    return {"width": lab.shape[1], "height": lab.shape[0], "n_labels": n,
            "data": base64.b64encode(lab.astype(np.uint8).tobytes()).decode()}  # fmt: skip


def test_a_painted_label_map_is_the_cli_s_grey_level_png(client, project):
    lab = np.zeros((20, 30), np.uint8)
    lab[5:15, 10:20] = 2
    lab[:, :3] = 1
    r = client.put("/api/labels", params={"path": "l.png"}, json=_labels_body(lab, 3))
    assert r.status_code == 200, r.text
    img = io.read_image(project.root / "l.png")
    assert img.ndim == 2 and set(np.unique(np.rint(img * 255))) == {0, 128, 255}
    assert np.array_equal(bark.decode_labels(img), lab)
    back = client.get("/api/labels", params={"path": "l.png"}).json()
    assert back["n_labels"] == 3 and base64.b64decode(back["data"]) == lab.tobytes()


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"data": "***"}, "base64"),
        ({"width": 31}, "bytes"),
        ({"n_labels": 2}, "label 2"),
        ({"n_labels": 17}, "n_labels"),
    ],
)
def test_bad_label_maps_are_refused(client, project, change, words):
    lab = np.zeros((20, 30), np.uint8)
    lab[0, 0] = 2
    r = client.put("/api/labels", params={"path": "l.png"}, json={**_labels_body(lab, 3), **change})
    assert r.status_code == 422 and words in r.json()["detail"], r.text
    assert not (project.root / "l.png").exists()


def test_a_photo_is_no_label_map(client):
    r = client.get("/api/labels", params={"path": "photos/bark.png"})
    assert r.status_code == 422 and "distinct colours" in r.json()["detail"]


# -- jobs ---------------------------------------------------------------------------------------
def test_a_strokes_job_streams_progress_and_writes_its_result_and_sidecar(client, project):
    client.put("/api/strokes", params={"path": "strokes.json"}, json=STROKES)
    r = client.post("/api/jobs", json={"kind": "strokes-edit", "image": "photos/bar.png", "strokes": "strokes.json",
                                       "out": "results/bent.png"})  # fmt: skip
    assert r.status_code == 202, r.text
    end = finish_job(client, r.json()["id"])
    assert end["state"] == "done", end["message"]
    assert end["outputs"] == ["results/bent.png"]
    assert any(e["total"] > 0 for e in end["events"])  # progress reached the stream
    out = io.read_image(project.root / "results" / "bent.png")
    assert out.shape == (100, 160, 4)
    alpha = out[..., 3] > 0.5
    assert alpha[20, 60] and alpha[40, 90] and not alpha[95, 5]  # along the bent target, not in a corner
    side = json.loads((project.root / "results" / "bent.png.json").read_text())
    assert side["command"] == "studio strokes-edit" and side["parameters"]["strokes"] == "strokes.json"
    assert client.get(f"/api/jobs/{r.json()['id']}").json()["state"] == "done"
    assert [j["id"] for j in client.get("/api/jobs").json()] == [r.json()["id"]]
    r = client.post("/api/jobs", json={"kind": "strokes-edit", "image": "photos/bar.png", "strokes": "strokes.json",
                                       "out": "results/bent.png"})  # fmt: skip
    assert r.status_code == 409 and "already exists" in r.json()["detail"]


def test_bark_labels_then_texture_from_the_painted_map(client, project):
    r = client.post("/api/jobs", json={"kind": "bark-labels", "image": "photos/bark.png", "n_labels": 2})
    assert r.status_code == 202, r.text
    end = finish_job(client, r.json()["id"])
    assert end["state"] == "done" and end["outputs"] == ["photos/bark_labels_in.png"]
    labels = client.get("/api/labels", params={"path": "photos/bark_labels_in.png"}).json()
    assert (labels["width"], labels["height"], labels["n_labels"]) == (96, 96, 2)
    lab = np.frombuffer(base64.b64decode(labels["data"]), np.uint8).reshape(96, 96).copy()
    lab[:, :48] = 0  # paint the left half with label 0
    assert client.put("/api/labels", params={"path": "photos/bark_labels_in.png", "overwrite": True},
                      json=_labels_body(lab, 2)).status_code == 200  # fmt: skip
    r = client.post("/api/jobs", json={"kind": "bark-texture", "image": "photos/bark.png", "n_labels": 2,
                                       "labels_in": "photos/bark_labels_in.png", "size": [48, 64], "out": "t.png"})  # fmt: skip
    end = finish_job(client, r.json()["id"])
    assert end["state"] == "done", end["message"]
    assert io.read_image(project.root / "t.png").shape == (48, 64, 3)
    assert (
        json.loads((project.root / "t.png.json").read_text())["parameters"]["labels_in"] == "photos/bark_labels_in.png"
    )


def test_a_texture_writes_its_new_label_map_which_painted_over_paints_the_next(client, project):
    """The output label map (phloem bark --keep-intermediates' OUT_labels_out.png) is a stage to edit:
    written beside the texture, read back as labels_out, whose shape sets the next texture's size."""
    end = run_job(client, {"kind": "bark-texture", "image": "photos/bark.png", "n_labels": 2, "size": [40, 56],
                           "out": "t.png"})  # fmt: skip
    assert end["outputs"] == ["t.png", "t_labels_out.png"]
    out_map = bark.decode_labels(io.read_image(project.root / "t_labels_out.png"))
    assert out_map.shape == (40, 56) and set(np.unique(out_map)) <= {0, 1}
    painted = np.zeros((40, 56), np.uint8)
    painted[:, 28:] = 1  # half and half
    client.put("/api/labels", params={"path": "t_labels_out.png", "overwrite": True}, json=_labels_body(painted, 2))
    end = run_job(client, {"kind": "bark-texture", "image": "photos/bark.png", "n_labels": 2, "size": [8, 8],
                           "labels_out": "t_labels_out.png", "out": "t2.png"})  # fmt: skip
    tex = io.read_image(project.root / "t2.png")
    assert tex.shape == (40, 56, 3)  # the painted map's size, not `size`
    assert abs(float(tex[:, :28].mean()) - float(tex[:, 28:].mean())) > 0.05  # its two halves differ, as painted
    assert json.loads((project.root / "t2.png.json").read_text())["parameters"]["labels_out"] == "t_labels_out.png"
    r = client.post("/api/jobs", json={"kind": "bark-texture", "image": "photos/bark.png", "size": [8, 8],
                                       "labels_out": "none.png"})  # fmt: skip
    assert r.status_code == 404 and "labels_out: no file" in r.json()["detail"]


@pytest.mark.parametrize(
    ("body", "status", "words"),
    [
        ({"kind": "nope"}, 422, "does not match"),
        ({"kind": "bark-labels"}, 422, "image: Field required"),
        ({"kind": "bark-labels", "image": "photos/bark.png", "n_labels": 99}, 422, "n_labels"),
        ({"kind": "bark-texture", "image": "photos/bark.png", "size": [0, 5]}, 422, "size"),
        ({"kind": "bark-texture", "image": "photos/none.png", "size": [8, 8]}, 404, "image: no file"),
        (
            {"kind": "bark-texture", "image": "photos/bark.png", "labels_in": "photos/bar.png", "size": [8, 8]},
            422,
            "labels_in",
        ),
        ({"kind": "strokes-edit", "image": "photos/bar.png", "strokes": "none.json"}, 404, "strokes: no file"),
        ({"kind": "bark-labels", "image": "photos/bark.png", "out": "x.txt"}, 400, "out:"),
    ],
)
def test_bad_jobs_are_refused_before_they_are_queued(client, body, status, words):
    r = client.post("/api/jobs", json=body)
    assert r.status_code == status and words in r.json()["detail"], r.text
    assert client.get("/api/jobs").json() == []


def test_unknown_jobs_are_404(client):
    for r in (client.get("/api/jobs/abc"), client.post("/api/jobs/abc/cancel"), client.get("/api/jobs/abc/events")):
        assert r.status_code == 404 and "job_id" in r.json()["detail"]


def test_a_failing_request_leaves_the_server_serving(client):
    for _ in range(3):
        assert client.get("/api/labels", params={"path": "photos/bark.png"}).status_code == 422
    assert client.get("/api/info").status_code == 200


def test_project_must_be_a_folder(tmp_path: Path):
    from phloem.studio import Project

    with pytest.raises(ValueError, match="project: .* is not a folder"):
        Project(tmp_path / "none")


def test_jobs_and_uploads_are_held_to_the_project_s_memory_limit(project):
    from fastapi.testclient import TestClient

    from phloem.studio import Project, create_app

    small = Project(project.root, max_memory=2**20)  # 1 MiB: the 96² photo decodes, a 2048² texture does not
    with TestClient(create_app(small, token=TOKEN), headers={"X-Phloem-Token": TOKEN}) as c:
        r = c.post(
            "/api/jobs",
            json={"kind": "bark-texture", "image": "photos/bark.png", "size": [2048, 2048], "out": "big.png"},
        )
        end = finish_job(c, r.json()["id"])
        assert end["state"] == "failed" and "size: 2048×2048" in end["message"] and "memory limit" in end["message"]
        assert not (project.root / "big.png").exists()
        big = png_bytes(np.zeros((300, 300), np.float32))  # 90 000 px: under the pixel limit, over 1 MiB decoded
        r = c.post("/api/upload", params={"path": "big.png"}, files={"file": ("big.png", big)})
        assert r.status_code == 413 and "memory limit" in r.json()["detail"]
