"""branching.synthesize: fitted models passed back in give the same image as fitting again."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phloem import branching


def _river() -> np.ndarray:
    img = np.full((96, 128), 0.8, np.float32)
    cv2.line(img, (5, 90), (70, 40), 0.1, 5)
    cv2.line(img, (70, 40), (125, 5), 0.1, 4)
    cv2.line(img, (70, 40), (90, 92), 0.1, 3)
    return img


def test_models_of_an_earlier_result_make_the_same_image_as_fitting_again():
    img, opts = _river(), {"kind": "dark", "sigmas": (1.5, 2.5)}
    first = branching.synthesize(img, trace_options=opts, seed=1)
    again = branching.synthesize(img, trace_options=opts, seed=2)
    reused = branching.synthesize(img, first.source, seed=2, models=(first.bending, first.furcation))
    assert np.array_equal(reused.image, again.image) and reused.target == again.target
    assert reused.bending is first.bending


@pytest.mark.parametrize("models", [("a", None), (None,), [1, 2]])
def test_models_of_the_wrong_kind_are_refused(models):
    with pytest.raises(TypeError, match="^models: expected"):
        branching.synthesize(_river(), trace_options={"kind": "dark", "sigmas": (1.5,)}, models=models)
