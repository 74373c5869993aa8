"""Exact, repeatable Euclidean distance transforms (phloem._distance)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from phloem._distance import EXACT_UP_TO, euclidean_distance


def _brute_force(inside: np.ndarray) -> np.ndarray:
    out = np.argwhere(~inside).astype(float)
    ys, xs = np.mgrid[: inside.shape[0], : inside.shape[1]]
    d = np.sqrt(((ys[..., None] - out[:, 0]) ** 2 + (xs[..., None] - out[:, 1]) ** 2).min(axis=-1))
    return np.where(inside, d, 0.0).astype(np.float32)


@pytest.mark.parametrize("seed", range(4))
def test_distance_is_exact_against_brute_force(seed: int) -> None:
    rng = np.random.default_rng(seed)
    inside = rng.random((23, 31)) > 0.05
    inside[0, 0] = False
    assert np.array_equal(euclidean_distance(inside), _brute_force(inside))


def test_distance_is_the_same_on_every_call_and_equals_scipy() -> None:
    # OpenCV's precise transform alone differed between calls by ~1e-5 px on 1 in 20 random masks
    rng = np.random.default_rng(0)
    for _ in range(20):
        h, w = rng.integers(50, 400, 2)
        inside = rng.random((h, w)) > 0.02
        first = euclidean_distance(inside)
        assert np.array_equal(first, ndimage.distance_transform_edt(inside).astype(np.float32))
        assert all(np.array_equal(first, euclidean_distance(inside)) for _ in range(3))


def test_far_distances_and_no_outside() -> None:
    inside = np.ones((8, 2 * int(EXACT_UP_TO) + 40), bool)
    inside[:, 0] = False
    d = euclidean_distance(inside)
    assert d.max() > EXACT_UP_TO and np.array_equal(d, ndimage.distance_transform_edt(inside).astype(np.float32))
    assert euclidean_distance(np.ones((5, 5), bool)).min() > 1e6  # nothing outside: no finite distance
