"""Studio fixtures: a project folder with an object photo and a bark photo, and a test client."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

import phloem
from phloem.studio import Project, create_app

TOKEN = "test-token"


def bar_photo() -> np.ndarray:
    """An RGBA bar (rows 20..40, columns 10..150) with a random texture on a transparent background."""
    rng = np.random.default_rng(0)
    img = np.zeros((60, 160, 4), np.float32)
    img[20:41, 10:150, :3] = rng.random((21, 140, 3))
    img[20:41, 10:150, 3] = 1
    return img


@pytest.fixture
def project(tmp_path: Path) -> Project:
    root = tmp_path / "project"
    (root / "photos").mkdir(parents=True)
    phloem.io.write_image(root / "photos" / "bar.png", bar_photo())
    phloem.io.write_image(root / "photos" / "bark.png", phloem.data.bark()[:96, :96, :3])
    return Project(root, max_pixels=200_000, max_upload_bytes=300_000)


@pytest.fixture
def client(project: Project) -> Iterator[TestClient]:
    with TestClient(create_app(project, token=TOKEN, threads=1), headers={"X-Phloem-Token": TOKEN}) as c:
        yield c


def png_bytes(image: np.ndarray) -> bytes:
    from phloem import _files

    return _files.encode(Path("x.png"), image, 8)


def finish_job(client: TestClient, job_id: str) -> dict[str, object]:
    """The job's server-sent events until it ends; the last, with all of them under ``events``."""
    events = []
    with client.stream("GET", f"/api/jobs/{job_id}/events") as r:
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/event-stream")
        for line in r.iter_lines():
            if line.startswith("data: "):
                events.append(json.loads(line[6:]))
    assert events and events[-1]["state"] in ("done", "failed", "cancelled")
    return {"events": events, **events[-1]}


def run_job(client: TestClient, body: dict[str, object]) -> dict[str, object]:
    """Submit a job, follow it to its end and check that it is done; its last state."""
    r = client.post("/api/jobs", json=body)
    assert r.status_code == 202, r.text
    end = finish_job(client, r.json()["id"])
    assert end["state"] == "done", end["message"]
    return end


def tree_image(seed: int, crown_r: int = 40, trunk_w: int = 10, trunk_h: int = 50) -> np.ndarray:
    """A small RGBA tree: a leafy disk crown on a brown trunk standing on the bottom."""
    img = np.zeros((160, 120, 4), np.float32)
    top = 150 - trunk_h
    img[top:150, 60 - trunk_w // 2 : 60 + trunk_w // 2] = (0.4, 0.25, 0.1, 1)
    crown = np.zeros((160, 120), np.uint8)
    cv2.circle(crown, (60, top - crown_r + 8), crown_r, 1, -1)
    leaf = np.random.default_rng(seed).uniform(0.3, 0.8, (160, 120)).astype(np.float32)
    on = crown > 0
    img[on] = np.stack([0.1 * leaf[on], leaf[on], 0.2 * leaf[on], np.ones(on.sum(), np.float32)], -1)
    return img
