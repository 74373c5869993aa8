"""The furcation model (Sibbing et al. 2010, §4.3): the SVM ranks furcations, picks keep their spacing."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from phloem.branching import BendingModel, Branch, FurcationModel, Skeleton, synthetic_skeleton

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
