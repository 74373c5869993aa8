"""Leaves: new leaves of one species by structural layering, after Assa & Cohen-Or, *More of the Same:
Synthesizing a Variety by Structural Layering* (the paper of issue 17).

From a handful of photos or scans of leaves of one species the pipeline registers each exemplar to a
training leaf (§3), induces the user's layers on every exemplar (§4) and synthesises new leaves by
mixing layers of different exemplars under random warps (§5). Built so far:

1. :func:`extract` cuts the leaves from a plain background (scanner white, cloth, a photo's backdrop)
   into RGBA, one array per leaf, petiole included (the input of every later stage).
2. :func:`register` aligns an exemplar to the training leaf by TPS-RPM (§3): dense forward and
   inverse displacement fields.
3. :func:`correct_texture` replaces texture a warp stretched or squeezed by patches of the unwarped
   exemplar (§3, after Fang & Hart 2007); :func:`distortion` says where.
4. :func:`color_distance` is the colour term S of layer induction (Eq. 1): the normalised earth
   mover's distance between the colours of the user's layer and each pixel's 8×8 neighbourhood.

Modules
-------
extract        extract (leaves in)
registration   register, Registration, keypoints (§3)
correction     correct_texture, distortion (§3 texture correction)
color          color_distance (Eq. 1)
model          LeafModel (what analysis learns, what synthesis uses)
"""

from __future__ import annotations

from .color import color_distance

# correction
from .correction import correct_texture, distortion
from .extract import extract
from .model import LeafModel
from .registration import Registration, keypoints, register

__all__ = [
    "LeafModel",
    "Registration",
    "color_distance",
    # correction
    "correct_texture",
    "distortion",
    "extract",
    "keypoints",
    "register",
]
