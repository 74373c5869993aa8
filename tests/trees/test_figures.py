"""phloem.trees.figures: the combination tables of the paper's Fig. 13 and Fig. 14."""

from __future__ import annotations

import numpy as np
import pytest

from phloem import trees


def _cell(img: np.ndarray, r: int, c: int, tile: int) -> np.ndarray:
    return img[r * tile : (r + 1) * tile, c * tile : (c + 1) * tile]


def test_morph_table_headers_diagonal_and_triangles(library):
    ts = [library[0], library[1], library[2]]
    tile = 32
    out = trees.morph_table(ts, tile=tile, background=(1.0, 0.0, 1.0))
    assert out.shape == (4 * tile, 4 * tile, 3) and out.dtype == np.float32
    assert np.all(_cell(out, 0, 0, tile) == np.float32([1.0, 0.0, 1.0]))  # the empty corner
    for i in range(1, 4):
        # The first row and column repeat the exemplars shown on the diagonal.
        np.testing.assert_array_equal(_cell(out, 0, i, tile), _cell(out, i, i, tile))
        np.testing.assert_array_equal(_cell(out, i, 0, tile), _cell(out, i, i, tile))
    # Weights 2/3 + 1/3 below the diagonal, 1/3 + 2/3 above it: mirrored cells differ.
    assert not np.array_equal(_cell(out, 2, 1, tile), _cell(out, 1, 2, tile))


def test_morph_table_silhouettes(library):
    ts = [library[0], library[3]]
    tile = 32
    out = trees.morph_table(ts, tile=tile, colors=False)
    for r, c in ((1, 2), (2, 1)):
        cell = _cell(out, r, c, tile)
        # Only the silhouette green, the grey background and their blends along the edge.
        assert np.allclose(cell[..., 0], cell[..., 2])
        assert (cell[..., 1] < 0.4).any() and (cell[..., 1] > 0.79).any()
    with pytest.raises(ValueError, match=r"^trees: a combination table needs at least two"):
        trees.morph_table(ts[:1])
