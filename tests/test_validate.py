"""phloem._validate: argument checks give one-line messages that name the argument, never numpy's."""

from __future__ import annotations

import numpy as np
import pytest

from phloem._validate import as_image, as_labels, as_mask, check_convex_weights


@pytest.mark.parametrize(
    ("value", "err", "match"),
    [
        ([[0.1, 0.2], [0.3]], TypeError, r"^image: expected an array of numbers, got a ragged or mixed list$"),
        ([[0.1, "a"], [0.3, None]], TypeError, r"^image: expected a real-valued image array, got dtype object$"),
        (np.zeros((3, 4), object), TypeError, r"^image: expected a real-valued image array, got dtype object$"),
        (np.zeros((0, 4)), ValueError, r"^image: expected a non-empty image, got shape \(0, 4\)$"),
        (np.zeros((2, 2, 2, 2)), ValueError, r"^image: expected shape \(H, W\) or \(H, W, C\), got \(2, 2, 2, 2\)$"),
    ],
)
def test_as_image_messages(value, err, match):
    with pytest.raises(err, match=match):
        as_image(value, "image")


def test_ragged_inputs_name_the_argument():
    ragged = [[1, 2], [3]]
    for call in (
        lambda: as_labels(ragged, "labels"),
        lambda: as_mask(ragged, "mask", (2, 2)),
        lambda: check_convex_weights([[0.5], [0.25, 0.25]], 2, "weights"),
    ):
        with pytest.raises(TypeError, match=r"^(labels|mask|weights): expected an array of numbers, got a ragged"):
            call()


def test_views_and_byte_orders_are_accepted():
    big = np.arange(24, dtype=">f8").reshape(4, 6) / 24
    out = as_image(big[:, ::2], "image")
    assert out.flags.c_contiguous and out.dtype == np.float32 and out.shape == (4, 3, 1)
    np.testing.assert_array_equal(out[..., 0], big[:, ::2].astype(np.float32))


@pytest.mark.filterwarnings("error")
def test_float64_beyond_float32_is_refused_without_numpy_warning():
    # the cast to float32 made 1e300 inf with numpy's "overflow encountered in cast" on stderr
    with pytest.raises(
        ValueError, match=r"^image: expected finite values, found 1e\+300 at \(row 0, col 1, channel 0\)$"
    ):
        as_image(np.array([[0.5, 1e300]]), "image")
