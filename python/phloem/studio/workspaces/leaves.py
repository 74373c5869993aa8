"""The leaves workspace (Assa & Cohen-Or, 002 §6): scribbles painted on the training leaf, saved as
the integer label PNG ``phloem leaves analyze --scribbles`` reads; expansion to full layers (the
lazy-snapping cut) and analysis with synthesis as jobs.

Scribbles are painted on the training leaf's whole file, as the page shows it; the jobs cut them
to the leaf :func:`phloem.leaves.extract` finds there (the CLI does the same with a scan).
"""

from __future__ import annotations

import base64
import secrets
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from fastapi import FastAPI, Query
from numpy.typing import NDArray
from pydantic import BaseModel, Field

from ... import _files, io, leaves
from ..._progress import Progress
from ..._seeds import sub_seed
from ..files import IMAGE_SUFFIXES, Project, name_pattern
from ..jobs import Work
from ..outputs import LabelMap, Outputs, decode_label_map, gray_png

__all__ = ["LAYER_COLOURS", "LeavesExpandJob", "LeavesSynthesizeJob", "mount", "plan"]

#: The page's brush colour of layer 1, 2, …; expanded layers are written in the same colours.
LAYER_COLOURS = ("#e6194b", "#4363d8", "#ffd700", "#3cb44b", "#f58231", "#911eb4", "#42d4f4", "#f032e6")
_PNG = frozenset({".png"})
Seed = Annotated[int, Field(ge=0, lt=2**63)]


class LeavesExpandJob(BaseModel):
    """Expand scribbles on the training leaf to full layers (:func:`phloem.leaves.layers_from_scribbles`)."""

    kind: Literal["leaves-expand"]
    image: str = Field(description="project name of the training leaf's image (a scan or an RGBA leaf)")
    scribbles: str = Field(description="project name of the scribble PNG (the image's size or the leaf's)")
    seed: Seed = 0
    out: str | None = Field(
        None, description="project name of the layers PNG; default <scribbles>_layers.png beside them"
    )
    overwrite: bool = False


class LeavesSynthesizeJob(BaseModel):
    """Analyse leaves with the scribbles (:func:`phloem.leaves.analyze`) and make new ones (:func:`phloem.leaves.synthesize`)."""

    kind: Literal["leaves-synthesize"]
    leaves: list[str] = Field(
        min_length=1, max_length=32, description="project names of the leaf images (every leaf in each)"
    )
    training: str | None = Field(
        None, description="the image, one of leaves, whose first leaf is the training leaf; default leaves[0]"
    )
    scribbles: str = Field(description="project name of the scribble PNG on the training image")
    count: int = Field(4, ge=1, le=64, description="new leaves to make")
    seed: Seed = 0
    points: int = Field(100, ge=10, le=1000, description="edge keypoints of the registration (§3)")
    out: str | None = Field(None, description="project name of the folder written; default results/leaves-<id>")
    overwrite: bool = False


def _colours() -> NDArray[np.float32]:
    return np.array([[int(c[i : i + 2], 16) / 255 for i in (1, 3, 5)] for c in LAYER_COLOURS], np.float32)


def layer_image(labels: NDArray[Any]) -> NDArray[np.float32]:
    """RGBA: layer ``k`` in ``LAYER_COLOURS[k - 1]``, transparent where ``labels`` is 0 (the scribble
    format's colour form, so the file is itself valid scribbles)."""
    out = np.zeros((*labels.shape, 4), np.float32)
    cols = _colours()
    on = labels > 0
    out[on, :3] = cols[(labels[on] - 1) % len(cols)]
    out[on, 3] = 1.0
    return out


def _cut(labels: NDArray[Any], box: tuple[int, int, int, int]) -> NDArray[np.int32]:
    """``labels`` of a whole file cut to a leaf's box (which may reach past the file's edge)."""
    y0, y1, x0, x1 = box
    fh, fw = labels.shape
    out = np.zeros((y1 - y0, x1 - x0), np.int32)
    sy, sx = slice(max(0, y0), min(fh, y1)), slice(max(0, x0), min(fw, x1))
    out[sy.start - y0 : sy.stop - y0, sx.start - x0 : sx.stop - x0] = labels[sy, sx]
    return out


def _paste(labels: NDArray[Any], box: tuple[int, int, int, int], shape: tuple[int, int]) -> NDArray[np.int32]:
    """The inverse of :func:`_cut`: a leaf's labels placed in its file's frame."""
    y0, y1, x0, x1 = box
    out = np.zeros(shape, np.int32)
    sy, sx = slice(max(0, y0), min(shape[0], y1)), slice(max(0, x0), min(shape[1], x1))
    out[sy, sx] = labels[sy.start - y0 : sy.stop - y0, sx.start - x0 : sx.stop - x0]
    return out


def _leaves_of(project: Project, name: str, name_of: str) -> tuple[NDArray[np.float32], Any]:
    img = project.read_image(name, name_of=name_of)
    try:
        return img, leaves.extract(img, full_output=True)
    except ValueError as e:
        raise ValueError(f"{name_of}: {name}: {str(e).split(': ', 1)[-1]}") from None


def _scribbles_for(
    project: Project, name: str, file_shape: tuple[int, int], leaf: NDArray[Any], box: tuple[int, int, int, int]
) -> NDArray[np.int32]:
    """The scribble file as labels of the leaf: drawn on the leaf, taken as they are; drawn on the whole file, cut."""
    path = project.existing(name, suffixes=_PNG, name_of="scribbles")
    size = io.image_size(path, max_pixels=project.max_pixels)
    if size == leaf.shape[:2] and size != file_shape:
        return leaves.read_scribbles(path, leaf.shape)[0]
    labels, _ = leaves.read_scribbles(path, file_shape)
    return _cut(labels, box)


def plan(req: LeavesExpandJob | LeavesSynthesizeJob, outputs: Outputs, threads: int | None) -> Work:
    """Check a leaves job's inputs and outputs; its work."""
    project = outputs.project
    params = req.model_dump()
    if isinstance(req, LeavesExpandJob):
        img, found = _leaves_of(project, req.image, "image")
        leaf, box = found.leaves[0], found.boxes[0]
        sc = _scribbles_for(project, req.scribbles, img.shape[:2], leaf, box)
        src = Path(req.scribbles)
        out = outputs.target(req.out or (src.parent / f"{src.stem}_layers.png").as_posix(), suffixes=_PNG,
                             overwrite=req.overwrite)  # fmt: skip

        def expand(progress: Progress) -> list[str]:
            assert progress is not None
            progress(0, 1)
            layers = leaves.layers_from_scribbles(leaf, sc, seed=req.seed, threads=threads)
            progress(1, 1)
            whole = layer_image(_paste(layers, box, img.shape[:2]))
            return [
                outputs.image(out, whole, command=req.kind, parameters=params, seed=req.seed, overwrite=req.overwrite)
            ]

        return expand

    training = req.training or req.leaves[0]
    if training not in req.leaves:
        raise ValueError(f"training: {training!r} is not one of leaves")
    imgs: list[NDArray[np.float32]] = []
    first = 0
    marks: NDArray[np.int32] | None = None
    for i, name in enumerate(req.leaves):
        img, found = _leaves_of(project, name, f"leaves[{i}]")
        if name == training and marks is None:
            first = len(imgs)
            marks = _scribbles_for(project, req.scribbles, img.shape[:2], found.leaves[0], found.boxes[0])
        imgs += found.leaves
    assert marks is not None
    if len(imgs) < 2:
        raise ValueError(f"leaves: the images hold {len(imgs)} leaf; analysis needs at least two")
    folder = req.out or f"results/leaves-{secrets.token_hex(4)}"
    names = [f"{folder}/leaf_{i:04d}.png" for i in range(req.count)]
    targets = [outputs.target(n, suffixes=_PNG, overwrite=req.overwrite) for n in [*names, f"{folder}/sheet.png"]]
    model_dir = project.resolve(f"{folder}/model", name_of="out")
    if (model_dir / "model.json").exists() and not req.overwrite:
        raise FileExistsError(f"out: {folder}/model already exists (pass overwrite=true to replace it)")

    def synthesize(progress: Progress) -> list[str]:
        assert progress is not None
        model = leaves.analyze(imgs, marks, training=first, points=req.points, seed=req.seed, threads=threads,
                               progress=lambda d, t: progress(d, 2 * t), max_memory=project.max_memory)  # fmt: skip
        new: list[NDArray[np.float32]] = []
        for i in range(req.count):
            # one call per leaf with its own seed, as the CLI does, so any leaf can be remade alone
            new += leaves.synthesize(model, count=1, seed=sub_seed(req.seed, i), threads=threads)
            progress(req.count + i + 1, 2 * req.count)
        progress(1, 1)
        files: list[tuple[Path, bytes, dict[str, Any] | None]] = [
            (model_dir / n, data, None) for n, data in model.files().items()
        ]
        files.append((io.sidecar_path(model_dir), io._sidecar(model_dir, f"studio {req.kind}", params, req.seed), None))
        for i, (t, leaf) in enumerate(zip(targets, new)):
            files.append((t, _files.encode(t, leaf, None), {**params, "leaf_seed": sub_seed(req.seed, i)}))
        files.append((targets[-1], _files.encode(targets[-1], leaves.contact_sheet(model, new), None), params))
        written = outputs.write_all(files, command=req.kind, seed=req.seed, overwrite=req.overwrite)
        return [written[-1], *written[-1 - req.count : -1]]

    return synthesize


def _png_name(description: str) -> Any:
    """A ``path`` query parameter (as :func:`phloem.studio.app._name`): its pattern in the API description."""
    return Query(description=description, json_schema_extra={"pattern": name_pattern(_PNG)})


def _image_name(description: str) -> Any:
    return Query(description=description, json_schema_extra={"pattern": name_pattern(IMAGE_SUFFIXES)})


def mount(app: FastAPI, project: Project, guarded: Callable[[Callable[[], Any]], Any], saved: type[BaseModel]) -> None:
    """The leaves workspace's endpoints on ``app``."""

    @app.get("/api/scribbles", response_model=LabelMap)
    def get_scribbles(
        path: Annotated[str, _png_name("project name of a scribble PNG")],
        image: Annotated[str, _image_name("project name of the image they are drawn on")],
    ) -> Any:
        """Scribbles as labels ``0`` (unmarked) and ``1 … n``, read as ``phloem leaves`` reads them."""

        def load() -> LabelMap:
            h, w = io.image_size(project.existing(image, suffixes=IMAGE_SUFFIXES, name_of="image"),
                                 max_pixels=project.max_pixels)  # fmt: skip
            lab, n = leaves.read_scribbles(project.existing(path, suffixes=_PNG), (h, w))
            data = base64.b64encode(lab.astype(np.uint8).tobytes()).decode()
            return LabelMap(width=w, height=h, n_labels=n + 1, data=data)

        return guarded(load)

    @app.put("/api/scribbles", response_model=saved)
    def put_scribbles(
        path: Annotated[str, _png_name("project name of the PNG to write")], body: LabelMap, overwrite: bool = False
    ) -> Any:
        """Write scribbles (0 unmarked, layer ``k`` as ``k``) as the integer grey PNG ``phloem leaves`` reads."""

        def save() -> Any:
            project.resolve(path, suffixes=_PNG)
            lab = decode_label_map(body, project.max_pixels)
            if not lab.any():
                raise ValueError("data: nothing is scribbled (every pixel is 0)")
            project.write_bytes(path, gray_png(lab), overwrite=overwrite)
            return saved(path=path, width=body.width, height=body.height)

        return guarded(save)
