"""The skeleton model of Sibbing et al. 2010 §4.1 and its JSON file format."""

from __future__ import annotations

import json
import math

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


def _reference_resample(points: np.ndarray, count: int, h: float) -> tuple[np.ndarray, np.ndarray]:
    """The NumPy implementation ``Branch.resample`` had before ``phloem_core::resample``."""
    out = [points[0].copy()]
    seg = 0
    while len(out) < count and seg < len(points) - 1:
        a, d = points[seg], points[seg + 1] - points[seg]
        f = a - out[-1]
        qa = float(d @ d)
        if qa == 0.0:
            seg += 1
            continue
        qb = float(f @ d)
        t = (-qb + math.sqrt(max(qb * qb - qa * (float(f @ f) - h * h), 0.0))) / qa
        if t <= 1.0:
            out.append(a + t * d)
        else:
            seg += 1
    pts = np.asarray(out) if len(out) > 1 else points[[0, -1]].copy()
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    s = np.empty(len(pts))
    seg = 0
    for i, q in enumerate(pts):
        best, best_s, best_seg = math.inf, 0.0, seg
        for j in range(seg, len(points) - 1):
            a, d = points[j], points[j + 1] - points[j]
            qa = float(d @ d)
            t = 0.0 if qa == 0.0 else min(max(float((q - a) @ d) / qa, 0.0), 1.0)
            e = a + t * d - q
            dist = float(e @ e)
            if dist < best - 1e-12:
                best, best_s, best_seg = dist, float(cum[j] + t * (cum[j + 1] - cum[j])), j
            if dist < 1e-12:
                break
        s[i], seg = best_s, best_seg
    return pts, np.interp(s, cum, np.asarray(range(len(points)), np.float64))


# Whether NumPy's 2-vector dot product is fused here, as phloem_core::resample's is (0.66 unfused).
_BLAS_FUSES = float(np.array([0.1, 0.7]) @ np.array([0.3, 0.9])) == 0.6599999999999999


@pytest.mark.parametrize("seed", range(40))
def test_resample_gives_the_bits_of_its_numpy_reference(seed):
    # Pixel staircases with repeated points (a trace's centre lines) and smooth wiggles; the
    # thickness is the vertex index, so the arc position of every new vertex is compared too.
    rng = np.random.default_rng(seed)
    if seed % 2:
        pts = _wiggle(seed, 60).points
    else:
        pts = np.cumsum(rng.integers(-1, 2, (80, 2)), axis=0).astype(np.float64) + 40.0
    b = Branch(pts, np.arange(len(pts), dtype=np.float64))
    for h in (1.0, 2.7, 3.0, 7.5):
        count = math.floor(b.length() / h + 1e-9) + 1
        if count < 2:
            continue
        want_pts, want_thick = _reference_resample(pts, count, h)
        r = b.resample(h)
        if _BLAS_FUSES:
            np.testing.assert_array_equal(r.points, want_pts)
            np.testing.assert_array_equal(r.thickness, want_thick)
        else:  # the reference rounds its dot products otherwise on this machine
            np.testing.assert_allclose(r.points, want_pts, rtol=0, atol=1e-9)
            np.testing.assert_allclose(r.thickness, want_thick, rtol=0, atol=1e-6)


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
        ("{not json", r"^path: .*bad.json line 1 column 2: Expecting property name"),
        ("[1, 2]", r"a skeleton must be a JSON object"),
        ('{"branches": []}', r"'branches' must be a non-empty list"),
        ('{"format": "svg", "branches": [{"points": [[0, 0], [1, 1]]}]}', r"format must be 'phloem.skeleton'"),
        ('{"version": 9, "branches": [{"points": [[0, 0], [1, 1]]}]}', r"unsupported skeleton version 9"),
        ('{"branches": [{"thickness": [1]}]}', r"branches\[0\] must be an object with 'points'"),
        ('{"branches": [{"points": [[0, 0]]}]}', r"branches\[0\]: a branch needs at least 2 points"),
        (
            '{"branches": [{"points": [[0, 0, 0], [1, 1, 1]]}]}',
            r"branches\[0\].points\[0\] must be \[x, y\] with two numbers, got \[0, 0, 0\]",
        ),
        (
            '{"branches": [{"points": [[0, "a"], [1, 1]]}]}',
            r"branches\[0\].points\[0\] must be \[x, y\] with two numbers",
        ),
        ('{"branches": [{"points": [[0, NaN], [1, 1]]}]}', r"bad.json line 1 column 31: NaN is not a JSON number"),
        (
            '{"branches": [{"points": [[0, 0], [1, 1]], "thickness": [1, 2, 3]}]}',
            r"thickness must have one value per point",
        ),
        (
            '{"branches": [{"points": [[0, 0], [1, 1]], "thickness": [1, -2]}]}',
            r"branches\[0\].thickness\[1\]: expected a radius in \[0, 8192\] px, got -2.0",
        ),
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


# -- bounds (issue 16: a skeleton file with far-away coordinates made run/fit_models loop for minutes)


@pytest.mark.parametrize(
    ("branch", "message"),
    [
        (
            '{"points": [[0, 0], [1e12, 5]]}',
            r"branches\[0\].points\[1\]: coordinates must be finite \(no NaN or infinity\) and within ±1048576",
        ),
        ('{"points": [[0, 0], [1, -3e9]]}', r"branches\[0\].points\[1\]: coordinates must be finite"),
        ('{"points": [[0, 0], [1, 1e400]]}', r"1e400 is too large for a number"),
        (
            '{"points": [[0, 0], [1, 1]], "thickness": 1e6}',
            r"branches\[0\].thickness\[0\]: expected a radius in \[0, 8192\]",
        ),
        (
            '{"points": [[0, 0], ["1", 1]]}',
            r"branches\[0\].points\[1\] must be \[x, y\] with two numbers, got \['1', 1\]",
        ),
        ('{"points": [[0, 0], [true, 1]]}', r"branches\[0\].points\[1\] must be \[x, y\] with two numbers"),
        ('{"points": {"x": 1}}', r"branches\[0\].points must be a list of \[x, y\] pairs, got dict"),
        ('{"points": [[0, 0], [1, 1]], "thickness": ["2", 1]}', r"branches\[0\].thickness\[0\] must be a number"),
        ('{"points": [[0, 0], [1, 1]], "thickness": [1, Infinity]}', r"Infinity is not a JSON number"),
        ('{"points": [[0, 0], [1, 1]], "parent": [0, 99999999999999999999]}', r"branches\[0\].parent: branch index 0"),
    ],
)
def test_file_bounds_and_types(tmp_path, branch, message):
    p = tmp_path / "bad.json"
    p.write_text('{"branches": [' + branch + "]}")
    with pytest.raises(SkeletonError, match=r"^path: .*bad.json[: ].*" + message):
        Skeleton.load(p)


def test_file_shape_and_total_length_bounds(tmp_path):
    p = tmp_path / "s.json"
    p.write_text('{"shape": [10, 2000000], "branches": [{"points": [[0, 0], [1, 1]]}]}')
    with pytest.raises(SkeletonError, match=r"'shape' must be \[H, W\] with integers in 1..1048576"):
        Skeleton.load(p)
    far = [[0, 0], [1_000_000, 0]] * 200
    with pytest.raises(SkeletonError, match=r"^branches: a total length of 3.99e\+08 px is more than"):
        Skeleton([Branch(far, 1.0)])


def test_branch_refuses_huge_coordinates_and_thickness():
    with pytest.raises(
        SkeletonError, match=r"branch.points\[1\]: coordinates must be finite \(no NaN or infinity\) and within"
    ):
        Branch([[0, 0], [0, 1e15]], 1.0)
    with pytest.raises(SkeletonError, match=r"branch.points\[0\]: coordinates must be finite"):
        Branch([[np.nan, 0], [0, 1]], 1.0)
    with pytest.raises(SkeletonError, match=r"branch.thickness\[1\]: expected a radius in \[0, 8192\] px, got 40000.0"):
        Branch([[0, 0], [0, 1]], [1.0, 40000.0])


@pytest.mark.parametrize("h", [0, -1.0, float("nan"), float("inf"), "2", 1e-300, 1e-4])
def test_branch_resample_refuses_a_bad_or_tiny_step(h):
    # a step of 1e-4 px on a 200-px branch would be 2 million vertices: refused, not a hang
    with pytest.raises((ValueError, TypeError), match="^h: "):
        Branch([[0, 0], [200, 0]], 1.0).resample(h)


def test_resample_bounds_the_vertex_count():
    sk = Skeleton([Branch([[0, 0], [1_000_000, 0]], 1.0)])
    with pytest.raises(
        ValueError, match=r"^h: resampling 1e\+06 px of branches at h=0.5 would make about 2e\+06 vertices"
    ):
        sk.resample(0.5)
    assert len(sk.resample(100.0).branches[0]) >= 10_000


def test_from_json_names_line_and_column_and_refuses_deep_nesting():
    with pytest.raises(SkeletonError, match=r"^text: line 2 column 1: Expecting value"):
        Skeleton.from_json("[1,\n")
    with pytest.raises(SkeletonError, match=r"^text: line 1 column 65: nested more than 64 levels deep"):
        Skeleton.from_json("[" * 100_000)
    with pytest.raises(TypeError, match=r"^text: expected a str, got bytes"):
        Skeleton.from_json(b"{}")  # type: ignore[arg-type]


def test_synthesize_checks_a_shapeless_skeleton_against_the_image_before_fitting():
    from phloem import branching

    sk = Skeleton([Branch([[0, 0], [900_000, 5]], 1.0)])
    with pytest.raises(
        SkeletonError, match=r"^skeleton: branches\[0\].points\[1\] = \(900000.0, 5.0\) is outside the 32x32"
    ):
        branching.synthesize(np.zeros((32, 32), np.float32), sk)


def test_thick_skeletons_draw_without_an_opencv_error():
    # Before: the gap completion drew radius_factor x 8000 px wide lines, past OpenCV's MAX_THICKNESS.
    from phloem import branching

    sk = Skeleton([Branch([[4, 20], [60, 22], [100, 30]], 8000.0)], (48, 110))
    assert sk.mask().all()
    from phloem.branching.gaps import _background

    assert not _background(sk, (48, 110), 3.0).any()
    img = np.random.default_rng(0).random((48, 110)).astype(np.float32)
    out = branching.render(img, sk, sk, seed=0)
    assert out.shape == (48, 110) and np.isfinite(out).all()
