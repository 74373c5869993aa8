"""The input's layout of directions (``layout``): fitted to the different branches near each
place, nothing where they do not agree, and growth that follows it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from phloem.branching import BendingModel, Branch, Skeleton, fit_models, grow
from phloem.branching._elements import _edge_headings
from phloem.branching._layout import DirectionLayout


def _line(a: tuple[float, float], b: tuple[float, float], n: int = 40) -> Branch:
    t = np.linspace(0.0, 1.0, n)[:, None]
    return Branch(np.asarray(a) * (1 - t) + np.asarray(b) * t, 1.5)


def test_parallel_branches_have_a_layout_and_one_branch_has_none():
    rows = Skeleton([_line((20, y), (280, y + 8)) for y in range(60, 241, 20)], (300, 300))
    lay = DirectionLayout.fit(rows)
    kappa, phi = lay.at(150, 150, (300, 300))
    # ten parallel branches agree: a sharp distribution along their axis (slope 8/260, up-right on screen)
    assert kappa > 3.0
    assert abs(phi - (-math.atan2(8, 260))) < 0.02
    # one branch, however straight, is no layout: nothing near it agrees or disagrees with it
    one = DirectionLayout.fit(Skeleton([_line((20, 150), (280, 150))], (300, 300)))
    assert one.kappa.max() == 0.0


def test_branches_that_run_every_way_have_no_layout():
    # a crack-like mesh: lines at 0, 45, 90 and 135 degrees through the same area
    brs = []
    for k in range(4):
        a = k * math.pi / 4
        d = np.array([math.cos(a), -math.sin(a)])
        n = np.array([-d[1], d[0]])
        for off in (-60, -20, 20, 60):
            c = np.array([150.0, 150.0]) + off * n
            brs.append(_line(tuple(c - 120 * d), tuple(c + 120 * d)))
    lay = DirectionLayout.fit(Skeleton(brs, (300, 300)))
    assert lay.at(150, 150, (300, 300))[0] < 0.3


def test_the_layout_is_laid_over_a_picture_of_another_size():
    # horizontal branches on the left half, vertical ones on the right
    left = [_line((10, y), (130, y)) for y in range(20, 181, 16)]
    right = [_line((x, 10), (x, 190)) for x in range(170, 291, 16)]
    lay = DirectionLayout.fit(Skeleton(left + right, (200, 300)))
    k, phi = lay.at(140, 200, (400, 600))  # the left half's middle, on a picture twice the size
    assert k > 2.0 and abs(phi) < 0.1
    k, phi = lay.at(460, 200, (400, 600))
    assert k > 2.0 and abs(abs(phi) - math.pi / 2) < 0.1


def _fan(rng: np.random.Generator, n: int = 24, shape: tuple[int, int] = (300, 300)) -> Skeleton:
    """Wavy branches leaving a centre every way, as a fundus's vessels leave the disc."""
    cy, cx = shape[0] / 2, shape[1] / 2
    brs = []
    for j in range(n):
        a = 2 * math.pi * j / n + rng.normal(0, 0.05)
        r0 = 20 + 10 * rng.random()
        turns = rng.normal(0, 0.08, 50)
        brs.append(Branch.from_angles([cx + r0 * math.cos(a), cy - r0 * math.sin(a)], a, turns - turns.mean(),
                                      np.full(52, 1.5), 2.0))  # fmt: skip
    return Skeleton(brs, shape)


def _radial_agreement(sk: Skeleton) -> float:
    """Length-weighted mean of ``cos 2(θ − radial direction)`` over the edges: 1 all radial, 0 any way."""
    cy, cx = (sk.shape[0] - 1) / 2, (sk.shape[1] - 1) / 2
    num = den = 0.0
    for b in sk.branches:
        p = np.asarray(b.points)
        mid = 0.5 * (p[1:] + p[:-1])
        radial = np.arctan2(-(mid[:, 1] - cy), mid[:, 0] - cx)
        length = np.hypot(*np.diff(p, axis=0).T)
        num += float((length * np.cos(2 * (_edge_headings(p) - radial))).sum())
        den += float(length.sum())
    return num / den


def test_growth_follows_the_inputs_layout():
    src = _fan(np.random.default_rng(0))
    assert _radial_agreement(src) > 0.9

    def agreements(weight: float) -> list[float]:
        bend = BendingModel.fit(src, h=2.0, layout=weight)
        return [_radial_agreement(grow(bend, None, size=src.shape, seed=s, max_length="input")) for s in range(4)]

    without, with_ = agreements(0.0), agreements(1.0)
    assert np.mean(with_) > np.mean(without) + 0.15, (with_, without)
    assert min(with_) > np.median(without), (with_, without)


def test_layout_off_fits_no_layout_and_a_bad_weight_is_refused():
    src = _fan(np.random.default_rng(1))
    assert BendingModel.fit(src, h=2.0).direction_layout is None
    assert fit_models(src, h=2.0, layout=1.0)[0].direction_layout is not None
    for bad in (-1.0, math.nan):
        with pytest.raises(ValueError, match="^layout:"):
            fit_models(src, h=2.0, layout=bad)
