"""Tree bark from one small photo: the pipeline of Laitoch 2018, *Procedural Modeling of Tree Bark*.

The pipeline (thesis §3.2) has three stages, each with a result an artist can inspect, edit and
feed back in:

1. :func:`input_labels` segments the photo into ``n_labels`` regions (§3.5): non-local-means
   denoising, CIELAB, k-means, majority-filter erosion of tiny regions;
2. :func:`synthesize_labels` grows a new label map of any size with the same shapes (§3.6:
   Rosenberger et al. 2009 layered shape synthesis, or phloem's joint multi-label variant);
3. :func:`phloem.texture.by_numbers` paints the new label map with bark from the photo (§3.3–3.4:
   Fan et al. 2012 texture-by-numbers with smart initialisation).

:func:`generate` runs all three; give it ``labels_in`` or ``labels_out`` to resume from edited
maps. :func:`add_edge_label` is the optional extra region of §3.5.5, applied to both maps once
both exist; :func:`cylinder_preview` wraps a texture around a trunk for a quick look.
"""

from __future__ import annotations

from .label_files import decode_labels, encode_labels
from .labels import add_edge_label, input_labels
from .pipeline import BarkResult, generate
from .preview import cylinder_preview
from .synthesis import synthesize_labels

__all__ = [
    "BarkResult",
    "add_edge_label",
    "cylinder_preview",
    "decode_labels",
    "encode_labels",
    "generate",
    "input_labels",
    "synthesize_labels",
]
