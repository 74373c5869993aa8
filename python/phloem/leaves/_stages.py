"""Running independent per-exemplar calls side by side on the analysis' cores."""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any, TypeVar

from .. import _core

T = TypeVar("T")


class Stopped(Exception):
    """Raised in a task of :class:`Stages` once the analysis is being abandoned."""


#: A stage task: called with its thread count and a check to call between engine calls.
Task = Callable[[int | None, Callable[[], None]], T]


class Stages:
    """Runs the independent per-exemplar calls of a stage side by side.

    The engines release the GIL, but each runs partly serial (NumPy between the Rust calls,
    the sequential quilting), so ``threads`` cores are better used by tasks side by side, each
    on ``threads // width`` rayon threads, than by one task at a time on all of them
    (docs/pipelines/leaves/analysis.md). Every task has its own seed and results come back
    in submission order, so the model is the one the serial order makes. Python delivers
    Ctrl-C only to the main thread, which here waits on the tasks: on any exception there the
    tasks are told to stop (they raise at their next check, between engine calls), those not
    started are dropped, and the exception is raised once every task has ended.
    """

    def __init__(self, threads: int | None) -> None:
        self.threads = threads
        self.cores = _core.default_threads() if threads is None else threads
        self.stop = threading.Event()

    def width(self, n_tasks: int) -> int:
        return max(1, min(self.cores, n_tasks))

    def check(self) -> None:
        if self.stop.is_set():
            raise Stopped

    def run(self, tasks: Sequence[Task[Any]], done: Callable[[int], None]) -> list[Any]:
        """Results of ``tasks`` in order; ``done(k)`` in the calling thread after task k's."""
        width = self.width(len(tasks))
        if width == 1:
            out = []
            for k, task in enumerate(tasks):
                out.append(task(self.threads, self.check))
                done(k)
            return out
        per = self.cores // width

        def start(task: Task[Any]) -> Any:
            self.check()
            return task(per, self.check)

        pool = ThreadPoolExecutor(width, thread_name_prefix="phloem-leaves")
        futures: list[Future[Any]] = []
        try:
            futures = [pool.submit(start, task) for task in tasks]
            out = []
            for k, fut in enumerate(futures):
                out.append(fut.result())
                done(k)
            return out
        except BaseException:
            self.stop.set()
            for fut in futures:
                fut.cancel()
            raise
        finally:
            pool.shutdown(wait=True)
