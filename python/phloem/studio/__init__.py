"""phloem studio: the interactive tools of the papers in a local web page (``phloem studio``).

A FastAPI application (:func:`create_app`) over one project folder (:class:`Project`): the page
draws strokes, skeletons and guides, paints label maps, scribbles and masks on canvases, saves
them as the same files the CLI reads (``phloem.strokes`` and ``phloem.skeleton`` JSON, guide
JSON, label-map, scribble and mask PNGs) and runs phloem's engines as cancellable jobs
(:class:`JobManager`) whose progress streams to the page. The workspaces beyond strokes and
bark live in :mod:`phloem.studio.workspaces`. Needs the ``studio`` extra
(``pip install "phloem[studio]"``). See ``docs/studio.md``.
"""

from __future__ import annotations

import contextlib
import socket
import sys
import webbrowser
from typing import TextIO

from .app import TOKEN_HEADER, create_app
from .files import PathError, Project
from .jobs import Job, JobCancelled, JobManager

__all__ = ["TOKEN_HEADER", "Job", "JobCancelled", "JobManager", "PathError", "Project", "create_app", "serve"]

_LOOPBACK = ("127.0.0.1", "::1", "localhost")


def serve(
    project: Project,
    *,
    host: str = "127.0.0.1",
    port: int = 8765,
    open_browser: bool = True,
    threads: int | None = None,
    stream: TextIO | None = None,
) -> None:
    """Serve the studio for ``project`` until Ctrl-C.

    Parameters
    ----------
    project : Project
        The project folder and its limits.
    host : str, optional
        Address to bind (default 127.0.0.1: this machine only). Another address lets other
        machines reach the studio; the token still guards every request.
    port : int, optional
        Port (default 8765; 0 picks a free one).
    open_browser : bool, optional
        Open the page in the default browser (default True).
    threads : int, optional
        Threads of each engine run.
    stream : text stream, optional
        Where the opening URL is printed (default stderr).

    Examples
    --------
    >>> serve(Project("."), port=-1)
    Traceback (most recent call last):
    ...
    ValueError: port: expected 0 to 65535, got -1
    """
    import uvicorn

    if not 0 <= port <= 65535:
        raise ValueError(f"port: expected 0 to 65535, got {port}")
    out = stream or sys.stderr
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as e:
        sock.close()
        raise OSError(f"port: cannot listen on {host}:{port}: {e.strerror}") from None
    # Listen before the URL is printed: a browser (or script) that connects while uvicorn is still
    # starting waits in the backlog instead of being refused.
    sock.listen(128)
    bound = sock.getsockname()[1]
    app = create_app(project, threads=threads)
    shown = f"[{host}]" if ":" in host else host
    url = f"http://{shown}:{bound}/?token={app.state.token}"
    if host not in _LOOPBACK:
        print(f"phloem studio: warning: listening on {host}, reachable from other machines", file=out)
    print(f"phloem studio: {project.root}\nopen {url}\n(Ctrl-C stops it)", file=out, flush=True)
    if open_browser:
        webbrowser.open(url)
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning"))
    with contextlib.suppress(KeyboardInterrupt):  # uvicorn shuts down cleanly, then re-raises the Ctrl-C
        server.run(sockets=[sock])
    print("phloem studio: stopped", file=out)
