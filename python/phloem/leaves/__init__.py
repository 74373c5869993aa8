"""Leaves: new leaves of one species by structural layering, after Assa & Cohen-Or, *More of the Same:
Synthesizing a Variety by Structural Layering* (the paper of issue 17).

From a handful of photos or scans of leaves of one species and scribbles on one of them (the
training leaf), :func:`analyze` registers each exemplar to the training leaf (§3), expands the
scribbles into layers and induces them on every exemplar, peeling one layer at a time (§4), into a
:class:`LeafModel`; :func:`synthesize` makes new leaves from it by mixing layers of different
exemplars under random warps and warping the result into a new shape (§5, Eq. 7).

1. :func:`extract` cuts the leaves from a plain background (scanner white, cloth, a photo's backdrop)
   into RGBA, one array per leaf, petiole included (the input of every later stage).
2. :func:`pose` puts an exemplar on the training leaf by a similarity (principal axes, area), and
   :func:`register` aligns it non-rigidly by TPS-RPM (§3): dense forward and inverse fields.
3. :func:`correct_texture` replaces texture a warp stretched or squeezed by patches of the unwarped
   exemplar (§3, after Fang & Hart 2007); :func:`distortion` says where.
4. :func:`read_scribbles` and :func:`layers_from_scribbles` expand the user's strokes into full
   layers of the training leaf (a lazy-snapping graph cut).
5. :func:`color_distance` is the colour term S of layer induction (Eq. 1): the normalised earth
   mover's distance between the colours of the user's layer and each pixel's 8×8 neighbourhood;
   :func:`induce` carries the user's layer to every aligned exemplar (§4, Eqs. 2–6): colour and
   position fused into D, the threshold δ fitted on the training leaf, λ from the layer's overlap.
6. :func:`synthesize` (§5), with :func:`random_warp` and :func:`blend_fields` (Eq. 7).

Modules
-------
extract        extract (leaves in)
pose           pose (a similarity onto the training leaf)
registration   register, Registration, keypoints (§3)
correction     correct_texture, distortion (§3 texture correction)
scribbles      read_scribbles, layers_from_scribbles
color          color_distance (Eq. 1)
induction      induce, Induction (§4, Eqs. 2–6)
analysis       analyze (§3–4 end to end)
model          LeafModel (what analysis learns, what synthesis uses; save and load)
synthesis      synthesize, random_warp, blend_fields (§5, Eq. 7)
sheet          contact_sheet
"""

from __future__ import annotations

from .analysis import analyze
from .color import color_distance
from .correction import correct_texture, distortion
from .extract import ExtractResult, extract
from .induction import Induction, induce
from .model import LeafModel
from .pose import pose
from .registration import Registration, keypoints, register
from .scribbles import layers_from_scribbles, read_scribbles
from .sheet import contact_sheet
from .synthesis import blend_fields, random_warp, synthesize

__all__ = [
    "ExtractResult",
    "Induction",
    "LeafModel",
    "Registration",
    "analyze",
    "blend_fields",
    "color_distance",
    "contact_sheet",
    "correct_texture",
    "distortion",
    "extract",
    "induce",
    "keypoints",
    "layers_from_scribbles",
    "pose",
    "random_warp",
    "read_scribbles",
    "register",
    "synthesize",
]
