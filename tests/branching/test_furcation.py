"""The furcation model (Sibbing et al. 2010, §4.3): the SVM ranks furcations, picks keep their spacing."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from phloem.branching import BendingModel, Branch, FurcationModel, Skeleton, grow, synthetic_skeleton
from phloem.branching.furcation import SPACING_QUANTILE

H = 2.0


def auc(scores: np.ndarray, labels: np.ndarray) -> float:
    pos, neg = scores[labels], scores[~labels]
    return float(((pos[:, None] > neg[None]).sum() + 0.5 * (pos[:, None] == neg[None]).sum()) / (len(pos) * len(neg)))


def test_svm_ranks_held_out_furcations_above_chance(forest: Callable[..., Skeleton]):
    # furcations follow a learnable rule: the thickness drops by 30 % right after them
    fur = FurcationModel.fit(forest(100, branches=4), h=H)
    scores, labels = [], []
    for seed in range(200, 204):
        sk = synthetic_skeleton(seed, length=260.0, furcations=5).resample(H)
        main = sk.branches[0]
        lab = np.zeros(len(main), bool)
        lab[[v for v, _ in sk.children()[0]]] = True
        scores.append(fur.probabilities(main))
        labels.append(lab)
    s, lab = np.concatenate(scores), np.concatenate(labels)
    assert lab.sum() >= 15
    assert auc(s, lab) > 0.8
    assert ((s >= 0) & (s <= 1)).all()


def test_svm_training_needs_furcations(walk_branch: Callable[..., Branch]):
    sk = Skeleton([walk_branch(np.random.default_rng(0), 50, 0.2)])
    with pytest.raises(ValueError, match="skeleton"):
        FurcationModel.fit(sk, h=H)


def test_pick_respects_min_spacing(models: tuple[BendingModel, FurcationModel]):
    _, fur = models
    main = synthetic_skeleton(7).resample(H).branches[0]
    picks = fur.pick(main, 6, min_spacing=10)
    assert len(picks) == len(set(picks)) >= 3
    assert min(abs(a - b) for a in picks for b in picks if a != b) >= 10
    assert all(0 < p < len(main) - 1 for p in picks)


def _comb(walk: Callable[..., Branch], rng: np.random.Generator) -> Skeleton:
    """A wandering stem with a child every 15 vertices, on alternate sides, and one more child
    a vertex beside the second: the close pair a trace makes at a junction."""
    stem = walk(rng, 200, 0.05, start=(20.0, 200.0))
    at = [*range(15, 190, 15), 31]
    kids = []
    for j, v in enumerate(sorted(at)):
        side = 1.0 if j % 2 else -1.0
        t = stem.points[v + 1] - stem.points[v - 1]
        heading = float(np.arctan2(-t[1], t[0])) + side * 1.0
        kid = walk(rng, 25, 0.1, start=tuple(stem.points[v]), heading=heading)
        kids.append(Branch(kid.points, np.minimum(kid.thickness, 2.0), (0, v)))
    return Skeleton([stem, *kids], (400, 480))


def test_default_spacing_ignores_the_input_s_closest_pair(walk_branch: Callable[..., Branch]):
    # The smallest gap (1 vertex) would let children be picked a vertex apart all along every
    # branch; the default is the gaps' 10 % quantile, and growth (picks, retries, top-ups) keeps it.
    src = _comb(walk_branch, np.random.default_rng(3))
    gaps = np.diff(sorted(v for v, _ in src.resample(H).children()[0]))
    assert gaps.min() <= 2
    fur = FurcationModel.fit(src, h=H)
    assert fur.min_spacing == int(np.floor(np.quantile(gaps, SPACING_QUANTILE))) >= 10
    # n⁻, n⁺ weighted as §4.3 means them (keeping furcations apart): no spacing is drawn
    assert (fur.weights[-2:] > 0).all()
    stem, rng = src.resample(H).branches[0], np.random.default_rng(0)
    assert fur.pick(stem, 6, rng=rng) == fur.pick(stem, 6)
    assert rng.random() == np.random.default_rng(0).random()
    bend = BendingModel.fit(src, h=H)
    for seed in range(3):
        out = grow(bend, fur, size=(400, 480), seed=seed)
        for vs in out.children().values():
            if len(vs) > 1:
                assert np.diff(sorted(v for v, _ in vs)).min() >= fur.min_spacing
        assert sum(len(vs) for vs in out.children().values()) >= 6


def _bursts(walk: Callable[..., Branch], rng: np.random.Generator) -> Skeleton:
    """Stems whose children come in a burst, 6 to 30 vertices apart, between long bare
    stretches: heavy-tailed gaps, where most non-furcations lie far from any furcation."""
    stems, kids = [], []
    for s in range(6):
        stem = walk(rng, 300, 0.05, start=(1000.0, 500.0 + 300.0 * s))
        stems.append(stem)
        v = int(rng.integers(20, 120))
        for j in range(5):
            t = stem.points[v + 1] - stem.points[v - 1]
            heading = float(np.arctan2(-t[1], t[0])) + (1.0 if j % 2 else -1.0)
            kid = walk(rng, 20, 0.1, start=tuple(stem.points[v]), heading=heading)
            kids.append(Branch(kid.points, np.minimum(kid.thickness, 2.0), (s, v)))
            v += int(rng.integers(6, 31))
    return Skeleton([*stems, *kids], (3000, 3000))


def test_picks_are_spaced_as_the_input_s_children(walk_branch: Callable[..., Branch]):
    # On bursty gaps the SVM weights n⁻, n⁺ negatively (§4.3 means them to keep furcations
    # apart): each pick draws the next to its side, and without a generator the picks pack a
    # stretch at min_spacing. Drawing each furcation's spacing from the input's gaps spaces
    # them as the input's children are.
    fur = FurcationModel.fit(_bursts(walk_branch, np.random.default_rng(5)), h=H)
    assert (fur.weights[-2:] < 0).any()
    assert fur.gaps.min() >= 5 and np.median(fur.gaps) >= 12
    stem = walk_branch(np.random.default_rng(9), 300, 0.05).resample(H)
    packed = np.diff(sorted(fur.pick(stem, 6)))
    assert np.median(packed) < np.median(fur.gaps), packed
    for seed in range(4):
        picks = fur.pick(stem, 6, rng=np.random.default_rng(seed))
        assert picks == fur.pick(stem, 6, rng=np.random.default_rng(seed))
        assert np.median(np.diff(sorted(picks))) >= np.median(fur.gaps), (picks, np.median(fur.gaps))
