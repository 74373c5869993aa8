"""The branching workspace (Sibbing et al. 2010): skeleton and guide files, interactive extension
of one branch (§6), angle and thickness histograms (Fig. 7), and the trace, grow and render jobs.

Vertex edits happen in the page (no request per drag); the page saves the skeleton as the same
``phloem.skeleton`` JSON that ``phloem branching trace`` writes and ``grow``/``render`` read, and
guide paths as ``--guide`` takes them: one path as a JSON list of ``[x, y]`` points, several as a
mask PNG (white along the paths).
"""

from __future__ import annotations

import secrets
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from fastapi import Body, FastAPI, Query
from pydantic import BaseModel, Field, TypeAdapter, ValidationError

from ... import _files, _json, branching
from ..._progress import Progress
from ...branching._fragment_map import fragment_map
from ...branching.pipeline import N_BEST
from ..files import JSON_SUFFIXES, Project, name_pattern
from ..jobs import Work
from ..outputs import Outputs, Side

__all__ = [
    "BranchingGrowJob",
    "BranchingRenderJob",
    "BranchingTraceJob",
    "Extend",
    "Histograms",
    "mount",
    "plan",
]

Seed = Annotated[int, Field(ge=0, lt=2**63)]
Point = tuple[Annotated[float, Field(allow_inf_nan=False)], Annotated[float, Field(allow_inf_nan=False)]]
#: A guide path as ``phloem branching grow --guide PATH.json`` reads it.
GuidePoints = Annotated[list[Point], Field(min_length=2, max_length=100_000)]
_GUIDE = TypeAdapter(GuidePoints)
_OUT = frozenset({".png", ".tif", ".tiff"})


class BranchingTraceJob(BaseModel):
    """Trace the skeleton of a structure in an image (:func:`phloem.branching.trace`), written as ``phloem branching trace`` does."""

    kind: Literal["branching-trace"]
    image: str = Field(description="project name of the image of the structure")
    trace_kind: Literal["auto", "bright", "dark", "mask"] = Field(
        "auto", description="what the structure looks like (the CLI's --kind)"
    )
    sigmas: list[Annotated[float, Field(gt=0, le=64)]] = Field(
        [1.0, 2.0, 3.0], min_length=1, max_length=8, description="ridge-filter scales in pixels"
    )
    min_length: float = Field(8.0, ge=0, le=100_000, description="drop traced branches shorter than this (px)")
    threshold: float | None = Field(
        None,
        allow_inf_nan=False,
        description="ridge-filter response that counts as structure (the CLI's --threshold); default Otsu's, "
        "raised on a grainy surface until the grain is shed",
    )
    threshold_scale: float = Field(
        1.0,
        gt=0,
        le=100,
        allow_inf_nan=False,
        description="factor on the default threshold of a photo (the CLI's --threshold-scale): below 1 keeps "
        "fainter structure, grain included; not with threshold, nor on a mask",
    )
    gap: float | None = Field(
        None,
        ge=0,
        le=100_000,
        allow_inf_nan=False,
        description="join a traced piece's end to structure at most this many px ahead (the CLI's --gap); default "
        "2 x the largest sigma + 3 on a photo, 0 on a mask. About 30 traces a fundus photo's vessels as one tree",
    )
    root: Point | None = Field(
        None, description="(x, y) where the structure starts, such as a retina's optic disc (the CLI's --root)"
    )
    subpixel: bool = Field(
        False,
        description="evaluate the ridge filter on a twice finer grid: thin lines in a glow (lightning) are traced "
        "whole, and more of a textured surface's grain too (the CLI's --subpixel)",
    )
    wide: bool = Field(
        True,
        description="also find structure wider than the ridge filter's scales, such as a vessel tree's trunk, with a "
        "second, wider filter (the CLI's --no-wide turns it off)",
    )
    edges: bool = Field(
        True,
        description="drop a further tree thicker than the main one's branches whose two sides differ, an edge "
        "between two regions such as a dish's rim (the CLI's --keep-edges turns it off)",
    )
    out: str | None = Field(
        None, description="project name of the skeleton (.json); default <image>_skeleton.json beside it"
    )
    overwrite: bool = False


class BranchingGrowJob(BaseModel):
    """Learn a skeleton's bending and branching and grow a new one (:func:`phloem.branching.grow`, §4)."""

    kind: Literal["branching-grow"]
    skeleton: str = Field(description="project name of the example skeleton (.json)")
    size: tuple[Side, Side] | None = Field(
        None, description="[height, width] of the new structure; default the example's"
    )
    guide: str | None = Field(
        None,
        description="project name of a guide (§4.5): a .json list of [x, y] points, or a mask .png, white along the paths",
    )
    seed: Seed = 0
    max_length: Literal["input"] | None = Field(
        "input", description="'input': about as much structure as the example; null: one tree"
    )
    h: float | None = Field(
        None, gt=0, le=1000, description="resampling step (px); default the example's median thickness, at least 2 px"
    )
    n_best: int = Field(N_BEST, ge=1, le=64, description="candidates drawn from at each step (the paper's c: 2)")
    layout: float | None = Field(
        None,
        ge=0,
        le=100,
        description="weight of the example's layout of directions: branches grow the way the example's run at the "
        "same places of the picture (0: off, the paper's model; null: 1 where the example is one connected "
        "structure and no guide is given, else 0)",
    )
    out: str | None = Field(
        None, description="project name of the new skeleton (.json); default results/grown-<id>.json"
    )
    overwrite: bool = False


class BranchingRenderJob(BaseModel):
    """Paint a skeleton with fragments of the example image (:func:`phloem.branching.render`, §5)."""

    kind: Literal["branching-render"]
    image: str = Field(description="project name of the example image")
    skeleton: str = Field(description="project name of the example's skeleton (.json)")
    target: str = Field(description="project name of the skeleton to paint (.json); its shape sets the size")
    seed: Seed = 0
    complete: bool = Field(True, description="complete the background from the example (§5.4)")
    out: str | None = Field(None, description="project name of the image; default results/branching-<id>.png")
    overwrite: bool = False


class Extend(BaseModel):
    """One branch of a skeleton extended at its tip by the bending model (§6)."""

    skeleton: dict[str, Any] = Field(description="the phloem.skeleton document being edited (with its shape)")
    branch: int = Field(ge=0, description="index of the branch whose tip grows")
    steps: int = Field(1, ge=1, le=50, description="Markov steps, each up to m vertices")
    seed: Seed = 0
    example: str | None = Field(
        None, description="project name of the skeleton whose bending is learnt; default the document itself"
    )


class HistogramPair(BaseModel):
    edges: list[float]
    source: list[float]
    result: list[float]
    distance: float = Field(description="L1 distance of the normalised histograms (0 equal, 2 disjoint)")


class Histograms(BaseModel):
    """Fig. 7: angle and thickness histograms of an example and a grown skeleton over the example's range."""

    h: float
    angle: HistogramPair
    thickness: HistogramPair


def read_guide(project: Project, name: str, name_of: str = "guide") -> list[tuple[float, float]]:
    """A guide file of the project: a JSON list of at least two ``[x, y]`` points."""
    data = _json.read_json(project.existing(name, suffixes=JSON_SUFFIXES, name_of=name_of), name_of)
    try:
        return [(float(x), float(y)) for x, y in _GUIDE.validate_python(data)]
    except ValidationError:
        raise ValueError(f"{name_of}: {name} must hold a JSON list of at least two [x, y] points") from None


def _check_pixels(shape: tuple[int, int], max_pixels: int, name_of: str) -> None:
    """Growth and rendering hold several maps of the structure's size: the project's pixel limit applies."""
    if shape[0] * shape[1] > max_pixels:
        raise ValueError(f"{name_of}: {shape[1]}×{shape[0]} is over the pixel limit of {max_pixels}")


def _guide(project: Project, name: str, shape: tuple[int, int]) -> Any:
    """A guide file as :func:`phloem.branching.grow` takes it: points, or a mask of the grown size."""
    if Path(name).suffix.lower() in JSON_SUFFIXES:
        return np.asarray(read_guide(project, name))
    img = project.read_image(name, name_of="guide")
    mask = (img if img.ndim == 2 else img[..., :3].max(axis=2)) >= 0.5
    if mask.shape != tuple(shape):
        raise ValueError(
            f"guide: {name} is {mask.shape[1]}×{mask.shape[0]}, but the new structure is {shape[1]}×{shape[0]}"
        )
    if not mask.any():
        raise ValueError(f"guide: {name} marks no path (white = path)")
    return mask


def _skeleton(project: Project, name: str, name_of: str) -> branching.Skeleton:
    return branching.Skeleton.load(project.existing(name, suffixes=JSON_SUFFIXES, name_of=name_of))


def _pair(
    measure: Callable[..., tuple[Any, Any]], source: branching.Skeleton, result: branching.Skeleton, h: float, bins: int
) -> HistogramPair:
    a, edges = measure(source, bins, h=h)
    b, _ = measure(result, bins, h=h, range=(float(edges[0]), float(edges[-1])))
    return HistogramPair(
        edges=edges.tolist(), source=a.tolist(), result=b.tolist(), distance=branching.histogram_distance(a, b)
    )


def plan(req: BranchingTraceJob | BranchingGrowJob | BranchingRenderJob, outputs: Outputs, threads: int | None) -> Work:
    """Check a branching job's inputs and outputs; its work."""
    project = outputs.project
    params = req.model_dump()
    if isinstance(req, BranchingTraceJob):
        img = project.read_image(req.image)
        src = Path(req.image)
        out = outputs.target(req.out or (src.parent / f"{src.stem}_skeleton.json").as_posix(),
                             suffixes=JSON_SUFFIXES, overwrite=req.overwrite)  # fmt: skip

        def trace(progress: Progress) -> list[str]:
            assert progress is not None
            progress(0, 1)
            valid = branching.valid_region(img)
            sk = branching.trace(img, kind=req.trace_kind, sigmas=tuple(req.sigmas), min_length=req.min_length,
                                 threshold=req.threshold, threshold_scale=req.threshold_scale, gap=req.gap,
                                 root=req.root,
                                 valid=None if valid.all() else valid,
                                 subpixel=req.subpixel, wide=req.wide, edges=req.edges)  # fmt: skip
            progress(1, 1)
            return [outputs.data(out, sk.to_json().encode(), command=req.kind, parameters=params, seed=None,
                                 overwrite=req.overwrite)]  # fmt: skip

        return trace
    if isinstance(req, BranchingGrowJob):
        source = _skeleton(project, req.skeleton, "skeleton")
        shape = req.size or source.shape
        if shape is None:
            raise ValueError(f"size: {req.skeleton} has no shape; give size [height, width]")
        _check_pixels(shape, project.max_pixels, "size")
        guide = None if req.guide is None else _guide(project, req.guide, shape)
        out = outputs.target(req.out or f"results/grown-{secrets.token_hex(4)}.json",
                             suffixes=JSON_SUFFIXES, overwrite=req.overwrite)  # fmt: skip

        def grow(progress: Progress) -> list[str]:
            # the same course-keeping defaults as synthesize and the command line
            d = branching.source_defaults(source, h=req.h, layout=req.layout, guided=guide is not None)
            bend, fur = branching.fit_models(
                source,
                h=d.h,
                n_best=req.n_best,
                course=d.course,
                total_turn=d.total_turn,
                orientation=d.orientation,
                direction_histogram=d.direction_histogram,
                turn_histogram=d.turn_histogram,
                layout=d.layout,
                denoise=d.denoise,
            )
            new = branching.grow(bend, fur, size=shape, seed=req.seed, max_length=req.max_length, guide=guide,
                                 repel_border=d.repel_border, joined_ends=d.joined_ends, progress=progress,
                                 max_memory=project.max_memory)  # fmt: skip
            assert progress is not None
            progress(1, 1)  # a cancel during the last step writes nothing
            used = {
                **params,
                "h": bend.h,
                "course": bend.course,
                "total_turn": d.total_turn,
                "turn_bound": bend.turn_bound,
                "repel_border": d.repel_border,
                "joined_ends": d.joined_ends,
                "orientation": d.orientation,
                "direction_histogram": d.direction_histogram,
                "denoise": d.denoise,
                "layout": d.layout,
            }
            return [outputs.data(out, new.to_json().encode(), command=req.kind, parameters=used,
                                 seed=req.seed, overwrite=req.overwrite)]  # fmt: skip

        return grow
    img = project.read_image(req.image)
    source = _skeleton(project, req.skeleton, "skeleton")
    target = _skeleton(project, req.target, "target")
    if target.shape is None:
        raise ValueError(f"target: {req.target} has no shape; the new image's size comes from it")
    _check_pixels(target.shape, project.max_pixels, "target")
    out = outputs.target(req.out or f"results/branching-{secrets.token_hex(4)}.png", suffixes=_OUT,
                         overwrite=req.overwrite)  # fmt: skip
    # the fragment map (which fragment painted each pixel), as 'phloem branching render --fragment-map' writes it
    fragments = out.with_name(f"{out.stem}_fragments.png")
    outputs.target(project.name(fragments), suffixes=_OUT, overwrite=req.overwrite)

    def render(progress: Progress) -> list[str]:
        valid = branching.valid_region(img)
        res = branching.render(img, source, target, seed=req.seed, complete=req.complete,
                               valid=None if valid.all() else valid, threads=threads, progress=progress,
                               max_memory=project.max_memory, full_output=True)  # fmt: skip
        assert progress is not None
        progress(1, 1)
        files = [(out, _files.encode(out, res.image, None), params),
                 (fragments, _files.encode(fragments, fragment_map(res.labels), None), params)]  # fmt: skip
        return outputs.write_all(files, command=req.kind, seed=req.seed, overwrite=req.overwrite)

    return render


def _json_name(description: str) -> Any:
    """A ``path`` query parameter (as :func:`phloem.studio.app._name`): its pattern in the API description."""
    return Query(description=description, json_schema_extra={"pattern": name_pattern(JSON_SUFFIXES)})


def mount(app: FastAPI, project: Project, guarded: Callable[[Callable[[], Any]], Any], saved: type[BaseModel]) -> None:
    """The branching workspace's endpoints on ``app``; ``guarded`` maps errors to 4xx, ``saved`` is the answer of a write."""

    @app.get("/api/skeleton")
    def get_skeleton(path: Annotated[str, _json_name("project name of a phloem.skeleton JSON file")]) -> Any:
        """A skeleton file, checked by :class:`phloem.branching.Skeleton`."""
        return guarded(lambda: _skeleton(project, path, "path").to_dict())

    @app.put("/api/skeleton", response_model=saved)
    def put_skeleton(
        path: Annotated[str, _json_name("project name of the JSON file to write")],
        body: Annotated[dict[str, Any], Body(description="a phloem.skeleton document")],
        overwrite: bool = False,
    ) -> Any:
        """Write a skeleton file (the JSON ``phloem branching trace`` writes and ``grow``/``render`` read)."""

        def save() -> Any:
            project.resolve(path, suffixes=JSON_SUFFIXES)
            sk = branching.Skeleton.from_dict(body)
            project.write_bytes(path, (sk.to_json() + "\n").encode(), overwrite=overwrite)
            return saved(path=path)

        return guarded(save)

    @app.get("/api/guide", response_model=GuidePoints)
    def get_guide(path: Annotated[str, _json_name("project name of a guide JSON file")]) -> Any:
        """A guide path: the JSON list of ``[x, y]`` points ``phloem branching grow --guide`` reads."""
        return guarded(lambda: read_guide(project, path, "path"))

    @app.put("/api/guide", response_model=saved)
    def put_guide(
        path: Annotated[str, _json_name("project name of the JSON file to write")],
        body: Annotated[GuidePoints, Body(description="at least two [x, y] points in image pixels")],
        overwrite: bool = False,
    ) -> Any:
        """Write a guide path file."""

        def save() -> Any:
            project.resolve(path, suffixes=JSON_SUFFIXES)
            text = "[" + ", ".join(f"[{x:.6g}, {y:.6g}]" for x, y in body) + "]\n"
            project.write_bytes(path, text.encode(), overwrite=overwrite)
            return saved(path=path)

        return guarded(save)

    @app.post("/api/skeleton/extend")
    def extend(body: Extend) -> Any:
        """The document with one branch extended at its tip (§6); nothing is written."""

        def run() -> Any:
            sk = branching.Skeleton.from_dict(body.skeleton)
            if sk.shape is None:
                raise ValueError("skeleton: the document has no shape; extension needs the image size")
            _check_pixels(sk.shape, project.max_pixels, "skeleton")
            if body.branch >= len(sk.branches):
                raise ValueError(f"branch: expected 0 .. {len(sk.branches) - 1}, got {body.branch}")
            example = sk if body.example is None else _skeleton(project, body.example, "example")
            bend, _ = branching.fit_models(example)
            return branching.extend(sk, body.branch, bend, steps=body.steps, seed=body.seed).to_dict()

        return guarded(run)

    @app.get("/api/histograms", response_model=Histograms)
    def histograms(
        source: Annotated[str, _json_name("project name of the example skeleton")],
        result: Annotated[str, _json_name("project name of the grown skeleton")],
        bins: Annotated[int, Query(ge=1, le=256)] = 16,
    ) -> Any:
        """Angle and thickness histograms of the example and the grown skeleton, binned over the example's
        range at the bending model's step (the CLI's ``--histograms`` figure as numbers)."""

        def measure() -> Histograms:
            a, b = _skeleton(project, source, "source"), _skeleton(project, result, "result")
            h = branching.default_h(a)
            return Histograms(
                h=h,
                angle=_pair(branching.angle_histogram, a, b, h, bins),
                thickness=_pair(branching.thickness_histogram, a, b, h, bins),
            )

        return guarded(measure)
