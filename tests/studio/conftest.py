"""Studio fixtures: a project folder with an object photo and a bark photo, and a test client."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

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
