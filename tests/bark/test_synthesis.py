"""phloem.bark.synthesis: the shape engine under the bark pipeline's defaults."""

from __future__ import annotations

import numpy as np

import phloem
from phloem import bark, shapes


def test_synthesize_labels_is_the_shape_engine_with_bark_defaults():
    lab = bark.input_labels(phloem.data.bark()[:64, :64], 2)
    got = bark.synthesize_labels(lab, (40, 48), patch_size=5, seed=3)
    want = shapes.synthesize_labels(lab, (40, 48), method="joint", rotations="half", patch_size=5, seed=3)
    np.testing.assert_array_equal(got, want)
