"""What analysis learns from a set of leaves, and what synthesis needs: :class:`LeafModel`.

Every array lives on one canvas, the training leaf's frame padded so that every exemplar
fits (``docs/pipelines/leaves.md`` says how it is chosen): the exemplars' registration
fields, induced layers and inpainted backgrounds then share one pixel grid, and Eq. 7's
convex combination of inverse warps is a per-pixel sum.
"""

from __future__ import annotations

import io
import json
import math
import os
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import _files, _json

__all__ = ["LeafModel"]

F32 = NDArray[np.float32]

#: The ``format`` entry of ``model.json``; ``version`` changes when the folder's layout does.
MODEL_FORMAT = "phloem.leaves.LeafModel"
MODEL_VERSION = 1


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
    scale : list of float
        Per exemplar, the linear factor its pose scaled it by to the training leaf's area
        (empty: all 1); synthesis gives each new leaf a size between the exemplars' own.
    kappa : float
        κ of Eq. 5 that ``lam`` was computed with: ``λ/κ`` is the layer's overlap across the
        exemplars, 1 for a perfectly structural layer, and sets how far synthesis moves it.
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
    scale: list[float] = field(default_factory=list)
    kappa: float = 1.5

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

    # -- files -------------------------------------------------------------------------------
    def save(self, path: str | os.PathLike[str], *, overwrite: bool = False) -> None:
        """Write the model to the folder ``path``: ``model.json`` and one ``exemplar_NNN.npz``
        per exemplar (lossless float32, deflated). All files appear together or none do; an
        existing file is replaced only with ``overwrite``."""
        _files.write_folder(path, self.files(), overwrite)

    def files(self) -> dict[str, bytes]:
        """The folder :meth:`save` writes, as file name → bytes."""
        from .. import __version__

        meta = {
            "format": MODEL_FORMAT,
            "version": MODEL_VERSION,
            "phloem_version": __version__,
            "training": self.training,
            "order": list(self.order),
            "size": list(self.size),
            "n_exemplars": self.n_exemplars,
            "residual": [float(v) for v in self.residual],
            "scale": [float(v) for v in self.scale],
            "lam": [float(v) for v in self.lam],
            "delta": [float(v) for v in self.delta],
            "objective": [float(v) for v in self.objective],
            "kappa": float(self.kappa),
        }
        out = {"model.json": (json.dumps(meta, indent=1) + "\n").encode()}
        for i in range(self.n_exemplars):
            out[f"exemplar_{i:03d}.npz"] = self._exemplar_bytes(i)
        return out

    def _exemplar_bytes(self, i: int) -> bytes:
        n_k = len(self.lam)
        h, w = self.size
        arrays = {
            "leaf": self.leaves[i],
            "forward": self.forward[i],
            "inverse": self.inverse[i],
            "aligned": self.aligned[i],
            "background": self.background[i],
            "masks": np.stack(self.masks[i]) if n_k else np.zeros((0, h, w), bool),
            "dissimilarity": np.stack(self.dissimilarity[i]) if n_k else np.zeros((0, h, w), np.float32),
            "layers": np.stack(self.layers[i]) if n_k else np.zeros((0, h, w, 4), np.float32),
        }
        return _files.npz_bytes(arrays)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> LeafModel:
        """Read a model written by :meth:`save`; a missing, foreign or inconsistent folder
        raises a one-line ``ValueError`` naming the file."""
        folder = Path(path)
        if not folder.is_dir():
            raise ValueError(f"path: {folder} is not a folder written by LeafModel.save")
        meta = _json.read_json(folder / "model.json", "path")
        if not isinstance(meta, dict) or meta.get("format") != MODEL_FORMAT:
            raise ValueError(f"path: {folder / 'model.json'} is not a phloem leaf model")
        if meta.get("version") != MODEL_VERSION:
            raise ValueError(
                f"path: {folder / 'model.json'} has model version {meta.get('version')!r}; this phloem reads {MODEL_VERSION}"
            )
        try:
            n = int(meta["n_exemplars"])
            h, w = (int(v) for v in meta["size"])
            order = [int(v) for v in meta["order"]]
            lists = {k: [float(v) for v in meta[k]] for k in ("residual", "scale", "lam", "delta", "objective")}
            training = int(meta["training"])
            kappa = float(meta["kappa"])
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"path: {folder / 'model.json'} lacks a field or has one of the wrong type") from None
        n_k = len(order) - 1
        if not (n >= 2 and 0 <= training < n and h > 0 and w > 0 and sorted(order) == list(range(1, n_k + 2))) or not (
            math.isfinite(kappa) and kappa > 0
        ):
            raise ValueError(
                f"path: {folder / 'model.json'} is inconsistent (exemplars, training index, size or order)"
            )
        if (
            len(lists["residual"]) != n
            or len(lists["scale"]) not in (0, n)
            or any(len(lists[k]) != n_k for k in ("lam", "delta", "objective"))
        ):
            raise ValueError(f"path: {folder / 'model.json'} has per-exemplar or per-layer lists of the wrong length")
        expect = {
            "leaf": ((h, w, 4), np.float32),
            "forward": ((h, w, 2), np.float32),
            "inverse": ((h, w, 2), np.float32),
            "aligned": ((h, w, 4), np.float32),
            "background": ((h, w, 4), np.float32),
            "masks": ((n_k, h, w), np.bool_),
            "dissimilarity": ((n_k, h, w), np.float32),
            "layers": ((n_k, h, w, 4), np.float32),
        }
        per: list[dict[str, Any]] = []
        for i in range(n):
            p = folder / f"exemplar_{i:03d}.npz"
            try:
                # read whole first: np.load leaves the file open when the archive is corrupt
                with np.load(io.BytesIO(p.read_bytes()), allow_pickle=False) as z:
                    arrays = {k: z[k] for k in expect}
            except (OSError, KeyError, ValueError, zipfile.BadZipFile, EOFError, zlib.error) as e:
                raise ValueError(f"path: {p} cannot be read as a leaf model exemplar ({type(e).__name__})") from None
            for k, (shape, dtype) in expect.items():
                a = arrays[k]
                if a.shape != shape or a.dtype != dtype:
                    raise ValueError(
                        f"path: {p}: {k} has shape {a.shape} {a.dtype}, expected {shape} {np.dtype(dtype)}"
                    )
                if a.dtype == np.float32 and not np.isfinite(a).all():
                    raise ValueError(f"path: {p}: {k} holds NaN or infinite values")
            per.append(arrays)
        return cls(
            training=training,
            order=order,
            leaves=[a["leaf"] for a in per],
            forward=[a["forward"] for a in per],
            inverse=[a["inverse"] for a in per],
            residual=lists["residual"],
            aligned=[a["aligned"] for a in per],
            masks=[list(a["masks"]) for a in per],
            dissimilarity=[list(a["dissimilarity"]) for a in per],
            layers=[list(a["layers"]) for a in per],
            background=[a["background"] for a in per],
            lam=lists["lam"],
            delta=lists["delta"],
            objective=lists["objective"],
            scale=lists["scale"],
            kappa=kappa,
        )
