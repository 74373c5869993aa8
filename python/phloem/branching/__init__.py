"""Branching structures: Sibbing, Pavić, Kobbelt 2010, *Image Synthesis for Branching Structures*.

Learn the bending and branching of rivers, cracks, lightning, ridges or vessels from one
example image with its skeleton, grow new skeletons with the same character, and compose a new
image from fragments of the input. One module per stage, named after what it holds:
``skeleton`` and ``trace`` (§3, §4.1), ``histograms``, ``bending`` (§4.2), ``furcation`` (§4.3),
``growth`` (§4.4, §4.5), ``joins`` (ends that rejoin, beyond the paper), ``fragments`` (§5.1), ``render`` (§5.2, §5.3), ``gaps`` (§5.4),
``rectify`` (Fig. 8), ``frame`` (a photo's frame), ``pipeline`` (all of it); see ``docs/pipelines/branching.md``.

References
----------
.. [1] D. Sibbing, D. Pavić, L. Kobbelt, "Image Synthesis for Branching Structures",
   Computer Graphics Forum 29(7), 2010 (Pacific Graphics).
"""

from __future__ import annotations

from .bending import BendingModel, default_h
from .figures import histogram_figure
from .fragments import Fragment, fragments, rigid_align
from .frame import valid_region
from .furcation import FurcationModel
from .gaps import gap_diversity_default
from .growth import extend, grow
from .histograms import angle_histogram, histogram_distance, thickness_histogram
from .joins import join_ends
from .pipeline import (
    SourceDefaults,
    SynthesisResult,
    course_defaults,
    course_edges_default,
    denoise_default,
    direction_histogram_default,
    fit_models,
    h_default,
    layout_default,
    orientation_default,
    source_defaults,
    synthesize,
)
from .rectify import rectify, unrectify
from .render import RenderResult, render
from .skeleton import Branch, Skeleton, SkeletonError
from .synthetic import synthetic_skeleton
from .trace import estimate_thickness, threshold_climb, trace

__all__ = [
    "BendingModel",
    "Branch",
    "Fragment",
    "FurcationModel",
    "RenderResult",
    "Skeleton",
    "SkeletonError",
    "SourceDefaults",
    "SynthesisResult",
    "angle_histogram",
    "course_defaults",
    "course_edges_default",
    "default_h",
    "denoise_default",
    "direction_histogram_default",
    "estimate_thickness",
    "extend",
    "fit_models",
    "fragments",
    "gap_diversity_default",
    "grow",
    "h_default",
    "histogram_distance",
    "histogram_figure",
    "join_ends",
    "layout_default",
    "orientation_default",
    "rectify",
    "render",
    "rigid_align",
    "source_defaults",
    "synthesize",
    "synthetic_skeleton",
    "thickness_histogram",
    "threshold_climb",
    "trace",
    "unrectify",
    "valid_region",
]
