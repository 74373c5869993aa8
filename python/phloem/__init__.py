"""phloem: new images of natural structures from a few real examples.

Submodules
----------
bark      the bark pipeline: label maps, shape synthesis, texture-by-numbers
branching branching structures: skeletons, bending/furcation models, fragment synthesis
io        reading and writing images and result sidecars
data      small embedded example images
blend     gradient-domain solvers: seamless (Poisson) blending, smooth field interpolation
patch     patch matching: PatchMatch and exact fields, k nearest patches, k-coherence, voting
seams     exact grid max-flow / min-cut and graph-cut seams between overlapping images
texture   texture synthesis, texture-by-numbers, graph-cut quilting and image completion
shapes    boundary-patch synthesis of binary shapes and label maps (Rosenberger et al. 2009)
trees     tree billboards: atlas splitting, contours, crown/trunk, pin points (Argudo et al. 2017)
leaves    new leaves by structural layering: leaf extraction (Assa & Cohen-Or)
strokes   stroke-based editing of object structure: the stroke model and files (Luo et al.)
metrics   measures of result quality
warp      image warps between contours by mean value coordinates (Hormann & Floater 2006)
cli       the ``phloem`` command

replay(sidecar) re-runs the command a result's sidecar records, to the same bytes.
"""

from __future__ import annotations

import os

from . import (
    _core,
    bark,
    blend,
    branching,
    data,
    io,
    leaves,
    metrics,
    patch,
    seams,
    shapes,
    strokes,
    texture,
    trees,
    warp,
)
from ._memory import MemoryLimitError

__version__: str = _core.__version__

# A forked child inherits phloem's cached thread pools but not their threads; without this
# its first parallel call would hang (e.g. multiprocessing's default "fork" on Linux).
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_core._after_fork_in_child)

from .cli.replay import replay

__all__ = [
    "MemoryLimitError",
    "__version__",
    "bark",
    "blend",
    "branching",
    "data",
    "io",
    "leaves",
    "metrics",
    "patch",
    "replay",
    "seams",
    "shapes",
    "strokes",
    "texture",
    "trees",
    "warp",
]
