"""The skeleton model of Sibbing et al. 2010 §4.1 and its JSON file format."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from phloem.branching import Branch, Skeleton, SkeletonError


def _wiggle(seed: int, n: int = 40) -> Branch:
    rng = np.random.default_rng(seed)
    steps = rng.uniform(0.5, 4.0, n)[:, None] * np.stack(
        [np.cos(np.cumsum(rng.normal(0, 0.4, n))), np.sin(np.cumsum(rng.normal(0, 0.4, n)))], axis=1
    )
    pts = np.vstack([[50.0, 50.0], 50.0 + np.cumsum(steps, axis=0)])
    return Branch(pts, rng.uniform(1.0, 5.0, n + 1))


@given(st.integers(0, 10_000), st.floats(0.5, 6.0))
def test_resample_has_constant_edges_and_angles_round_trip(seed, h):
    b = _wiggle(seed)
    r = b.resample(h)
    edges = np.linalg.norm(np.diff(r.points, axis=0), axis=1)
    if len(r) > 2 or b.length() >= h:
        np.testing.assert_allclose(edges, h, rtol=1e-9, atol=1e-9)
    # Vertices lie on the original polyline, in order, starting at its start.
    np.testing.assert_array_equal(r.points[0], b.points[0])
    # Angles + thickness + h define the branch up to a rigid motion (§4.1): rebuild it.
    back = Branch.from_angles(r.points[0], r.heading(), r.angles(), r.thickness, h)
    np.testing.assert_allclose(back.points, r.points, atol=1e-7)
    assert np.all(np.abs(r.angles()) <= np.pi)
    assert r.thickness.min() >= b.thickness.min() - 1e-9 and r.thickness.max() <= b.thickness.max() + 1e-9


def test_angles_sign_and_straight_line():
    # Screen coordinates (y down): turning from +x towards -y (up on screen) is counter-clockwise.
    assert Branch([[0, 0], [1, 0], [1, -1]], 1.0).angles()[0] == pytest.approx(np.pi / 2)
    assert Branch([[0, 0], [1, 0], [1, 1]], 1.0).angles()[0] == pytest.approx(-np.pi / 2)
    np.testing.assert_allclose(Branch([[0, 0], [1, 1], [2, 2], [3, 3]], 1.0).angles(), 0.0, atol=1e-12)


def test_resample_thickness_and_child_attachment():
    trunk = Branch([[0, 0], [10, 0], [20, 0]], [4.0, 2.0, 0.0])
    child = Branch([[10, 0], [10, 10]], 1.0, parent=(0, 1))
    r = Skeleton([trunk, child], (30, 30)).resample(2.5)
    t = r.branches[0]
    np.testing.assert_allclose(t.thickness, 4.0 - 0.2 * t.points[:, 0])  # linear in arc length
    pb, pv = r.branches[1].parent
    assert pb == 0 and np.allclose(t.points[pv], [10, 0])


def test_json_round_trip_and_atomic_save(tmp_path):
    sk = Skeleton([_wiggle(1), Branch([[60, 60], [70, 80]], 2.0, parent=(0, 5))], (200, 200))
    assert Skeleton.from_json(sk.to_json()) == sk
    path = tmp_path / "s.json"
    sk.save(path)
    assert Skeleton.load(path) == sk
    with pytest.raises(FileExistsError):
        sk.save(path)
    sk.save(path, overwrite=True)
    assert json.loads(path.read_text())["format"] == "phloem.skeleton"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("{not json", r"not a valid JSON skeleton"),
        ("[1, 2]", r"a skeleton must be a JSON object"),
        ('{"branches": []}', r"'branches' must be a non-empty list"),
        ('{"format": "svg", "branches": [{"points": [[0, 0], [1, 1]]}]}', r"format must be 'phloem.skeleton'"),
        ('{"version": 9, "branches": [{"points": [[0, 0], [1, 1]]}]}', r"unsupported skeleton version 9"),
        ('{"branches": [{"thickness": [1]}]}', r"branches\[0\] must be an object with 'points'"),
        ('{"branches": [{"points": [[0, 0]]}]}', r"branches\[0\]: a branch needs at least 2 points"),
        ('{"branches": [{"points": [[0, 0, 0], [1, 1, 1]]}]}', r"branches\[0\]: points must have shape \(n, 2\)"),
        ('{"branches": [{"points": [[0, "a"], [1, 1]]}]}', r"branches\[0\]: points must be a list of \[x, y\] pairs"),
        ('{"branches": [{"points": [[0, NaN], [1, 1]]}]}', r"branches\[0\]: points contain NaN"),
        (
            '{"branches": [{"points": [[0, 0], [1, 1]], "thickness": [1, 2, 3]}]}',
            r"thickness must have one value per point",
        ),
        ('{"branches": [{"points": [[0, 0], [1, 1]], "thickness": [1, -2]}]}', r"thickness must be finite and >= 0"),
        (
            '{"branches": [{"points": [[0, 0], [1, 1]], "parent": [0, 0]}]}',
            r"branches\[0\].parent: branch index 0 must refer to an earlier",
        ),
        (
            '{"branches": [{"points": [[0, 0], [1, 1]]}, {"points": [[0, 0], [1, 1]], "parent": [0, 5]}]}',
            r"branches\[1\].parent: vertex 5 is outside branch 0",
        ),
        (
            '{"branches": [{"points": [[0, 0], [1, 1]], "parent": "root"}]}',
            r"parent must be null or \[branch index, vertex index\]",
        ),
        ('{"shape": [10], "branches": [{"points": [[0, 0], [1, 1]]}]}', r"'shape' must be \[H, W\]"),
        (
            '{"shape": [10, 10], "branches": [{"points": [[0, 0], [12, 3]]}]}',
            r"branches\[0\].points\[1\] = \(12.0, 3.0\) is outside the 10x10 image",
        ),
    ],
)
def test_malformed_files_give_clear_errors(tmp_path, text, message):
    p = tmp_path / "bad.json"
    p.write_text(text)
    with pytest.raises(SkeletonError, match=message):
        Skeleton.load(p)


def test_check_inside_names_the_argument_and_drawing():
    sk = Skeleton([Branch([[2, 2], [20, 5]], 2.0)])
    with pytest.raises(
        SkeletonError, match=r"^target: branches\[0\].points\[1\] = \(20.0, 5.0\) is outside the 10x12 image"
    ):
        sk.check_inside((12, 10), "target")
    m = sk.mask((12, 30))
    assert m.shape == (12, 30) and m[2:6, 2:20].any() and not m[11].any()
    img = sk.draw(size=(12, 30), color=(1, 0, 0))
    assert img.shape == (12, 30, 3) and img[..., 0].max() > 0.5 and img[..., 1].max() == 0
    with pytest.raises(SkeletonError, match=r"mask: the skeleton has no shape"):
        sk.mask()
