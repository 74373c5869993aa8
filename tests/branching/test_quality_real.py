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
    # every mark that fails, in one message, so one run says all that is wrong
    fails = []
    if not r.f1 >= bench.F1_MIN:
        fails.append(f"re-trace F1 {r.f1:.2f} (precision {r.precision:.2f}, recall {r.recall:.2f}) < {bench.F1_MIN}")
    if not abs(r.share_out - r.share_in) <= bench.SHARE_TOL:
        fails.append(f"largest-tree share {r.share_in:.2f} -> {r.share_out:.2f}, off by more than {bench.SHARE_TOL}")
    if not r.drift <= bench.DRIFT_MAX:
        fails.append(
            f"drift L1 {r.drift:.2f} > {bench.DRIFT_MAX} (median turn {r.heading_in:.2f} -> {r.heading_out:.2f})"
        )
    if mask and not r.two_level >= bench.TWO_LEVEL_MIN:
        fails.append(f"two-level fraction {r.two_level:.3f} < {bench.TWO_LEVEL_MIN}")
    if not r.angle < 1.5 * r.angle_spread:
        fails.append(f"angle histogram distance {r.angle:.2f} >= 1.5 x input spread {r.angle_spread:.2f}")
    if not r.thickness < r.thickness_spread:
        fails.append(f"thickness histogram distance {r.thickness:.2f} >= input spread {r.thickness_spread:.2f}")
    assert not fails, "; ".join(fails)


def test_photo_trace_options_leave_masks_to_their_threshold() -> None:
    # --sigmas and --gap reach the photos' trace; a mask is traced by its threshold either way
    assert bench.photo_trace_options("a.png", True, tuned=False, sigmas=[1.0, 4.5], gap=12.0) is None
    assert bench.photo_trace_options("a.jpg", False, tuned=False, sigmas=[1.0, 4.5], gap=12.0) == {
        "sigmas": (1.0, 4.5),
        "gap": 12.0,
    }
    assert bench.photo_trace_options("a.jpg", False, tuned=False, sigmas=None, gap=None) is None
    assert bench.photo_trace_options("a.jpg", False, tuned=False, sigmas=None, gap=None, threshold_scale=0.5) == {
        "threshold_scale": 0.5
    }
    assert bench.photo_trace_options("a.png", True, tuned=False, sigmas=None, gap=None, threshold_scale=0.5) is None
    name = sorted(TRACE_SETTINGS)[0]
    tuned = bench.photo_trace_options(name, False, tuned=True, sigmas=[2.0], gap=None)
    assert tuned is not None and tuned["sigmas"] == (2.0,)
    assert {k: v for k, v in tuned.items() if k != "sigmas"} == {
        k: v for k, v in TRACE_SETTINGS[name].items() if k != "sigmas"
    }
