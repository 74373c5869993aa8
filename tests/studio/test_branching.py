"""The branching workspace's API: skeleton and guide files as the CLI reads them, trace, grow
and render jobs with sidecars, interactive extension (§6) and the Fig. 7 histograms; bad requests."""

from __future__ import annotations

import base64
import json

import numpy as np
import pytest

from phloem import branching, io
from phloem.metrics import joined_end_share
from phloem.testing import channel_scene

from .conftest import run_job

SKELETON = {
    "format": "phloem.skeleton",
    "version": 1,
    "shape": [128, 224],
    "branches": [
        {"points": [[10, 60], [60, 62], [110, 58], [160, 64], [210, 60]], "thickness": 3.0, "parent": None},
        {"points": [[60, 62], [80, 90], [100, 115]], "thickness": [2.0, 2.0, 1.5], "parent": [0, 1]},
    ],
}


@pytest.fixture
def scene(project):
    img, sk = channel_scene(0)
    io.write_image(project.root / "photos" / "channel.png", img)
    sk.save(project.root / "channel.json")
    return img, sk


def test_a_skeleton_is_written_as_the_cli_reads_it_and_read_back(client, project):
    r = client.put("/api/skeleton", params={"path": "edited/sk.json"}, json=SKELETON)
    assert r.status_code == 200 and r.json()["path"] == "edited/sk.json"
    sk = branching.Skeleton.load(project.root / "edited" / "sk.json")
    assert sk.shape == (128, 224) and sk.branches[1].parent == (0, 1)
    assert np.allclose(sk.branches[0].thickness, 3.0) and sk.branches[1].points[2].tolist() == [100, 115]
    assert client.get("/api/skeleton", params={"path": "edited/sk.json"}).json() == sk.to_dict()
    r = client.put("/api/skeleton", params={"path": "edited/sk.json"}, json=SKELETON)
    assert r.status_code == 409 and "overwrite=true" in r.json()["detail"]
    assert (
        client.put("/api/skeleton", params={"path": "edited/sk.json", "overwrite": True}, json=SKELETON).status_code
        == 200
    )


@pytest.mark.parametrize(
    ("change", "words"),
    [
        (lambda d: d["branches"][1].update(parent=[1, 0]), "must refer to an earlier branch"),
        (lambda d: d["branches"][1].update(parent=[0, 9]), "vertex 9 is outside branch 0"),
        (lambda d: d["branches"][0].update(points=[[10, 60], [500, 60]]), "outside the 224x128 image"),
        (lambda d: d.update(branches=[]), "non-empty list"),
        (lambda d: d.update(format="phloem.strokes"), "format"),
        (lambda d: d["branches"][0].update(points="no"), "branches[0]"),
    ],
)
def test_a_bad_skeleton_is_a_422_naming_the_problem_and_writes_nothing(client, project, change, words):
    doc = json.loads(json.dumps(SKELETON))
    change(doc)
    r = client.put("/api/skeleton", params={"path": "bad.json"}, json=doc)
    assert r.status_code == 422 and words in r.json()["detail"], r.text
    assert not (project.root / "bad.json").exists()


@pytest.mark.parametrize("name", ["../x.json", "/etc/x.json", "a/../../x.json", ".hidden.json", "x.png"])
def test_skeleton_and_guide_names_outside_the_project_are_refused(client, project, name):
    for url, body in (("/api/skeleton", SKELETON), ("/api/guide", [[1, 2], [3, 4]])):
        r = client.put(url, params={"path": name}, json=body)
        assert r.status_code == 400 and r.json()["detail"].startswith("path:"), r.text
        assert client.get(url, params={"path": name}).status_code == 400
    assert not list(project.root.parent.glob("x.*"))


def test_a_missing_or_broken_skeleton_file_is_a_4xx(client, project):
    assert client.get("/api/skeleton", params={"path": "none.json"}).status_code == 404
    (project.root / "broken.json").write_text("{not json")
    r = client.get("/api/skeleton", params={"path": "broken.json"})
    assert r.status_code == 422 and "broken.json" in r.json()["detail"]


def test_a_guide_is_the_cli_s_json_list_of_points(client, project):
    r = client.put("/api/guide", params={"path": "guide.json"}, json=[[10, 20], [100.5, 40], [200, 90]])
    assert r.status_code == 200
    assert json.loads((project.root / "guide.json").read_text()) == [[10, 20], [100.5, 40], [200, 90]]
    assert client.get("/api/guide", params={"path": "guide.json"}).json() == [[10, 20], [100.5, 40], [200, 90]]
    for bad in ([[1, 2]], [[1, 2, 3], [4, 5]], "x", [[1, "a"], [2, 3]]):
        assert client.put("/api/guide", params={"path": "g2.json"}, json=bad).status_code == 422
    (project.root / "g3.json").write_text('{"a": 1}')
    r = client.get("/api/guide", params={"path": "g3.json"})
    assert r.status_code == 422 and "at least two [x, y] points" in r.json()["detail"]


def test_trace_then_grow_then_render_write_the_cli_s_files_with_sidecars(client, project, scene):
    end = run_job(client, {"kind": "branching-trace", "image": "photos/channel.png"})
    assert end["outputs"] == ["photos/channel_skeleton.json"]
    traced = branching.Skeleton.load(project.root / "photos" / "channel_skeleton.json")
    assert traced.shape == (128, 224) and traced.total_length() > 150  # the channel is 210 px long
    side = json.loads((project.root / "photos" / "channel_skeleton.sidecar.json").read_text())
    assert side["command"] == "studio branching-trace" and side["parameters"]["image"] == "photos/channel.png"
    assert side["parameters"]["subpixel"] is False

    client.put("/api/guide", params={"path": "guide.json"}, json=[[10, 100], [210, 100]])
    grow = {"kind": "branching-grow", "skeleton": "channel.json", "guide": "guide.json", "seed": 3, "out": "grown.json"}
    end = run_job(client, grow)
    grown = branching.Skeleton.load(project.root / "grown.json")
    assert end["outputs"] == ["grown.json"] and grown.shape == (128, 224) and grown.total_length() > 50
    side = json.loads((project.root / "grown.sidecar.json").read_text())
    assert side["seed"] == 3 and side["parameters"]["guide"] == "guide.json" and side["parameters"]["h"] > 0
    # the command line's course-keeping defaults, resolved for the example and recorded
    course = branching.course_defaults(branching.Skeleton.load(project.root / "channel.json"))
    assert (side["parameters"]["total_turn"], side["parameters"]["repel_border"]) == course
    assert side["parameters"]["turn_bound"] == (5.0 if course[0] > 0 else 0.0)
    edges = branching.course_edges_default(branching.Skeleton.load(project.root / "channel.json"))
    assert (side["parameters"]["course"] == 0) == (edges == 0)  # resolved for the example and recorded
    channel = branching.Skeleton.load(project.root / "channel.json")
    # a guide says which way the structure runs, so the heading on the image is not matched
    assert branching.orientation_default(channel) == 3.0 and side["parameters"]["orientation"] == 0.0
    assert side["parameters"]["direction_histogram"] == 0.0
    assert side["parameters"]["joined_ends"] == joined_end_share(channel)
    again = run_job(client, {**grow, "out": "grown2.json"})
    assert branching.Skeleton.load(project.root / again["outputs"][0]) == grown  # one seed, one structure

    end = run_job(client, {"kind": "branching-render", "image": "photos/channel.png", "skeleton": "channel.json",
                        "target": "grown.json", "out": "results/new.png"})  # fmt: skip
    out = io.read_image(project.root / "results" / "new.png")
    assert out.shape[:2] == (128, 224) and out.std() > 0.02
    on = grown.mask()
    assert out[on].mean() < out[~on].mean() - 0.1  # the dark channel painted along the grown skeleton
    assert json.loads((project.root / "results" / "new.png.json").read_text())["parameters"]["target"] == "grown.json"
    assert end["outputs"] == ["results/new.png", "results/new_fragments.png"]
    frag = io.read_image(project.root / "results" / "new_fragments.png")
    assert frag.shape == (128, 224, 3) and len(np.unique(frag.reshape(-1, 3), axis=0)) > 3  # several fragments


def test_trace_subpixel_reaches_trace_and_the_sidecar(client, project, scene, monkeypatch):
    seen = []
    real = branching.trace
    monkeypatch.setattr(branching, "trace", lambda *a, **k: seen.append(k.get("subpixel")) or real(*a, **k))
    run_job(client, {"kind": "branching-trace", "image": "photos/channel.png", "subpixel": True, "out": "fine.json"})
    assert seen == [True]
    assert json.loads((project.root / "fine.sidecar.json").read_text())["parameters"]["subpixel"] is True


@pytest.mark.parametrize("switch", ["wide", "edges"])
def test_trace_on_by_default_switches_reach_trace_and_the_sidecar(client, project, scene, monkeypatch, switch):
    seen = []
    real = branching.trace
    monkeypatch.setattr(branching, "trace", lambda *a, **k: seen.append(k.get(switch)) or real(*a, **k))
    run_job(client, {"kind": "branching-trace", "image": "photos/channel.png", "out": "on.json"})
    run_job(client, {"kind": "branching-trace", "image": "photos/channel.png", switch: False, "out": "off.json"})
    assert seen == [True, False]
    assert json.loads((project.root / "off.sidecar.json").read_text())["parameters"][switch] is False


def test_trace_threshold_reaches_trace_and_the_sidecar(client, project, scene, monkeypatch):
    seen = []
    real = branching.trace
    monkeypatch.setattr(branching, "trace", lambda *a, **k: seen.append(k.get("threshold")) or real(*a, **k))
    run_job(client, {"kind": "branching-trace", "image": "photos/channel.png", "out": "auto.json"})
    run_job(client, {"kind": "branching-trace", "image": "photos/channel.png", "threshold": 0.05, "out": "set.json"})
    assert seen == [None, 0.05]
    assert json.loads((project.root / "set.sidecar.json").read_text())["parameters"]["threshold"] == 0.05


def test_trace_threshold_scale_reaches_trace_and_the_sidecar(client, project, scene, monkeypatch):
    seen = []
    real = branching.trace
    monkeypatch.setattr(branching, "trace", lambda *a, **k: seen.append(k.get("threshold_scale")) or real(*a, **k))
    run_job(client, {"kind": "branching-trace", "image": "photos/channel.png", "out": "auto.json"})
    body = {"kind": "branching-trace", "image": "photos/channel.png", "threshold_scale": 0.5, "out": "set.json"}
    run_job(client, body)
    assert seen == [1.0, 0.5]
    assert json.loads((project.root / "set.sidecar.json").read_text())["parameters"]["threshold_scale"] == 0.5


def test_trace_gap_and_root_reach_trace_and_the_sidecar(client, project, scene, monkeypatch):
    seen = []
    real = branching.trace
    monkeypatch.setattr(branching, "trace", lambda *a, **k: seen.append((k.get("gap"), k.get("root"))) or real(*a, **k))
    run_job(client, {"kind": "branching-trace", "image": "photos/channel.png", "out": "auto.json"})
    body = {"kind": "branching-trace", "image": "photos/channel.png", "gap": 12.5, "root": [3, 40], "out": "set.json"}
    run_job(client, body)
    assert seen[0] == (None, None) and seen[1][0] == 12.5 and tuple(seen[1][1]) == (3, 40)
    params = json.loads((project.root / "set.sidecar.json").read_text())["parameters"]
    assert params["gap"] == 12.5 and params["root"] == [3, 40]


def test_several_guide_paths_are_a_mask_the_structure_follows(client, project, scene):
    """The page saves two or more guide paths as a mask (PUT /api/mask), which --guide also takes."""
    mask = np.zeros((128, 224), np.uint8)
    mask[20:24, 10:214] = 1  # a path along the top, one along the bottom
    mask[104:108, 10:214] = 1
    body = {"width": 224, "height": 128, "n_labels": 2,
            "data": base64.b64encode(mask.tobytes()).decode()}  # fmt: skip
    assert client.put("/api/mask", params={"path": "guides.png"}, json=body).status_code == 200
    shares = []
    for seed in (1, 2, 3):  # a stem can leave its path before the guide's look-up reaches it
        end = run_job(client, {"kind": "branching-grow", "skeleton": "channel.json", "guide": "guides.png",
                               "seed": seed, "out": f"guided{seed}.json"})  # fmt: skip
        grown = branching.Skeleton.load(project.root / end["outputs"][0])
        pts = np.vstack([b.points for b in grown.branches])
        shares.append(((np.abs(pts[:, 1] - 22) < 15) | (np.abs(pts[:, 1] - 106) < 15)).mean())
    assert np.median(shares) > 0.5, shares  # most of the structure runs along the two paths
    io.write_image(project.root / "blank.png", np.zeros((128, 224), np.float32))
    for name, words in (
        ("photos/bar.png", "is 160×60, but the new structure is 224×128"),
        ("blank.png", "marks no path"),
    ):
        r = client.post("/api/jobs", json={"kind": "branching-grow", "skeleton": "channel.json", "guide": name})
        assert r.status_code == 422 and words in r.json()["detail"], r.text


@pytest.mark.parametrize(
    ("body", "status", "words"),
    [
        ({"kind": "branching-trace", "image": "photos/none.png"}, 404, "image: no file"),
        ({"kind": "branching-trace", "image": "photos/bar.png", "out": "x.png"}, 400, "must end in one of .json"),
        ({"kind": "branching-trace", "image": "photos/bar.png", "sigmas": []}, 422, "sigmas"),
        ({"kind": "branching-trace", "image": "photos/bar.png", "subpixel": "maybe"}, 422, "subpixel"),
        ({"kind": "branching-trace", "image": "photos/bar.png", "wide": "maybe"}, 422, "wide"),
        ({"kind": "branching-trace", "image": "photos/bar.png", "edges": "maybe"}, 422, "edges"),
        ({"kind": "branching-trace", "image": "photos/bar.png", "threshold": "high"}, 422, "threshold"),
        ({"kind": "branching-trace", "image": "photos/bar.png", "threshold_scale": 0}, 422, "threshold_scale"),
        ({"kind": "branching-trace", "image": "photos/bar.png", "gap": -1}, 422, "gap"),
        ({"kind": "branching-trace", "image": "photos/bar.png", "root": [1]}, 422, "root"),
        ({"kind": "branching-trace", "image": "../bar.png"}, 400, "image:"),
        ({"kind": "branching-grow", "skeleton": "none.json"}, 404, "skeleton: no file"),
        ({"kind": "branching-grow", "skeleton": "channel.json", "guide": "none.json"}, 404, "guide: no file"),
        ({"kind": "branching-grow", "skeleton": "channel.json", "size": [0, 10]}, 422, "size"),
        ({"kind": "branching-grow", "skeleton": "channel.json", "layout": -1}, 422, "layout"),
        ({"kind": "branching-grow", "skeleton": "photos/bar.png"}, 400, "skeleton:"),
        ({"kind": "branching-grow", "skeleton": "channel.json", "size": [8000, 8000]}, 422, "over the pixel limit"),
        (
            {
                "kind": "branching-render",
                "image": "photos/channel.png",
                "skeleton": "channel.json",
                "target": "channel.json",
                "out": "photos/channel.png",
            },
            409,
            "already exists",
        ),
    ],
)
def test_bad_branching_jobs_are_refused_before_they_are_queued(client, scene, body, status, words):
    r = client.post("/api/jobs", json=body)
    assert r.status_code == status and words in r.json()["detail"], r.text
    assert client.get("/api/jobs").json() == []


def test_a_branch_is_extended_at_its_tip_and_nothing_is_written(client, project, scene):
    before = set(project.root.rglob("*"))
    _, sk = scene
    doc = sk.to_dict()
    r = client.post("/api/skeleton/extend", json={"skeleton": doc, "branch": 1, "steps": 2, "seed": 1})
    assert r.status_code == 200, r.text
    new = branching.Skeleton.from_dict(r.json())
    assert len(new.branches[1]) > len(sk.branches[1]) and np.array_equal(new.branches[0].points, sk.branches[0].points)
    assert np.allclose(new.branches[1].points[len(sk.branches[1]) - 1], sk.branches[1].points[-1])  # grown from the tip
    r2 = client.post("/api/skeleton/extend", json={"skeleton": doc, "branch": 1, "steps": 2, "seed": 1,
                                                   "example": "channel.json"})  # fmt: skip
    assert r2.status_code == 200
    assert set(project.root.rglob("*")) == before
    for body, words in (({"skeleton": doc, "branch": 5}, "branch: expected 0 .. 1"),
                        ({"skeleton": {**doc, "shape": None}, "branch": 0}, "no shape"),
                        ({"skeleton": {**doc, "shape": [100_000, 100_000]}, "branch": 0}, "over the pixel limit"),
                        ({"skeleton": {"format": "x"}, "branch": 0}, "format"),
                        ({"skeleton": doc, "branch": 0, "example": "none.json"}, "example: no file")):  # fmt: skip
        r = client.post("/api/skeleton/extend", json=body)
        assert 400 <= r.status_code < 500 and words in r.json()["detail"], r.text


def test_histograms_compare_the_example_and_the_grown_skeleton(client, project, scene):
    _, sk = scene
    r = client.get("/api/histograms", params={"source": "channel.json", "result": "channel.json", "bins": 8})
    assert r.status_code == 200, r.text
    h = r.json()
    for key in ("angle", "thickness"):
        assert len(h[key]["source"]) == 8 and len(h[key]["edges"]) == 9
        assert h[key]["source"] == h[key]["result"] and h[key]["distance"] == 0
        assert abs(sum(h[key]["source"]) - 1) < 1e-9
    ha, _ = branching.angle_histogram(sk, 8, h=h["h"])
    assert np.allclose(h["angle"]["source"], ha) and h["h"] == branching.default_h(sk)
    thin = branching.Skeleton([branching.Branch(b.points, b.thickness * 0.3, b.parent) for b in sk.branches], sk.shape)
    thin.save(project.root / "thin.json")
    h = client.get("/api/histograms", params={"source": "channel.json", "result": "thin.json"}).json()
    assert h["thickness"]["distance"] > 1.0 and h["thickness"]["result"][0] == 1.0  # all below the example's range
    assert client.get("/api/histograms", params={"source": "none.json", "result": "thin.json"}).status_code == 404
    assert (
        client.get("/api/histograms", params={"source": "channel.json", "result": "thin.json", "bins": 0}).status_code
        == 422
    )


def test_grow_takes_the_examples_layout_and_records_it(client, project, scene):
    # wavy branches leaving a centre every way: a layout (the channel scene's one river has none)
    rng = np.random.default_rng(0)
    brs = []
    for j in range(16):
        a = 2 * np.pi * j / 16
        brs.append(branching.Branch.from_angles([100 + 15 * np.cos(a), 100 - 15 * np.sin(a)], a,
                                                rng.normal(0, 0.1, 30), np.full(32, 1.5), 2.0))  # fmt: skip
    branching.Skeleton(brs, (200, 200)).save(project.root / "fan.json")
    grown = {}
    for weight in (0.0, 1.0):
        end = run_job(client, {"kind": "branching-grow", "skeleton": "fan.json", "seed": 1, "layout": weight,
                               "out": f"fan{weight:g}.json"})  # fmt: skip
        grown[weight] = branching.Skeleton.load(project.root / end["outputs"][0])
    assert grown[0.0] != grown[1.0]
    assert json.loads((project.root / "fan1.sidecar.json").read_text())["parameters"]["layout"] == 1.0
    # left out, the example decides: sixteen separate branches are a forest (off), the
    # channel scene's one river a connected structure (on); the sidecar records the weight used
    for name, used in (("fan", 0.0), ("channel", 1.0)):
        run_job(client, {"kind": "branching-grow", "skeleton": f"{name}.json", "seed": 1, "out": f"{name}-auto.json"})
        assert json.loads((project.root / f"{name}-auto.sidecar.json").read_text())["parameters"]["layout"] == used
