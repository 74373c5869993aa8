"""The textures workspace: :func:`phloem.texture.synthesize` and :func:`~phloem.texture.quilt` from
an exemplar, and hole filling (:func:`~phloem.texture.complete`) with a mask painted in the page,
saved as the PNG ``phloem complete`` reads (white where pixels are filled)."""

from __future__ import annotations

import secrets
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from fastapi import FastAPI, Query
from pydantic import BaseModel, Field

from ... import _files, texture
from ..._masks import hole_from_mask
from ..._progress import Progress
from ..files import Project, name_pattern
from ..jobs import Work
from ..outputs import LabelMap, Outputs, Side, decode_label_map, gray_png

__all__ = ["TextureCompleteJob", "TextureJob", "mount", "plan"]

_PNG = frozenset({".png"})
_OUT = frozenset({".png", ".tif", ".tiff"})
Seed = Annotated[int, Field(ge=0, lt=2**63)]


class TextureJob(BaseModel):
    """A texture of any size from an exemplar: texture optimisation or graph-cut quilting."""

    kind: Literal["texture-synthesize", "texture-quilt"]
    image: str = Field(description="project name of the exemplar")
    size: tuple[Side, Side] = Field(description="output [height, width]")
    seed: Seed = 0
    out: str | None = Field(None, description="project name of the result; default results/<kind>-<id>.png")
    overwrite: bool = False


class TextureCompleteJob(BaseModel):
    """Fill the masked pixels of an image from the rest of it (:func:`phloem.texture.complete`)."""

    kind: Literal["texture-complete"]
    image: str = Field(description="project name of the image")
    mask: str = Field(description="project name of the mask PNG: white where pixels are filled")
    seed: Seed = 0
    out: str | None = Field(None, description="project name of the result; default results/filled-<id>.png")
    overwrite: bool = False


def sources_image(sources: Any, shape: tuple[int, int]) -> np.ndarray:
    """Quilting's source map shown as colour: red the exemplar column, green its row (patches and
    their seams show as flat gradients meeting along edges)."""
    h, w = shape
    out = np.zeros((*sources.shape[:2], 3), np.float32)
    out[..., 0] = sources[..., 1] / max(w - 1, 1)
    out[..., 1] = sources[..., 0] / max(h - 1, 1)
    out[..., 2] = 0.5
    return out


def plan(req: TextureJob | TextureCompleteJob, outputs: Outputs, threads: int | None) -> Work:
    """Check a textures job's inputs and outputs; its work."""
    project = outputs.project
    params = req.model_dump()
    img = project.read_image(req.image)
    if isinstance(req, TextureCompleteJob):
        m = project.read_image(req.mask, name_of="mask")
        hole = hole_from_mask(m, req.mask, alpha=False, invert=False)
        if hole.shape != img.shape[:2]:
            raise ValueError(
                f"mask: {req.mask} is {hole.shape[1]}×{hole.shape[0]}, but the image is {img.shape[1]}×{img.shape[0]}"
            )
        if not hole.any():
            raise ValueError(f"mask: {req.mask} marks no pixel to fill (white = fill)")
        out = outputs.target(req.out or f"results/filled-{secrets.token_hex(4)}.png", suffixes=_OUT,
                             overwrite=req.overwrite)  # fmt: skip

        def fill(progress: Progress) -> list[str]:
            res = texture.complete(img, hole, seed=req.seed, threads=threads, progress=progress,
                                   max_memory=project.max_memory)  # fmt: skip
            assert progress is not None
            progress(1, 1)
            return [
                outputs.image(out, res, command=req.kind, parameters=params, seed=req.seed, overwrite=req.overwrite)
            ]

        return fill
    if req.size[0] * req.size[1] > project.max_pixels:
        raise ValueError(f"size: {req.size[1]}×{req.size[0]} is over the pixel limit of {project.max_pixels}")
    name = req.kind.removeprefix("texture-")
    out = outputs.target(
        req.out or f"results/{name}-{secrets.token_hex(4)}.png", suffixes=_OUT, overwrite=req.overwrite
    )
    seams = out.with_name(f"{out.stem}_sources.png")
    if req.kind == "texture-quilt":
        outputs.target(outputs.project.name(seams), suffixes=_OUT, overwrite=req.overwrite)

    def make(progress: Progress) -> list[str]:
        kw: dict[str, Any] = {
            "seed": req.seed,
            "threads": threads,
            "progress": progress,
            "max_memory": project.max_memory,
        }
        if req.kind == "texture-synthesize":
            res = texture.synthesize(img, req.size, **kw)
            assert progress is not None
            progress(1, 1)
            return [
                outputs.image(out, res, command=req.kind, parameters=params, seed=req.seed, overwrite=req.overwrite)
            ]
        q = texture.quilt(img, req.size, full_output=True, **kw)
        assert progress is not None
        progress(1, 1)
        files: list[tuple[Path, bytes, dict[str, Any] | None]] = []
        files.append((out, _files.encode(out, q.texture, None), params))
        files.append((seams, _files.encode(seams, sources_image(q.sources, img.shape[:2]), None), params))
        return outputs.write_all(files, command=req.kind, seed=req.seed, overwrite=req.overwrite)

    return make


def _png_name(description: str) -> Any:
    return Query(description=description, json_schema_extra={"pattern": name_pattern(_PNG)})


def mount(app: FastAPI, project: Project, guarded: Callable[[Callable[[], Any]], Any], saved: type[BaseModel]) -> None:
    """The textures workspace's endpoint on ``app``."""

    @app.put("/api/mask", response_model=saved)
    def put_mask(
        path: Annotated[str, _png_name("project name of the PNG to write")], body: LabelMap, overwrite: bool = False
    ) -> Any:
        """Write a painted mask (labels 0 keep, 1 fill) as the black and white PNG ``phloem complete`` reads."""

        def save() -> Any:
            project.resolve(path, suffixes=_PNG)
            lab = decode_label_map(body, project.max_pixels)
            project.write_bytes(path, gray_png(np.where(lab > 0, 255, 0)), overwrite=overwrite)
            return saved(path=path, width=body.width, height=body.height)

        return guarded(save)
