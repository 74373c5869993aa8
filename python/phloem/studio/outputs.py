"""Where jobs write: checked names inside the project, each file with its sidecar, written
together through :class:`phloem._files.Transaction` (a refused overwrite writes nothing)."""

from __future__ import annotations

import base64
import binascii
import io as _bytes_io
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, Field

from .. import _files, io
from .files import Project

__all__ = ["MAX_SIDE", "LabelMap", "Outputs", "Side", "decode_label_map", "gray_png"]

MAX_SIDE = 8192
Side = Annotated[int, Field(ge=1, le=MAX_SIDE)]


class LabelMap(BaseModel):
    """A label map as the page paints it: ``data`` is base64 of ``height × width`` bytes, row by row."""

    width: Side
    height: Side
    n_labels: int = Field(ge=1, le=16)
    data: str


def decode_label_map(body: LabelMap, max_pixels: int) -> NDArray[np.uint8]:
    """The ``(height, width)`` labels of a painted map, each below ``n_labels`` (``ValueError`` naming the field)."""
    if body.width * body.height > max_pixels:
        raise ValueError(f"width: {body.width}×{body.height} is over the pixel limit of {max_pixels}")
    try:
        raw = base64.b64decode(body.data, validate=True)
    except (binascii.Error, ValueError):
        raise ValueError("data: not base64") from None
    if len(raw) != body.width * body.height:
        raise ValueError(f"data: expected {body.width * body.height} bytes (width × height), got {len(raw)}")
    lab = np.frombuffer(raw, np.uint8).reshape(body.height, body.width)
    if int(lab.max()) >= body.n_labels:
        raise ValueError(f"data: label {int(lab.max())} is not below n_labels = {body.n_labels}")
    return lab


def gray_png(labels: NDArray[Any]) -> bytes:
    """An 8-bit grey PNG of small integers as they are (label ``k`` stored as ``k``, not spread to
    grey levels): the integer label file :func:`phloem.leaves.read_scribbles` reads."""
    from PIL import Image

    buf = _bytes_io.BytesIO()
    Image.fromarray(np.ascontiguousarray(labels, np.uint8), "L").save(buf, "PNG")
    return buf.getvalue()


@dataclass(frozen=True)
class Outputs:
    """The project's output files of jobs."""

    project: Project

    def target(self, name: str, *, suffixes: frozenset[str], overwrite: bool, name_of: str = "out") -> Path:
        """The path of an output ``name`` and its sidecar, refused before any work if either exists
        (without ``overwrite``) or the name is not a plain project name with one of ``suffixes``."""
        path = self.project.resolve(name, suffixes=suffixes, name_of=name_of)
        for p in (path, io.sidecar_path(path)):
            if (p.exists() or p.is_symlink()) and not overwrite:
                raise FileExistsError(
                    f"{name_of}: {self.project.name(p)!r} already exists (pass overwrite=true to replace it)"
                )
        return path

    def image(
        self, path: Path, image: Any, *, command: str, parameters: Mapping[str, Any], seed: int | None, overwrite: bool
    ) -> str:
        """Write an image result and its sidecar; its project name."""
        return self.data(path, _files.encode(path, image, None), command=command, parameters=parameters, seed=seed,
                         overwrite=overwrite)  # fmt: skip

    def data(
        self, path: Path, data: bytes, *, command: str, parameters: Mapping[str, Any], seed: int | None, overwrite: bool
    ) -> str:
        """Write a file (image bytes, skeleton JSON) and its sidecar together; its project name."""
        return self.write_all([(path, data, parameters)], command=command, seed=seed, overwrite=overwrite)[0]

    def write_all(
        self,
        files: Sequence[tuple[Path, bytes, Mapping[str, Any] | None]],
        *,
        command: str,
        seed: int | None,
        overwrite: bool,
    ) -> list[str]:
        """Write several files, each with its sidecar unless its parameters are None, all or none of
        them (folders made as needed); their project names."""
        with _files.Transaction(overwrite, make_folders=True) as tx:
            for path, _, parameters in files:
                self.project.resolve(self.project.name(path))  # checked again when written: no link on the way
                tx.reserve(path)
                if parameters is not None:
                    tx.reserve(io.sidecar_path(path))
            for path, data, parameters in files:
                tx.stage(path, data)
                if parameters is not None:
                    tx.stage(io.sidecar_path(path), io._sidecar(path, f"studio {command}", parameters, seed))
            tx.commit()
        return [self.project.name(p) for p, _, _ in files]
