"""phloem.bark.label_files: label maps as flat grey images that survive a paint program."""

from __future__ import annotations

import numpy as np
import pytest

import phloem
from phloem import bark


def test_label_maps_round_trip_through_png(tmp_path):
    labels = np.random.default_rng(3).integers(0, 4, (30, 40)).astype(np.int32) * 7 + 2  # any values
    path = tmp_path / "labels.png"
    phloem.io.write_image(path, bark.encode_labels(labels))
    back = bark.decode_labels(phloem.io.read_image(path))
    np.testing.assert_array_equal(back, np.unique(labels, return_inverse=True)[1].reshape(labels.shape))
    with pytest.raises(ValueError, match="^image: found 256 distinct colours"):
        bark.decode_labels(np.linspace(0, 1, 256, dtype=np.float32).reshape(16, 16))


@pytest.mark.parametrize(
    "image",
    [
        # two different colours whose 8-bit keys collided: (0, 256/255) and (1/255, 0) became one label
        np.array([[[0, 256 / 255], [1 / 255, 0]]], np.float32),
        np.array([[1e38, 0]], np.float32),  # numpy's "overflow encountered in multiply"
        np.array([[-0.5, 0.5]], np.float32),
    ],
)
def test_decode_labels_refuses_values_outside_0_1(image):
    with pytest.raises(ValueError, match=r"^image: expected values in \[0, 1\] \(a label map image\), got "):
        bark.decode_labels(image)
