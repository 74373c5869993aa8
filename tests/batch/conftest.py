"""Fixtures of the batch tests: a small, fast job (32×32 synthesis from the embedded brick) and
one 2-worker LocalCluster shared by the tests that do not need a cluster of their own."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

import phloem.data

pytest.importorskip("distributed")


def write_spec(folder: Path, seeds: Any = "0..19", inputs: Any = None, **params: Any) -> Path:
    """A JSON spec in ``folder``: 32×32 syntheses of the brick, one iteration per level."""
    spec = {
        "job": "synthesize",
        "inputs": inputs if inputs is not None else [phloem.data.path("brick.png")],
        "params": {"size": "32x32", "iterations": 1, **params},
        "seeds": seeds,
    }
    path = folder / "spec.json"
    path.write_text(json.dumps(spec))
    return path


def outputs(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` but the manifest, by relative path."""
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.name != "manifest.jsonl"
    }


@pytest.fixture(scope="module")
def client() -> Iterator[Any]:
    from distributed import Client

    from phloem.batch import local_cluster

    with local_cluster(2) as cluster, Client(cluster) as c:
        yield c
