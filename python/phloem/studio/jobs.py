"""Jobs: phloem's engines run in a small worker pool, off the request thread, one progress report
at a time; a cancel request makes the next report raise, which stops the engine (see
:mod:`phloem._progress`: a callback's exception stops a run within a fraction of a second)."""

from __future__ import annotations

import asyncio
import json
import logging
import secrets
import threading
import time
from collections.abc import AsyncIterator, Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, Literal

from .. import io
from .._progress import Progress

__all__ = ["FINAL", "Job", "JobCancelled", "JobManager", "Work"]

State = Literal["queued", "running", "done", "failed", "cancelled"]
FINAL: frozenset[str] = frozenset({"done", "failed", "cancelled"})
#: A job's work: given a progress callback, it computes, writes its files and returns their project names.
Work = Callable[[Progress], list[str]]
_log = logging.getLogger("phloem.studio")
# The errors a job's input can cause, reported as they are; anything else is a bug, reported as one.
_EXPECTED = (ValueError, TypeError, OSError, io.ImageReadError)


class JobCancelled(Exception):
    """Raised from a job's progress callback once the job has been cancelled."""


@dataclass
class Job:
    """One run of an engine: its state, progress and the files it wrote."""

    id: str
    kind: str
    parameters: dict[str, Any]
    state: State = "queued"
    done: int = 0
    total: int = 0
    message: str = ""
    outputs: list[str] = field(default_factory=list)
    created: float = field(default_factory=time.time)
    version: int = 0
    cancel_requested: threading.Event = field(default_factory=threading.Event)

    def snapshot(self) -> dict[str, Any]:
        """The job as the API shows it (JSON-ready)."""
        return {
            "id": self.id,
            "kind": self.kind,
            "parameters": self.parameters,
            "state": self.state,
            "done": self.done,
            "total": self.total,
            "message": self.message,
            "outputs": list(self.outputs),
            "created": self.created,
        }


class JobManager:
    """A worker pool running :data:`Work` functions, with progress, cancellation and a record.

    Parameters
    ----------
    workers : int, optional
        Jobs run at once (default 1: the engines use every core themselves).
    keep : int, optional
        Finished jobs remembered for the job list (default 100; the oldest finished go first).

    Examples
    --------
    >>> m = JobManager()
    >>> job = m.submit("count", {}, lambda progress: [progress(1, 1)] and [])
    >>> m.wait(job.id, timeout=10).state
    'done'
    >>> m.shutdown()
    """

    def __init__(self, workers: int = 1, keep: int = 100) -> None:
        if workers < 1:
            raise ValueError(f"workers: expected a positive number of workers, got {workers}")
        self._pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="phloem-studio-job")
        self._jobs: dict[str, Job] = {}
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)
        self._keep = keep

    def submit(self, kind: str, parameters: dict[str, Any], work: Work) -> Job:
        """Queue ``work``; the job is returned at once, in state ``"queued"``."""
        job = Job(id=secrets.token_hex(6), kind=kind, parameters=parameters)
        with self._lock:
            self._jobs[job.id] = job
            self._forget_old()
        self._pool.submit(self._run, job, work)
        return job

    def get(self, job_id: str) -> Job:
        """The job ``job_id`` (``KeyError`` if there is none)."""
        with self._lock:
            return self._jobs[job_id]

    def jobs(self) -> list[Job]:
        """Every remembered job, newest first."""
        with self._lock:
            return sorted(self._jobs.values(), key=lambda j: j.created, reverse=True)

    def snapshot(self, job_id: str) -> tuple[dict[str, Any], int]:
        """The job's :meth:`Job.snapshot` and its version, read together."""
        with self._lock:
            job = self._jobs[job_id]
            return job.snapshot(), job.version

    def cancel(self, job_id: str) -> Job:
        """Ask the job to stop: a queued job never starts, a running one stops at its next progress report."""
        with self._lock:
            job = self._jobs[job_id]
            if job.state not in FINAL:
                job.cancel_requested.set()
                if job.state == "queued":
                    self._set(job, state="cancelled", message="cancelled before it started")
        return job

    def wait(self, job_id: str, timeout: float | None = None) -> Job:
        """Block until the job has finished (or ``timeout`` seconds have passed); the job."""
        with self._lock:
            job = self._jobs[job_id]
            self._changed.wait_for(lambda: job.state in FINAL, timeout)
            return job

    async def events(self, job_id: str, poll: float = 0.05) -> AsyncIterator[str]:
        """Server-sent events of the job: its snapshot each time it changed, the last one final.

        Polls every ``poll`` seconds rather than waking per report: engines report thousands
        of times a second at most, and a page needs no more than 20 frames a second.
        """
        last = -1
        while True:
            snap, version = self.snapshot(job_id)
            if version != last:
                last = version
                yield f"data: {json.dumps(snap)}\n\n"
            if snap["state"] in FINAL:
                return
            await asyncio.sleep(poll)

    def shutdown(self) -> None:
        """Cancel every job and stop the pool without waiting for running engines."""
        for job in self.jobs():
            self.cancel(job.id)
        self._pool.shutdown(wait=False, cancel_futures=True)

    # -- in the worker ---------------------------------------------------------------------
    def _set(self, job: Job, **changes: Any) -> None:
        # callers hold self._lock
        for k, v in changes.items():
            setattr(job, k, v)
        job.version += 1
        self._changed.notify_all()

    def _update(self, job: Job, **changes: Any) -> None:
        with self._lock:
            self._set(job, **changes)

    def _run(self, job: Job, work: Work) -> None:
        with self._lock:
            if job.cancel_requested.is_set() or job.state != "queued":
                return
            self._set(job, state="running")

        def report(done: int, total: int) -> None:
            if job.cancel_requested.is_set():
                raise JobCancelled
            self._update(job, done=int(done), total=int(total))

        try:
            outputs = work(report)  # work reports once more before it writes, so a cancel writes nothing
        except JobCancelled:
            self._update(job, state="cancelled", message="cancelled")
        except _EXPECTED as e:
            self._update(job, state="failed", message=str(e))
        except Exception as e:  # a bug: reported, and the pool keeps serving
            _log.exception("job %s (%s) failed", job.id, job.kind)
            self._update(job, state="failed", message=f"internal error: {type(e).__name__}: {e}")
        else:
            self._update(job, state="done", outputs=outputs, done=max(job.done, job.total))

    def _forget_old(self) -> None:
        finished = sorted((j for j in self._jobs.values() if j.state in FINAL), key=lambda j: j.created)
        for j in finished[: max(0, len(self._jobs) - self._keep)]:
            del self._jobs[j.id]
