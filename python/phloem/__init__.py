"""phloem: new images of natural structures from a few real examples.

Submodules
----------
io        reading and writing images and result sidecars
data      small embedded example images
patch     patch matching: PatchMatch and exact fields, k nearest patches, k-coherence, voting
texture   texture synthesis and image completion
metrics   measures of result quality
cli       the ``phloem`` command
"""

from __future__ import annotations

from . import _core, data, io, metrics, patch, texture

__version__: str = _core.__version__

__all__ = ["__version__", "data", "io", "metrics", "patch", "texture"]
