"""Branch ends carried on to other structure (``join_ends``, ``grow(joined_ends=)``) and the
measure they match (``joined_end_share``)."""

from __future__ import annotations

import numpy as np
import pytest

from phloem.branching import Branch, Skeleton, fit_models, grow, source_defaults, synthetic_skeleton
from phloem.branching.joins import join_ends
from phloem.metrics import joined_end_share

H = 2.0


def stem_and_side(end=(112.0, 40.0)) -> Skeleton:
    """A stem along y = 50 (thickness 3) and a side branch that leaves it at x = 60, arcs up and
    heads back down towards it, ending at ``end``."""
    stem = Branch([[10, 50], [60, 50], [190, 50]], 3.0)
    side = Branch([[60, 50], [75, 30], [100, 30], list(end)], 2.0, parent=(0, 1))
    return Skeleton([stem, side], (100, 200))


def surface_gap(point: np.ndarray, branch: Branch) -> float:
    """Brute force: distance from ``point`` to the branch's polyline, less its thickness there."""
    best = np.inf
    for a, b, ra, rb in zip(branch.points[:-1], branch.points[1:], branch.thickness[:-1], branch.thickness[1:]):
        t = float(np.clip((point - a) @ (b - a) / max((b - a) @ (b - a), 1e-12), 0, 1))
        best = min(best, float(np.hypot(*(a + t * (b - a) - point))) - (ra + t * (rb - ra)))
    return best


# -- the measure -------------------------------------------------------------------------------


def test_joined_end_share_counts_ends_on_other_structure() -> None:
    # the side branch ends 10 px from the stem's centre line: 7 px off its surface, free
    assert joined_end_share(stem_and_side()) == 0.0
    # 1 px off the surface: on it (the stem's own end stays free)
    assert joined_end_share(stem_and_side((112.0, 46.0))) == 0.5
    # the stem's end on a second tree's branch counts as well
    wall = Branch([[192, 10], [192, 90]], 2.0)
    sk = stem_and_side((112.0, 46.0))
    assert joined_end_share(Skeleton([*sk.branches, wall], sk.shape)) == pytest.approx(2 / 3)


def test_joined_end_share_leaves_out_the_branch_its_children_and_its_parent_at_its_start() -> None:
    stem = Branch([[10, 50], [60, 50], [190, 50]], 3.0)
    # a stub beside its parent closes no loop
    stub = Branch([[60, 50], [66, 46]], 2.0, parent=(0, 1))
    assert joined_end_share(Skeleton([stem, stub])) == 0.0
    # a child that starts at a branch's end does not put that end on structure
    kid = Branch([[190, 50], [190, 90]], 2.0, parent=(0, 2))
    assert joined_end_share(Skeleton([stem, kid])) == 0.0
    # a branch curling back onto itself is not on *other* structure
    curl = Branch([[20, 20], [80, 20], [80, 40], [40, 40], [40, 22]], 2.0)
    assert joined_end_share(Skeleton([curl])) == 0.0


def test_joined_end_share_refuses_what_is_not_a_skeleton() -> None:
    with pytest.raises(TypeError, match="skeleton"):
        joined_end_share([[0, 0], [1, 1]])  # type: ignore[arg-type]


# -- joining -------------------------------------------------------------------------------------


def test_an_end_short_of_structure_ahead_is_carried_onto_it() -> None:
    sk = stem_and_side()
    out = join_ends(sk, 0.5, reach=40.0, step=H)
    side, new = sk.branches[1], out.branches[1]
    # only appended: the grown branch is kept as it was, its parent link too
    assert np.array_equal(new.points[: len(side.points)], side.points) and new.parent == side.parent
    assert out.branches[0] == sk.branches[0]
    # it ends on the stem, on its centre line
    assert abs(surface_gap(new.points[-1], sk.branches[0]) + 3.0) < 0.5
    assert joined_end_share(out) == 0.5
    # edges of the step, but for the last one onto the centre line
    edges = np.linalg.norm(np.diff(new.points[len(side.points) - 1 :], axis=0), axis=1)
    assert np.allclose(edges[:-1], H) and 0 < edges[-1] <= H + 1e-9
    # leaving the way it was heading: the first new edge turns little
    d0 = side.points[-1] - side.points[-2]
    d1 = new.points[len(side.points)] - side.points[-1]
    assert np.degrees(np.arccos(d0 @ d1 / np.hypot(*d0) / np.hypot(*d1))) < 25
    # the way keeps off the stem until it arrives
    way = new.points[len(side.points) : -1]
    assert all(surface_gap(p, sk.branches[0]) > -1.5 for p in way[:-2])


def test_nothing_is_joined_that_need_not_or_cannot_be() -> None:
    sk = stem_and_side()
    assert join_ends(sk, 0.0, reach=40.0, step=H) == sk
    # out of reach
    assert join_ends(sk, 1.0, reach=8.0, step=H) == sk
    # structure behind the end, not ahead of it
    away = Skeleton([sk.branches[0], Branch([[60, 50], [75, 30], [100, 20], [112, 15]], 2.0, parent=(0, 1))], sk.shape)
    assert join_ends(away, 1.0, reach=40.0, step=H) == away
    # a way that would leave the domain
    domain = np.ones(sk.shape, bool)
    domain[43:47, :] = False
    assert join_ends(sk, 1.0, reach=40.0, step=H, domain=domain) == sk


def test_join_ends_names_bad_arguments() -> None:
    sk = stem_and_side()
    with pytest.raises(ValueError, match="share"):
        join_ends(sk, 1.5, reach=40.0, step=H)
    with pytest.raises(ValueError, match="reach"):
        join_ends(sk, 0.5, reach=0.0, step=H)
    with pytest.raises(ValueError, match="shape"):
        join_ends(Skeleton(sk.branches), 0.5, reach=40.0, step=H)
    with pytest.raises(ValueError, match="domain"):
        join_ends(sk, 0.5, reach=40.0, step=H, domain=np.ones((3, 3), bool))


def braided(seed: int) -> Skeleton:
    """A synthetic structure whose children often end on their parent: the first tree's
    side branches are bent back onto the stem further along, as channels round islands."""
    src = synthetic_skeleton(seed, length=260.0)
    out = list(src.branches)
    stem = out[0]
    for i, b in enumerate(out):
        if b.parent is None or b.parent[0] != 0 or i % 2:
            continue
        v = b.parent[1]
        back = min(v + 15, len(stem.points) - 1)
        q = stem.points[back]
        a = b.points[: max(3, len(b.points) // 3)]
        bridge = np.linspace(a[-1], q, 8)[1:]
        pts = np.vstack([a, bridge])
        out[i] = Branch(pts, np.full(len(pts), float(b.thickness[0])), b.parent)
    return Skeleton(out, src.shape)


def test_grown_structure_ends_on_structure_about_as_often_as_its_input() -> None:
    src = Skeleton.stack([braided(s) for s in (3, 4, 5)])
    share = joined_end_share(src)
    assert share > 0.5
    assert source_defaults(src).joined_ends == share
    bend, fur = fit_models(src, h=H)
    shares = []
    for seed in range(6):
        plain = grow(bend, fur, size=src.shape, seed=seed, max_length="input")
        joined = grow(bend, fur, size=src.shape, seed=seed, max_length="input", joined_ends=share)
        n = len(joined.branches)
        # towards the input's share, and not past it by more than a way's side effects
        assert joined_end_share(plain) < joined_end_share(joined) <= share + 2.0 / n
        # as far towards it as the grown ends have ways onto structure ahead
        most = joined_end_share(join_ends(plain, 1.0, reach=3.0 * bend.m * bend.h, step=bend.h))
        assert joined_end_share(joined) >= min(share, most) - 2.0 / n
        shares.append((joined_end_share(plain), joined_end_share(joined)))
        # joining only appends to the paper's branches, and stays in the image
        assert len(plain.branches) == n
        for a, b in zip(plain.branches, joined.branches, strict=True):
            assert np.array_equal(b.points[: len(a.points)], a.points) and a.parent == b.parent
        pts = np.vstack([b.points for b in joined.branches])
        assert pts.min() >= 0 and (pts.max(axis=0) <= np.array(src.shape[::-1]) - 1).all()
    # over the seeds, well up from growth alone, which ends far below the input's share (how
    # near it comes depends on how many grown ends stop within reach of structure ahead)
    plain_mean, joined_mean = np.mean(shares, axis=0)
    assert plain_mean < share - 0.3 and joined_mean >= plain_mean + 0.2
    # the same seed, the same structure
    assert grow(bend, fur, size=src.shape, seed=5, max_length="input", joined_ends=share) == joined


def test_grow_names_a_bad_joined_ends() -> None:
    bend, fur = fit_models(synthetic_skeleton(0), h=H)
    with pytest.raises(ValueError, match="joined_ends"):
        grow(bend, fur, size=(100, 100), joined_ends=1.5)
    with pytest.raises(ValueError, match="joined_ends"):
        grow(bend, fur, size=(100, 100), joined_ends=float("nan"))
