"""What analysis learns from a set of leaves, and what synthesis needs: :class:`LeafModel`.

Every array lives on one canvas, the training leaf's frame padded so that every exemplar
fits (``docs/pipelines/leaves.md`` says how it is chosen): the exemplars' registration
fields, induced layers and inpainted backgrounds then share one pixel grid, and Eq. 7's
convex combination of inverse warps is a per-pixel sum.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["LeafModel"]

F32 = NDArray[np.float32]


@dataclass(frozen=True)
class LeafModel:
    """The analysis of a set of leaves of one species (Assa & Cohen-Or §3–4).

    Index ``i`` runs over the exemplars (the training leaf is one of them, with an identity
    registration); index ``k`` over the user's layers in removal order, the last one being
    the residual (background) layer, which has no mask of its own.

    Attributes
    ----------
    training : int
        Which exemplar the scribbles were drawn on.
    order : list of int
        The scribble labels in removal order; ``order[-1]`` is the background layer.
    leaves : list of (H, W, 4) ndarray of float32
        Each exemplar as placed on the canvas, unaligned (RGBA, straight alpha).
    forward : list of (H, W, 2) ndarray of float32
        ``W_i``: for each canvas pixel of the training frame, the displacement ``(dx, dy)``
        to the exemplar position it comes from (:attr:`Registration.forward`).
    inverse : list of (H, W, 2) ndarray of float32
        ``W_i⁻¹``: for each canvas pixel of the exemplar frame, the displacement to its
        training-frame position (:attr:`Registration.inverse`), the fields Eq. 7 blends.
    residual : list of float
        Registration error of each exemplar in px (0 for the training leaf).
    aligned : list of (H, W, 4) ndarray of float32
        Each exemplar warped into the training frame and texture-corrected.
    masks : list of list of (H, W) ndarray of bool
        ``masks[i][k]``: layer ``k`` induced on exemplar ``i`` (the user's expanded layer on
        the training leaf), for every layer but the background.
    dissimilarity : list of list of (H, W) ndarray of float32
        ``D`` of Eq. 2 for exemplar ``i`` and layer ``k`` (0 inside the layer's likely
        pixels, larger away from them).
    layers : list of list of (H, W, 4) ndarray of float32
        ``layers[i][k]``: the pixels of layer ``k`` on exemplar ``i`` as they were when it was
        peeled (colours of the image left by the earlier layers; alpha the layer's mask).
    background : list of (H, W, 4) ndarray of float32
        Each aligned exemplar with every non-background layer peeled and completed.
    lam, delta, objective : list of float
        Per non-background layer: ``λ`` (Eq. 5), the threshold ``δ`` and the value of the
        Eq. 4 objective it reached on the training leaf.
    """

    training: int
    order: list[int]
    leaves: list[F32]
    forward: list[F32]
    inverse: list[F32]
    residual: list[float]
    aligned: list[F32]
    masks: list[list[NDArray[np.bool_]]]
    dissimilarity: list[list[F32]]
    layers: list[list[F32]]
    background: list[F32]
    lam: list[float]
    delta: list[float]
    objective: list[float]

    @property
    def n_exemplars(self) -> int:
        """How many exemplar leaves, the training leaf included."""
        return len(self.leaves)

    @property
    def n_layers(self) -> int:
        """How many layers, the background layer included."""
        return len(self.order)

    @property
    def size(self) -> tuple[int, int]:
        """The canvas ``(H, W)``."""
        h, w = self.leaves[0].shape[:2]
        return int(h), int(w)
