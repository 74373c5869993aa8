"""Leaves: new leaves of one species by structural layering, after Assa & Cohen-Or, *More of the Same:
Synthesizing a Variety by Structural Layering* (the paper of issue 17).

From a handful of photos or scans of leaves of one species the pipeline registers each exemplar to a
training leaf (§3), induces the user's layers on every exemplar (§4) and synthesises new leaves by
mixing layers of different exemplars under random warps (§5). This first piece brings the leaves in:

1. :func:`extract` cuts the leaves from a plain background (scanner white, cloth, a photo's backdrop)
   into RGBA, one array per leaf, petiole included (the input of every later stage).

Modules
-------
extract        extract (leaves in)
"""

from __future__ import annotations

# Leaves in (extract.py).
from .extract import extract

__all__ = [
    # Leaves in (extract.py).
    "extract",
]
