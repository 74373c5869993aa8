"""Bounding boxes against brute force: the smallest slices holding every True pixel, grown and clipped."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from phloem._boxes import bounding_box, points_box


@given(arrays(np.bool_, st.tuples(st.integers(1, 12), st.integers(1, 12))), st.integers(0, 4))
def test_bounding_box_is_the_brute_force_box(mask: np.ndarray, margin: int) -> None:
    ys, xs = bounding_box(mask, margin)
    if not mask.any():
        assert (ys, xs) == (slice(0, mask.shape[0]), slice(0, mask.shape[1]))
        return
    r, c = np.nonzero(mask)
    assert ys == slice(max(r.min() - margin, 0), min(r.max() + margin + 1, mask.shape[0]))
    assert xs == slice(max(c.min() - margin, 0), min(c.max() + margin + 1, mask.shape[1]))
    assert mask[ys, xs].sum() == mask.sum()
    assert points_box(r, c, mask.shape, margin) == (ys, xs)
