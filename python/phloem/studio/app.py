"""The studio's HTTP API (FastAPI) and its page.

Every request must carry the session token (header ``X-Phloem-Token`` or query ``token``); every
file name is checked by :class:`~phloem.studio.files.Project`; every error a request can cause
is a 4xx with a one-line ``detail`` naming the argument.
"""

from __future__ import annotations

import base64
import json
import secrets
from collections.abc import AsyncIterator, Awaitable, Callable, MutableMapping
from contextlib import asynccontextmanager
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal
from urllib.parse import parse_qs

import numpy as np
from fastapi import Body, FastAPI, File, HTTPException, Query, Request, UploadFile
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, Response, StreamingResponse
from numpy.typing import NDArray
from pydantic import BaseModel, Field

from .. import __version__, _files, _memory, bark, io, strokes
from .._progress import Progress
from .files import IMAGE_SUFFIXES, JSON_SUFFIXES, PathError, Project, name_pattern
from .jobs import JobManager
from .outputs import LabelMap, Outputs, Side, decode_label_map
from .workspaces import branching as branching_ws
from .workspaces import leaves as leaves_ws
from .workspaces import textures as textures_ws
from .workspaces import trees as trees_ws

__all__ = ["TOKEN_HEADER", "create_app"]

TOKEN_HEADER = "X-Phloem-Token"
WORKSPACES = ("strokes", "bark", "branching", "leaves", "trees", "textures")
# Bytes a JSON or form body may add around an upload's file (field names, boundaries).
_BODY_SLACK = 64 * 1024
_STATIC = ("app.js", "style.css")
PNG_SUFFIX = frozenset({".png"})
IMAGE_OUT = frozenset({".png", ".tif", ".tiff"})
# The page's URL holds the token: no referrer carries it away, no other site frames the page, and
# the page runs only its own scripts.
_PAGE_HEADERS = {
    "Cache-Control": "no-store",
    "Referrer-Policy": "no-referrer",
    "X-Content-Type-Options": "nosniff",
    "Content-Security-Policy": "default-src 'self'; img-src 'self' blob: data:; frame-ancestors 'none'",
}


def _name(description: str, suffixes: frozenset[str]) -> Any:
    """A ``path`` query parameter: its pattern is in the API description (clients and fuzzers
    see what a name looks like) but checked by :meth:`Project.resolve`, whose 400 names the
    problem more clearly than a pattern mismatch would."""
    return Query(description=description, json_schema_extra={"pattern": name_pattern(suffixes)})


Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]


class _Guard:
    """ASGI middleware: the token on every request, a declared and bounded body on every upload.

    A body without a ``Content-Length`` is refused (411) rather than counted while it streams:
    browsers always send one, and a refusal before the body is read costs the server nothing.
    """

    def __init__(self, app: ASGIApp, token: str, max_body: int) -> None:
        self.app = app
        self.token = token
        self.max_body = max_body

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}
        query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
        given = headers.get(TOKEN_HEADER.lower()) or (query.get("token") or [None])[0]
        refusal: tuple[int, str] | None = None
        if not given:
            refusal = (401, f"token: missing; open the URL phloem studio printed, or send the {TOKEN_HEADER} header")
        elif not secrets.compare_digest(given.encode(), self.token.encode()):
            refusal = (403, "token: wrong token for this studio session")
        elif scope["method"] in ("POST", "PUT", "PATCH"):
            length = headers.get("content-length")
            if length is None and "transfer-encoding" in headers:
                refusal = (411, "body: a Content-Length header is required")
            elif length is not None and (not length.isdigit() or int(length) > self.max_body):
                refusal = (413, f"body: {length} bytes, over the upload limit of {self.max_body}")
        if refusal is not None:
            await JSONResponse({"detail": refusal[1]}, status_code=refusal[0])(scope, receive, send)
            return
        await self.app(scope, receive, send)


# -- request and response bodies ------------------------------------------------------------
class StrokesEditJob(BaseModel):
    """Re-draw the object of ``image`` along the target strokes of ``strokes`` (:func:`phloem.strokes.edit`)."""

    kind: Literal["strokes-edit"]
    image: str = Field(description="project name of the object photo")
    strokes: str = Field(description="project name of the phloem.strokes JSON file")
    size: tuple[Side, Side] | None = Field(None, description="output [height, width]; default the file's target_size")
    out: str | None = Field(None, description="project name of the result (.png); default results/<kind>-<id>.png")
    overwrite: bool = False


class BarkLabelsJob(BaseModel):
    """The label map of a bark photo (:func:`phloem.bark.input_labels`), written as the CLI's grey-level PNG."""

    kind: Literal["bark-labels"]
    image: str = Field(description="project name of the bark photo")
    n_labels: int = Field(3, ge=2, le=16)
    seed: int = Field(0, ge=0, lt=2**63)
    out: str | None = Field(None, description="default <photo>_labels_in.png beside the photo")
    overwrite: bool = False


class BarkTextureJob(BaseModel):
    """A bark texture from a photo and, optionally, its (painted) label map (:func:`phloem.bark.generate`)."""

    kind: Literal["bark-texture"]
    image: str = Field(description="project name of the bark photo")
    labels_in: str | None = Field(None, description="project name of the photo's label map PNG")
    labels_out: str | None = Field(
        None, description="project name of a (painted) output label map PNG; the texture takes its size"
    )
    size: tuple[Side, Side] = Field(description="output [height, width] (unused with labels_out)")
    n_labels: int = Field(3, ge=2, le=16)
    tileable: bool = False
    seed: int = Field(0, ge=0, lt=2**63)
    out: str | None = None
    overwrite: bool = False


JobRequest = Annotated[
    StrokesEditJob
    | BarkLabelsJob
    | BarkTextureJob
    | branching_ws.BranchingTraceJob
    | branching_ws.BranchingGrowJob
    | branching_ws.BranchingRenderJob
    | leaves_ws.LeavesExpandJob
    | leaves_ws.LeavesSynthesizeJob
    | trees_ws.TreesJob
    | textures_ws.TextureJob
    | textures_ws.TextureCompleteJob,
    Field(discriminator="kind"),
]


class JobView(BaseModel):
    id: str
    kind: str
    parameters: dict[str, Any]
    state: Literal["queued", "running", "done", "failed", "cancelled"]
    done: int
    total: int
    message: str
    outputs: list[str]
    created: float


class Saved(BaseModel):
    path: str
    width: int | None = None
    height: int | None = None


# -- the application ------------------------------------------------------------------------
def _page(token: str) -> str:
    html = resources.files("phloem.studio").joinpath("static").joinpath("index.html").read_text(encoding="utf-8")
    return html.replace("{{TOKEN}}", token).replace("{{VERSION}}", __version__)


def _message(e: BaseException) -> str:
    return str(e.args[0]) if isinstance(e, OSError) and len(e.args) == 1 else str(e)


def _labels(project: Project, name: str, name_of: str) -> NDArray[np.int32]:
    """A label-map file of the project as labels ``0 … n-1``, errors naming ``name_of``."""
    img = project.read_image(name, name_of=name_of)
    try:
        return bark.decode_labels(img)
    except ValueError as e:
        raise ValueError(str(e).replace("image: ", f"{name_of}: {name} ", 1)) from None


def create_app(
    project: Project,
    *,
    token: str | None = None,
    workers: int = 1,
    threads: int | None = None,
) -> FastAPI:
    """The studio's ASGI application for ``project``.

    Parameters
    ----------
    project : Project
        The folder every file is read from and written to, with the upload limits.
    token : str, optional
        The session token every request must carry (default: a new random one, in
        ``app.state.token``).
    workers : int, optional
        Jobs run at once (default 1).
    threads : int, optional
        Threads of each engine run (default: ``PHLOEM_NUM_THREADS`` or all cores).

    Returns
    -------
    fastapi.FastAPI
        Serve it with uvicorn (:func:`phloem.studio.serve`) or test it with FastAPI's ``TestClient``.

    Examples
    --------
    >>> import tempfile
    >>> from fastapi.testclient import TestClient
    >>> app = create_app(Project(tempfile.mkdtemp()), token="secret")
    >>> with TestClient(app) as client:
    ...     client.get("/api/info").status_code, client.get("/api/info?token=secret").json()["workspaces"]
    (401, ['strokes', 'bark', 'branching', 'leaves', 'trees', 'textures'])
    """
    token = token or secrets.token_urlsafe(24)
    manager = JobManager(workers)

    @asynccontextmanager
    async def lifespan(_: FastAPI) -> AsyncIterator[None]:
        yield
        manager.shutdown()

    app = FastAPI(
        title="phloem studio",
        version=__version__,
        description="The interactive tools of phloem's papers over its files. Every request needs the "
        f"session token: header `{TOKEN_HEADER}` or query `token`.",
        lifespan=lifespan,
        # Swagger UI and ReDoc load their scripts from a CDN and fetch the document without the
        # token: neither works here, so only the document itself is served.
        docs_url=None,
        redoc_url=None,
    )
    app.state.token = token
    app.state.project = project
    app.state.jobs = manager
    app.add_middleware(_Guard, token=token, max_body=project.max_upload_bytes + _BODY_SLACK)

    def fail(status: int, e: BaseException) -> HTTPException:
        return HTTPException(status, _message(e))

    async def on_invalid(_: Request, exc: Exception) -> JSONResponse:
        errors = exc.errors() if isinstance(exc, RequestValidationError) else []
        first = errors[0] if errors else {"loc": (), "msg": str(exc)}
        where = ".".join(str(p) for p in first["loc"] if p not in ("body", "query"))
        return JSONResponse(
            {"detail": f"{where or 'request'}: {first['msg']}", "errors": json.loads(json.dumps(errors, default=str))},
            422,
        )

    app.add_exception_handler(RequestValidationError, on_invalid)

    def guarded(call: Callable[[], Any]) -> Any:
        """Map the errors a request can cause to 4xx with phloem's one-line message."""
        try:
            return call()
        except PathError as e:
            raise fail(400, e) from None
        except FileNotFoundError as e:
            raise fail(404, e) from None
        except FileExistsError as e:
            raise fail(409, e) from None
        except _memory.MemoryLimitError as e:
            raise fail(413, e) from None
        except (ValueError, TypeError, io.ImageReadError) as e:
            raise fail(422, e) from None
        except OSError as e:
            raise fail(500, e) from None

    # -- page ------------------------------------------------------------------------------
    @app.get("/", response_class=HTMLResponse, include_in_schema=False)
    def page() -> HTMLResponse:
        return HTMLResponse(_page(token), headers=_PAGE_HEADERS)

    @app.get("/static/{name}", include_in_schema=False)
    def static(name: str) -> Response:
        if name not in _STATIC:
            raise HTTPException(404, f"name: no static file {name!r}")
        text = resources.files("phloem.studio").joinpath("static").joinpath(name).read_text(encoding="utf-8")
        kind = "text/javascript" if name.endswith(".js") else "text/css"
        return Response(text, media_type=kind, headers={"Cache-Control": "no-store"})

    # -- project files ---------------------------------------------------------------------
    @app.get("/api/info")
    def info() -> dict[str, Any]:
        """The studio's version, project folder, workspaces and limits."""
        return {
            "version": __version__,
            "project": str(project.root),
            "workspaces": list(WORKSPACES),
            "max_pixels": project.max_pixels,
            "max_upload_bytes": project.max_upload_bytes,
            "layer_colours": list(leaves_ws.LAYER_COLOURS),
        }

    @app.get("/api/files")
    def files() -> list[dict[str, Any]]:
        """The project's images and JSON files (name, kind, bytes)."""
        return project.files()

    @app.get("/api/file", response_class=FileResponse)
    def file(
        path: Annotated[str, _name("project name of an image or JSON file", IMAGE_SUFFIXES | JSON_SUFFIXES)],
    ) -> FileResponse:
        """The bytes of one project file."""
        p = guarded(lambda: project.existing(path, suffixes=IMAGE_SUFFIXES | JSON_SUFFIXES))
        return FileResponse(p, headers={"Cache-Control": "no-store"})

    @app.post("/api/upload", response_model=Saved)
    async def upload(
        file: Annotated[UploadFile, File(description="an image (PNG, JPEG, TIFF, WebP)")],
        path: Annotated[str, _name("project name to save it as", IMAGE_SUFFIXES)],
        overwrite: bool = False,
    ) -> Saved:
        """Save an uploaded image in the project after phloem's image checks and limits."""
        target = guarded(lambda: project.resolve(path, suffixes=IMAGE_SUFFIXES))
        data = await file.read(project.max_upload_bytes + 1)

        def save() -> Saved:
            if target.exists() and not overwrite:
                raise FileExistsError(f"path: {path!r} already exists (pass overwrite=true to replace it)")
            h, w = project.check_image_bytes(data, target.suffix.lower())
            project.write_bytes(path, data, overwrite=overwrite)
            return Saved(path=path, width=w, height=h)

        if len(data) > project.max_upload_bytes:
            raise HTTPException(413, f"file: over the upload limit of {project.max_upload_bytes} bytes")
        result: Saved = guarded(save)
        return result

    # -- strokes ---------------------------------------------------------------------------
    @app.get("/api/strokes")
    def get_strokes(path: Annotated[str, _name("project name of a phloem.strokes JSON file", JSON_SUFFIXES)]) -> Any:
        """A stroke set file, checked by :class:`phloem.strokes.StrokeSet`."""
        return guarded(lambda: strokes.StrokeSet.load(project.existing(path, suffixes=JSON_SUFFIXES)).to_dict())

    @app.put("/api/strokes", response_model=Saved)
    def put_strokes(
        path: Annotated[str, _name("project name of the JSON file to write", JSON_SUFFIXES)],
        body: Annotated[dict[str, Any], Body(description="a phloem.strokes document")],
        overwrite: bool = False,
    ) -> Saved:
        """Write a stroke set file (the same JSON as ``phloem strokes edit`` reads)."""

        def save() -> Saved:
            project.resolve(path, suffixes=JSON_SUFFIXES)
            sset = strokes.StrokeSet.from_dict(body)
            project.write_bytes(path, (sset.to_json() + "\n").encode(), overwrite=overwrite)
            return Saved(path=path)

        result: Saved = guarded(save)
        return result

    # -- label maps ------------------------------------------------------------------------
    @app.get("/api/labels", response_model=LabelMap)
    def get_labels(path: Annotated[str, _name("project name of a label map PNG", PNG_SUFFIX)]) -> LabelMap:
        """A label map PNG (grey levels or flat colours) as labels ``0 … n-1``."""

        def load() -> LabelMap:
            lab = _labels(project, path, "path")
            return LabelMap(
                width=lab.shape[1],
                height=lab.shape[0],
                n_labels=int(lab.max()) + 1,
                data=base64.b64encode(lab.astype(np.uint8).tobytes()).decode(),
            )

        result: LabelMap = guarded(load)
        return result

    @app.put("/api/labels", response_model=Saved)
    def put_labels(
        path: Annotated[str, _name("project name of the PNG to write", PNG_SUFFIX)],
        body: LabelMap,
        overwrite: bool = False,
    ) -> Saved:
        """Write a painted label map as the CLI's label-map PNG (:func:`phloem.bark.encode_labels`)."""

        def save() -> Saved:
            project.resolve(path, suffixes=PNG_SUFFIX)
            lab = decode_label_map(body, project.max_pixels)
            img = bark.encode_labels(lab.astype(np.int32))
            project.write_bytes(path, _files.encode(Path(path), img, 8), overwrite=overwrite)
            return Saved(path=path, width=body.width, height=body.height)

        result: Saved = guarded(save)
        return result

    # -- jobs ------------------------------------------------------------------------------
    outputs = Outputs(project)

    def out_path(req: StrokesEditJob | BarkLabelsJob | BarkTextureJob, job_hint: str) -> Path:
        return outputs.target(req.out or job_hint, suffixes=IMAGE_OUT, overwrite=req.overwrite)

    def write(path: Path, image: Any, kind: str, parameters: dict[str, Any], seed: int, overwrite: bool) -> str:
        return outputs.image(path, image, command=kind, parameters=parameters, seed=seed, overwrite=overwrite)

    def plan(req: StrokesEditJob | BarkLabelsJob | BarkTextureJob) -> Callable[[Progress], list[str]]:
        """Check a job's inputs and output before it is queued; its work."""
        params = req.model_dump()
        if isinstance(req, StrokesEditJob):
            image = project.read_image(req.image)
            sset = strokes.StrokeSet.load(project.existing(req.strokes, suffixes=JSON_SUFFIXES, name_of="strokes"))
            out = out_path(req, f"results/strokes-{secrets.token_hex(4)}.png")

            def edit(progress: Progress) -> list[str]:
                res = strokes.edit(
                    image, sset, size=req.size, threads=threads, progress=progress, max_memory=project.max_memory
                )
                assert progress is not None
                progress(1, 1)  # a cancel that came during the last step writes nothing
                return [write(out, res, req.kind, params, 0, req.overwrite)]

            return edit
        if isinstance(req, BarkLabelsJob):
            photo = project.read_image(req.image)
            src = Path(req.image)
            out = out_path(req, (src.parent / f"{src.stem}_labels_in.png").as_posix())

            def labels(progress: Progress) -> list[str]:
                assert progress is not None
                lab = bark.input_labels(photo, req.n_labels, seed=req.seed, progress=progress)
                return [write(out, bark.encode_labels(lab), req.kind, params, req.seed, req.overwrite)]

            return labels
        photo = project.read_image(req.image)
        lab_in = None if req.labels_in is None else _labels(project, req.labels_in, "labels_in")
        if lab_in is not None and lab_in.shape != photo.shape[:2]:
            raise ValueError(
                f"labels_in: {lab_in.shape[1]}×{lab_in.shape[0]} px, but the photo is {photo.shape[1]}×{photo.shape[0]}"
            )
        lab_out = None if req.labels_out is None else _labels(project, req.labels_out, "labels_out")
        out = out_path(req, f"results/bark-{secrets.token_hex(4)}.png")
        # the new label map it was painted by, as 'phloem bark --keep-intermediates' writes it: edit it, resume
        maps = out.with_name(f"{out.stem}_labels_out.png")
        outputs.target(project.name(maps), suffixes=PNG_SUFFIX, overwrite=req.overwrite)

        def texture(progress: Progress) -> list[str]:
            res = bark.generate(
                photo, None if lab_out is not None else req.size, n_labels=req.n_labels, labels_in=lab_in,
                labels_out=lab_out, tileable=req.tileable, seed=req.seed, threads=threads, progress=progress,
                max_memory=project.max_memory, full_output=True,
            )  # fmt: skip
            assert progress is not None
            progress(100, 100)
            files = [(out, _files.encode(out, res.texture, None), params),
                     (maps, _files.encode(maps, bark.encode_labels(res.labels_out), 8), params)]  # fmt: skip
            return outputs.write_all(files, command=req.kind, seed=req.seed, overwrite=req.overwrite)

        return texture

    def plan_any(req: Any) -> Callable[[Progress], list[str]]:
        if isinstance(
            req, branching_ws.BranchingTraceJob | branching_ws.BranchingGrowJob | branching_ws.BranchingRenderJob
        ):
            return branching_ws.plan(req, outputs, threads)
        if isinstance(req, leaves_ws.LeavesExpandJob | leaves_ws.LeavesSynthesizeJob):
            return leaves_ws.plan(req, outputs, threads)
        if isinstance(req, trees_ws.TreesJob):
            return trees_ws.plan(req, outputs, threads)
        if isinstance(req, textures_ws.TextureJob | textures_ws.TextureCompleteJob):
            return textures_ws.plan(req, outputs, threads)
        return plan(req)

    branching_ws.mount(app, project, guarded, Saved)
    leaves_ws.mount(app, project, guarded, Saved)
    textures_ws.mount(app, project, guarded, Saved)

    @app.post("/api/jobs", status_code=202, response_model=JobView)
    def submit(req: Annotated[JobRequest, Body()]) -> JobView:
        """Check a job's inputs and queue it; follow it with ``/api/jobs/{id}/events``."""
        work = guarded(lambda: plan_any(req))
        job = manager.submit(req.kind, req.model_dump(), work)
        return JobView(**job.snapshot())

    @app.get("/api/jobs", response_model=list[JobView])
    def list_jobs() -> list[JobView]:
        """Every job of this session, newest first."""
        return [JobView(**j.snapshot()) for j in manager.jobs()]

    def known(job_id: str) -> None:
        try:
            manager.get(job_id)
        except KeyError:
            raise HTTPException(404, f"job_id: no job {job_id!r}") from None

    @app.get("/api/jobs/{job_id}", response_model=JobView)
    def get_job(job_id: str) -> JobView:
        """One job's state, progress and outputs."""
        known(job_id)
        return JobView(**manager.snapshot(job_id)[0])

    @app.post("/api/jobs/{job_id}/cancel", response_model=JobView)
    def cancel_job(job_id: str) -> JobView:
        """Stop a job: queued, it never starts; running, it stops at its next progress report and writes nothing."""
        known(job_id)
        manager.cancel(job_id)
        return JobView(**manager.snapshot(job_id)[0])

    @app.get("/api/jobs/{job_id}/events", response_class=StreamingResponse)
    def job_events(job_id: str) -> StreamingResponse:
        """Server-sent events: the job's state (as ``GET /api/jobs/{id}``) each time it changes, until it ends."""
        known(job_id)
        return StreamingResponse(
            manager.events(job_id), media_type="text/event-stream", headers={"Cache-Control": "no-store"}
        )

    return app
