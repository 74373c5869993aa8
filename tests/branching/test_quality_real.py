"""Issue 19's acceptance test: ``synthesize`` with its defaults on the real branching inputs
makes images that show their target skeleton, hold together, keep a course and stay masks.

Each case runs benches/quality/branching_quality.py's ``evaluate`` (up to a minute on the mouse
brain vessels): ``pytest -m slow tests/branching/test_quality_real.py``.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

from phloem.testing import TRACE_SETTINGS, shared_file

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location(
    "_branching_quality", ROOT / "benches" / "quality" / "branching_quality.py"
)
assert _spec is not None and _spec.loader is not None
bench = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = bench  # dataclasses look their module up by name
_spec.loader.exec_module(bench)


@pytest.mark.slow
@pytest.mark.shared
@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("name", sorted(TRACE_SETTINGS))
def test_synthesize_defaults_look_like_the_input(name: str, seed: int) -> None:
    img, mask = bench.load(shared_file("branching", name))
    r = bench.evaluate(name, img, mask, seed, threads=2)
    assert not r.error, r.error
    assert r.f1 >= bench.F1_MIN, f"re-trace F1 {r.f1:.2f} (precision {r.precision:.2f}, recall {r.recall:.2f})"
    assert abs(r.share_out - r.share_in) <= bench.SHARE_TOL, f"largest-tree share {r.share_in:.2f} -> {r.share_out:.2f}"
    assert r.drift <= bench.DRIFT_MAX, (
        f"drift L1 {r.drift:.2f} (median heading change {r.heading_in:.2f} -> {r.heading_out:.2f})"
    )
    if mask:
        assert r.two_level >= bench.TWO_LEVEL_MIN, f"two-level fraction {r.two_level:.3f}"
    assert r.angle < 1.5 * r.angle_spread, f"angle histogram distance {r.angle:.2f}, input spread {r.angle_spread:.2f}"
    assert r.thickness < r.thickness_spread, (
        f"thickness distance {r.thickness:.2f}, input spread {r.thickness_spread:.2f}"
    )
