"""Angle and thickness histograms and their distance (Sibbing et al. 2010, Fig. 7)."""

from __future__ import annotations

import numpy as np
import pytest

from phloem.branching import Branch, Skeleton, angle_histogram, histogram_distance, thickness_histogram


def test_histograms_share_a_range_to_compare_two_structures() -> None:
    a = Skeleton([Branch([[0, 0], [1, 0], [1, -1], [2, -1]], [1.0, 2.0, 2.0, 3.0])])
    b = Skeleton([Branch([[0, 0], [1, 0], [2, 0], [3, 0]], 1.0)])
    ha, edges = angle_histogram(a, bins=4, range=(-2.0, 2.0))
    hb, _ = angle_histogram(b, bins=4, range=(-2.0, 2.0))
    assert edges.tolist() == [-2.0, -1.0, 0.0, 1.0, 2.0]
    assert ha.tolist() == [0.5, 0.0, 0.0, 0.5] and hb.tolist() == [0.0, 0.0, 1.0, 0.0]
    assert histogram_distance(ha, hb) == pytest.approx(2.0)  # disjoint
    assert histogram_distance(ha, [1.0, 0.0, 1.0, 0.0]) == pytest.approx(1.0)
    assert histogram_distance(hb, hb) == 0.0
    # a constant thickness gets the range value ± 0.5 and lands in the upper half
    assert thickness_histogram(b, bins=2)[0].tolist() == [0.0, 1.0]


def test_bad_input_errors() -> None:
    with pytest.raises(ValueError, match="^a, b:"):
        histogram_distance([1, 2], [1, 2, 3])
    with pytest.raises(ValueError, match="^range:"):
        angle_histogram(Skeleton([Branch([[0, 0], [1, 0], [2, 1]], 1.0)]), range=(1.0, 1.0))
    with pytest.raises(ValueError, match="^a, b:"):
        histogram_distance([0, 0], [1, 2])
    with pytest.raises(ValueError, match="^a, b:"):
        histogram_distance(np.array([1.0, -1.0]), [1, 2])
