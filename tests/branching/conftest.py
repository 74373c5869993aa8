"""Shared fixtures of the branching model tests: example skeletons and the models fitted to them."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from phloem.branching import BendingModel, Branch, FurcationModel, Skeleton, synthetic_skeleton

H = 2.0


def walk_branch_of(rng: np.random.Generator, n: int, sigma: float, start=(20.0, 150.0), heading=0.0) -> Branch:
    """A random-walk branch with AR(1) turning angles of known spread and a tapering thickness."""
    a = np.zeros(n - 2)
    for i in range(n - 2):
        a[i] = (0.5 * a[i - 1] if i else 0.0) + rng.normal(0.0, sigma)
    thick = np.linspace(4.0, 1.5, n) * (1 + 0.05 * rng.standard_normal(n))
    return Branch.from_angles(start, heading, a, thick, H)


def forest_of(seed: int, sigma: float = 0.25, branches: int = 3) -> Skeleton:
    """Several synthetic structures side by side, one skeleton (more data for the statistics)."""
    return Skeleton.stack([synthetic_skeleton(seed + i, sigma=sigma, length=260.0) for i in range(branches)])


@pytest.fixture
def walk_branch() -> Callable[..., Branch]:
    """``walk_branch(rng, n, sigma, start=, heading=)``: a random-walk branch of step ``H``."""
    return walk_branch_of


@pytest.fixture
def forest() -> Callable[..., Skeleton]:
    """``forest(seed, sigma=0.25, branches=3)``: synthetic structures stacked in one skeleton."""
    return forest_of


@pytest.fixture(scope="module")
def source() -> Skeleton:
    return forest_of(10)


@pytest.fixture(scope="module")
def models(source: Skeleton) -> tuple[BendingModel, FurcationModel]:
    return BendingModel.fit(source, h=H), FurcationModel.fit(source, h=H)
