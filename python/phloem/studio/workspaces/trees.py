"""The trees workspace (Argudo et al. 2017): a library folder of RGBA tree images in the project,
and a job that writes new trees from it (:func:`phloem.trees.variation`), each with a sidecar
naming its exemplars and weights, as ``phloem trees`` does."""

from __future__ import annotations

import secrets
from typing import Annotated, Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, Field

from ... import _files, trees
from ..._progress import Progress
from ..._seeds import sub_seed
from ..files import IMAGE_SUFFIXES
from ..jobs import Work
from ..outputs import Outputs

__all__ = ["TreesJob", "plan"]

_PNG = frozenset({".png"})


class TreesJob(BaseModel):
    """New trees from the RGBA tree images of one project folder (its own images, not its subfolders)."""

    kind: Literal["trees-variations"]
    library: str = Field(description="project name of the folder of RGBA tree images")
    count: int = Field(4, ge=1, le=64, description="new trees to make")
    seed: Annotated[int, Field(ge=0, lt=2**63)] = 0
    n_sources: int = Field(2, ge=1, le=16, description="exemplars combined in each new tree")
    size: int = Field(512, ge=64, le=4096, description="side of the square the trees are normalised to (px)")
    out: str | None = Field(None, description="project name of the folder written; default results/trees-<id>")
    overwrite: bool = False


def plan(req: TreesJob, outputs: Outputs, threads: int | None) -> Work:
    """Read the library's images (with the project's checks) and reserve the outputs; the work."""
    project = outputs.project
    folder = project.resolve(req.library, name_of="library")
    if not folder.is_dir():
        raise FileNotFoundError(f"library: no folder {req.library!r} in the project")
    names = sorted(
        p.name for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file() and not p.is_symlink()
    )
    if not names:
        raise ValueError(f"library: {req.library} holds no images")
    images = [project.read_image(f"{req.library}/{n}", name_of="library") for n in names]
    for n, img in zip(names, images):
        if img.ndim != 3 or img.shape[2] != 4:
            raise ValueError(f"library: {req.library}/{n} has no alpha channel; trees are RGBA side views")
    out_dir = req.out or f"results/trees-{secrets.token_hex(4)}"
    targets = [
        outputs.target(f"{out_dir}/tree_{i:04d}.png", suffixes=_PNG, overwrite=req.overwrite) for i in range(req.count)
    ]
    params = req.model_dump()

    def make(progress: Progress) -> list[str]:
        assert progress is not None
        lib = trees.Library.from_images(images, names=names, size=req.size)
        made: list[tuple[NDArray[np.float32], dict[str, Any]]] = []
        for i in range(req.count):
            seed = sub_seed(req.seed, i)
            v = trees.variation(lib, n_sources=min(req.n_sources, len(lib)), seed=seed, threads=threads,
                                max_memory=project.max_memory)  # fmt: skip
            made.append((v.image, {**params, **v.describe(lib), "variation_seed": seed}))
            progress(i + 1, req.count)
        files = [(t, _files.encode(t, img, None), p) for t, (img, p) in zip(targets, made)]
        return outputs.write_all(files, command=req.kind, seed=req.seed, overwrite=req.overwrite)

    return make
