"""Every Examples section in phloem's docstrings runs and shows what it claims."""

from __future__ import annotations

import doctest
import importlib

import pytest


@pytest.mark.parametrize(
    "module",
    [
        "phloem.io",
        "phloem.data",
        "phloem.patch",
        "phloem.seams",
        "phloem.texture",
        "phloem.metrics",
        "phloem.blend",
        "phloem.bark",
        "phloem.shapes",
        "phloem.trees.atlas",
        "phloem.trees.contours",
        "phloem.trees.segmentation",
        "phloem.trees.classifier",
        "phloem.trees.preprocessing",
        "phloem.trees.contour_space",
        "phloem.trees.transfer",
        "phloem.trees.library",
        "phloem.trees.synthesis",
        "phloem.trees.figures",
        "phloem.warp",
        "phloem.branching.skeleton",
        "phloem.branching.histograms",
        "phloem.branching.bending",
        "phloem.branching.furcation",
        "phloem.branching.growth",
        "phloem.branching.synthetic",
        "phloem.branching.fragments",
        "phloem.branching.render",
        "phloem.branching.rectify",
        "phloem.branching.trace",
        "phloem.branching.figures",
        "phloem.branching.pipeline",
    ],
)
def test_docstring_examples(module):
    mod = importlib.import_module(module)
    result = doctest.testmod(mod, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0
    if module != "phloem.data":
        assert result.attempted > 0, f"{module} has no examples"
