"""Fragments on a skeleton and their rigid alignment (Sibbing et al. 2010, §5.1, §5.2)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from phloem.branching import Branch, Skeleton, fragments, rigid_align
from phloem.branching._elements import _dense
from phloem.branching.fragments import Fragment, foreign_fragments
from phloem.branching.synthetic import synthetic_skeleton
from phloem.testing import channel_scene


def _rot(a: float) -> np.ndarray:
    return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])


def test_rigid_align_is_exact_on_rotated_copies() -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        p = rng.normal(size=(9, 2)) * 20
        a = float(rng.uniform(-math.pi, math.pi))
        t0 = rng.normal(size=2) * 50
        R, t = rigid_align(p, p @ _rot(a).T + t0)
        assert np.allclose(R, _rot(a), atol=1e-12)
        assert np.allclose(t, t0, atol=1e-9)
        # With centres (the §5.2 form: centres coincide, only the rotation is fitted).
        c = p[4]
        R2, t2 = rigid_align(p, p @ _rot(a).T + t0, source_center=c, target_center=_rot(a) @ c + t0)
        assert np.allclose(R2, _rot(a), atol=1e-12) and np.allclose(t2, t0, atol=1e-9)
        assert abs(np.linalg.det(R)) == pytest.approx(1.0)


def test_rigid_align_never_reflects() -> None:
    p = np.array([[0.0, 0], [3, 0], [0, 1]])
    R, _ = rigid_align(p, p * [1, -1])  # a mirror image: the best rotation, not the reflection
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_fragments_cover_the_skeleton_with_lambda_spacing() -> None:
    _, sk = channel_scene()
    frs = fragments(None, sk, lam=0.75, radius_factor=3)
    for bi, b in enumerate(sk.branches):
        own = [f for f in frs if f.branch == bi and not f.furcation]
        # Radius three times the interpolated thickness.
        for f in own:
            th = np.interp(
                f.arc, np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(b.points, axis=0), axis=1))]), b.thickness
            )
            assert f.radius == pytest.approx(3 * th, rel=1e-9)
        # Spacing λ (s_i + s_(i+1)) between consecutive centres (the last one may close the end early).
        for f0, f1 in itertools.pairwise(own[:-1]):
            d = float(np.linalg.norm(f1.center - f0.center))
            assert d == pytest.approx(0.75 * (f0.radius + f1.radius), abs=0.6)
        # Every point of the skeleton lies in some disk.
        pts, _, _ = _dense(b, 0.5)
        cen = np.stack([f.center for f in own])
        rad = np.array([f.radius for f in own])
        assert (np.linalg.norm(pts[:, None] - cen[None], axis=2) <= rad[None]).any(axis=1).all()
    fur = [f for f in frs if f.furcation]
    assert len(fur) == 1 and np.allclose(fur[0].center, sk.branches[0].points[30])
    assert fur[0].points.shape == (18, 2) and fur[0].thickness.shape == (18,)


def test_fragments_spacing_follows_lambda() -> None:
    sk = Skeleton([Branch([[0, 10], [400, 10]], 5.0)], (20, 401))
    a = fragments(None, sk, lam=0.75)
    b = fragments(None, sk, lam=0.5)
    assert np.linalg.norm(a[1].center - a[0].center) == pytest.approx(22.5, abs=0.5)
    assert np.linalg.norm(b[1].center - b[0].center) == pytest.approx(15.0, abs=0.5)


def test_bad_inputs_name_the_argument() -> None:
    img, sk = channel_scene()
    with pytest.raises(ValueError, match="lam"):
        fragments(img, sk, lam=1.5)
    with pytest.raises(ValueError, match="source_points: expected shape"):
        rigid_align(np.zeros((3, 3)), np.zeros((3, 3)))


def test_a_library_without_any_usable_furcation_fragment_still_matches_branch_fragments() -> None:
    from phloem.branching.fragments import FragmentLibrary, cover

    _, sk = channel_scene()
    frs = cover(sk, 0.75, 3.0, 16, order=False)
    furc = np.array([f.furcation for f in frs])
    assert furc.any() and (~furc).any()
    lib = FragmentLibrary(frs, mirror=True, exclude=furc)
    plain = next(f for f in frs if not f.furcation)
    entries, S, _ = lib.shape_distance(plain, 2.0)
    assert len(entries) == int((~furc).sum()) and not lib.flip.any()
    assert float(S.min()) == pytest.approx(0.0, abs=1e-9)  # itself


def _foreign_by_brute_force(sk: Skeleton, frs: list[Fragment]) -> np.ndarray:
    """Every plain fragment against every other branch's points, as ``foreign_fragments`` defines it."""
    dense = [_dense(b, 1.0) for b in sk.branches]
    return np.array(
        [
            not f.furcation
            and any(
                bi != f.branch and bool((np.linalg.norm(pts - f.center, axis=1) - th < f.radius).any())
                for bi, (pts, th, _) in enumerate(dense)
            )
            for f in frs
        ]
    )


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_foreign_fragments_are_those_whose_disk_holds_another_branch(seed: int) -> None:
    sk = synthetic_skeleton(seed, length=300.0, furcations=6)
    frs = fragments(None, sk)
    want = _foreign_by_brute_force(sk, frs)
    # the fragments where a child leaves its parent, and those beside the child's first stretch
    assert 0 < want.sum() < sum(not f.furcation for f in frs)
    np.testing.assert_array_equal(foreign_fragments(sk, frs, keep=0), want)
    # too few plain fragments would remain: none is left out
    assert not foreign_fragments(sk, frs, keep=len(frs)).any()
