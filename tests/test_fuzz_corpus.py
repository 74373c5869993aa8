"""The committed fuzz corpus as a regression suite: every target's ``TestOneInput`` once per corpus file.

Runs without atheris (the targets import it only when they fuzz). A file here that fails is a
parser that regressed on an input it once handled; see ``fuzz/README.md``.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path
from types import ModuleType

import pytest

FUZZ = Path(__file__).resolve().parents[1] / "fuzz"
TARGETS = sorted(p.stem.removeprefix("fuzz_") for p in FUZZ.glob("fuzz_*.py"))
CASES = [(t, f) for t in TARGETS for f in sorted((FUZZ / "corpus" / t).iterdir())]


def _target(name: str) -> ModuleType:
    if str(FUZZ) not in sys.path:
        sys.path.insert(0, str(FUZZ))
    return importlib.import_module(f"fuzz_{name}")


def test_every_target_has_seeds() -> None:
    assert TARGETS == ["guide", "image", "label_map", "mask", "skeleton", "strokes", "svg", "trunk_model"]
    for t in TARGETS:
        assert len(list((FUZZ / "corpus" / t).iterdir())) >= 3, t


@pytest.mark.parametrize(("target", "path"), CASES, ids=[f"{t}/{f.name}" for t, f in CASES])
def test_corpus_file(target: str, path: Path) -> None:
    _target(target).TestOneInput(path.read_bytes())
