"""Running a batch on Dask distributed: one task per item, each the item's own ``phloem`` command.

A task calls :func:`phloem.cli.main` in the worker process with the arguments of the single
command-line run of its item (:meth:`Item.argv`), so a batch writes what those runs write,
through the same checks and the same all-or-nothing output transaction. The driver keeps the
manifest: it skips items whose files verify, retries a failed item once, records every item's
outcome as it arrives and goes on past failures.
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import re
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import _files, _memory
from .manifest import Manifest, file_hashes
from .spec import Item, Spec, load_spec

__all__ = ["Summary", "local_cluster", "run"]

# phloem.cli.main keeps the running command's output transaction in a module-level stack and
# swaps warnings.showwarning: one command at a time per worker process. A task gets the
# worker's threads instead (``--threads``).
_ONE_COMMAND = threading.Lock()

#: Flags every task adds to its item's arguments: an item that runs is one whose files did not
#: verify, so what it finds under its names is a killed or stale attempt, to be replaced.
TASK_FLAGS = ("--force", "--quiet")


@dataclass
class Summary:
    """What a batch did.

    Attributes
    ----------
    total : int
        Items in the spec.
    made : int
        Items run to success now.
    skipped : int
        Items whose files were already there and verified (hashes in the manifest).
    failed : dict of str to str
        Item name → its error, for items that failed twice.
    submitted : int
        Tasks sent to the cluster, retries included (0 for a finished batch).
    seconds : float
    manifest : Path
    """

    total: int
    made: int = 0
    skipped: int = 0
    failed: dict[str, str] = field(default_factory=dict)
    submitted: int = 0
    seconds: float = 0.0
    manifest: Path = Path()

    @property
    def ok(self) -> bool:
        """Whether every item is done."""
        return not self.failed and self.made + self.skipped == self.total

    def line(self) -> str:
        """The one-line summary the command prints."""
        text = (
            f"{self.total} items: {self.made} made, {self.skipped} already done, {len(self.failed)} failed "
            f"({self.submitted} tasks, {self.seconds:.1f} s)"
        )
        if self.failed:
            name, error = next(iter(self.failed.items()))
            text += f"; first failure {name}: {error}; see {self.manifest}"
        return text


def _worker_share() -> tuple[int | None, int | None]:
    """The threads and memory of the Dask worker running this task (None outside a worker)."""
    try:
        from distributed import get_worker

        w = get_worker()
    except (ImportError, ValueError):
        return None, None
    mem = w.memory_manager.memory_limit
    return int(w.state.nthreads), (int(mem) if mem else None)


def _last_line(text: str) -> str:
    lines = [ln.strip() for ln in text.strip().splitlines() if ln.strip()]
    return lines[-1] if lines else ""


def run_item(argv: list[str], targets: Sequence[str], root: str, threads: int | None,
             max_memory: int | None) -> dict[str, Any]:  # fmt: skip
    """Run one item's ``phloem`` command here (in a worker); its outcome as a manifest record
    with the hashes of the files of ``targets`` (its output, then any extra outputs).

    ``threads`` and ``max_memory`` default to the worker's own share.
    """
    from ..cli import main

    own_threads, own_memory = _worker_share()
    threads = threads if threads is not None else own_threads
    max_memory = max_memory if max_memory is not None else own_memory
    full = list(argv)
    if threads is not None:
        full += ["--threads", str(threads)]
    if max_memory is not None:
        full += ["--max-memory", str(max_memory)]
    t0 = time.perf_counter()
    err = io.StringIO()
    error = ""
    with _ONE_COMMAND:
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                status = main([*full, *TASK_FLAGS])
        except SystemExit as e:  # argparse refused the arguments
            status = e.code if isinstance(e.code, int) else 2
        except Exception as e:  # an internal failure of the command: record it, the batch goes on
            status, error = 1, f"{type(e).__name__}: {_last_line(str(e)) or 'no message'}"
    seconds = time.perf_counter() - t0
    rec: dict[str, Any] = {"argv": full, "seconds": round(seconds, 3)}
    if status == 0:
        hashes = {k: v for t in targets for k, v in file_hashes(Path(t), Path(root)).items()}
        rec.update(status="ok", outputs=hashes, error=None)
    else:
        rec.update(status="failed", outputs={}, error=error or _last_line(err.getvalue()) or f"exit status {status}")
    return rec


def local_cluster(workers: int | None = None) -> Any:
    """A ``LocalCluster`` that shares this machine out without oversubscribing it.

    ``workers`` processes (default: one per core), each running one task at a time; every
    task gets ``cores // workers`` threads and ``1/workers`` of phloem's memory budget
    (:func:`phloem._memory.default_limit`), which is also the worker's Dask memory limit.
    """
    import dask
    from distributed import LocalCluster

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    n = cores if workers is None else workers
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"workers: expected a positive number of worker processes, got {workers!r}")
    # Dask's nannies set their workers' variables (OMP_NUM_THREADS=1, MALLOC_TRIM_THRESHOLD_, ...)
    # in this process's own environment before spawning; every later subprocess of the caller
    # would inherit them, so the caller's environment is put back once the workers exist.
    saved = dict(os.environ)
    cluster = None
    try:
        # Dask's default MALLOC_TRIM_THRESHOLD_=65536 makes glibc map and fault in every large
        # array afresh, which slows array-heavy items (docs/pipelines/batch.md#speed)
        with (
            dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}),
            _interrupts_held(),
        ):
            cluster = LocalCluster(  # type: ignore[no-untyped-call]
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                memory_limit=_memory.default_limit() // n,
                dashboard_address=None,
                # no dashboard; its HTTP server (metrics) on a free loopback port: the default 8787 may be taken
                scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
                host="127.0.0.1",
                # workers' and scheduler's own log lines off: a batch reports each item itself, and
                # an interrupted batch's teardown races the workers' heartbeats, which log errors
                silence_logs=logging.CRITICAL,
            )
    except BaseException:  # e.g. a Ctrl-C held back while the workers started
        if cluster is not None:
            cluster.close()
        raise
    finally:
        os.environ.clear()
        os.environ.update(saved)
    return cluster


@contextlib.contextmanager
def _interrupts_held() -> Iterator[None]:
    """A Ctrl-C held back meanwhile and raised on leaving; SIGINT blocked in every thread and
    process started meanwhile.

    The cluster's loop thread inherits the blocked mask, and so do the worker processes it
    spawns, now or on a restart: a terminal's Ctrl-C, sent to the whole process group, then
    reaches only this process, which shuts the workers down itself instead of each worker
    dying with its own traceback. Held back, a Ctrl-C cannot abort the cluster half-built,
    beyond the reach of the caller's clean-up.
    """
    if not hasattr(signal, "pthread_sigmask"):  # Windows: no process groups to share a Ctrl-C
        yield
        return
    from multiprocessing import resource_tracker

    # started here first: starting it unblocks SIGINT in whichever thread does so
    resource_tracker.ensure_running()
    held: list[int] = []
    # threads started before (a BLAS pool) still take SIGINT: Python's handler must not raise meanwhile
    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, lambda signum, _: held.append(signum)) if main else None
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        if signal.SIGINT in signal.sigpending():
            held.append(signal.sigwait({signal.SIGINT}))
        signal.pthread_sigmask(signal.SIG_SETMASK, old)
        if main:
            # None: a handler installed outside Python, which signal.signal cannot put back
            signal.signal(signal.SIGINT, previous if previous is not None else signal.default_int_handler)
            if held and callable(previous):
                previous(signal.SIGINT, None)  # Python's own handler raises KeyboardInterrupt
            elif held and previous == signal.SIG_DFL:
                signal.raise_signal(signal.SIGINT)


@contextlib.contextmanager
def _interrupts_latched() -> Iterator[Callable[[], bool]]:
    """A Ctrl-C that Python swallows meanwhile, kept: yields ``interrupted()``, and raises
    KeyboardInterrupt on leaving if one was swallowed.

    Python raises a Ctrl-C in whatever the main thread runs at that moment. In a garbage
    collector callback (Dask's GC diagnosis), a ``__del__`` or a weakref callback it is only
    printed as "Exception ignored" and the batch would run on to the end with status 0.
    """
    swallowed: list[BaseException] = []
    previous = sys.unraisablehook

    def hook(unraisable: Any) -> None:
        if isinstance(unraisable.exc_value, KeyboardInterrupt):
            swallowed.append(unraisable.exc_value)
        else:
            previous(unraisable)

    sys.unraisablehook = hook
    try:
        yield lambda: bool(swallowed)
    finally:
        sys.unraisablehook = previous
    if swallowed:
        raise KeyboardInterrupt


def _local_share(cluster: Any) -> tuple[int, int]:
    """Threads and memory of each task on a :func:`local_cluster`."""
    n = max(1, len(cluster.workers))
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, cores // n), _memory.default_limit() // n


@contextlib.contextmanager
def _client(client: Any, workers: int | None) -> Iterator[tuple[Any, int | None, int | None]]:
    """The given client (the workers' own shares), or one on a new :func:`local_cluster`."""
    if client is not None:
        yield client, None, None
        return
    from distributed import Client

    with _dask_logs_silenced(), local_cluster(workers) as cluster, Client(cluster) as c:  # type: ignore[no-untyped-call]
        threads, memory = _local_share(cluster)
        yield c, threads, memory


@contextlib.contextmanager
def _dask_logs_silenced() -> Iterator[None]:
    """This process's Dask and Tornado log handlers at CRITICAL while a batch's own cluster lives.

    Ctrl-C lands in the client's waits and its cancellation callbacks, which Dask and Tornado
    log as errors with tracebacks while the batch's one-line message is all a user should see.
    """
    handlers = [h for name in ("distributed", "tornado", "tornado.application")
                for h in logging.getLogger(name).handlers if isinstance(h, logging.StreamHandler)]  # fmt: skip
    saved = [h.level for h in handlers]
    for h in handlers:
        h.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        for h, level in zip(handlers, saved):
            h.setLevel(level)


def _record(item: Item, rec: Mapping[str, Any], attempts: int) -> dict[str, Any]:
    return {
        "item": item.name,
        "job": item.job,
        "input": item.input,
        "seed": item.seed,
        "params": item.params,
        "attempts": attempts,
        **rec,
    }


def run(
    spec: Spec | Mapping[str, Any] | str | os.PathLike[str],
    *,
    out_dir: str | os.PathLike[str],
    client: Any = None,
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Summary:
    """Run a batch: every (input, seed) item of ``spec`` as one Dask task, resumably.

    Parameters
    ----------
    spec : Spec, mapping or path-like
        A spec file (YAML or JSON), its mapping, or a :func:`load_spec` result.
    out_dir : path-like
        The folder of the outputs and of ``manifest.jsonl`` (created if missing). Items
        whose files are there and match the manifest's hashes are skipped.
    client : distributed.Client, optional
        Run on this client's cluster (e.g. ``Client("tcp://host:8786")``); each task then
        takes its worker's threads and memory limit. The workers must see ``out_dir`` and the
        inputs at the same paths. Default: a new :func:`local_cluster` for this batch.
    workers : int, optional
        Worker processes of the local cluster (default: one per core); not with ``client``.
    progress : callable, optional
        ``progress(done, total)`` as items finish (skipped items count as done).

    Returns
    -------
    Summary
        A failed item (after one retry) is in ``Summary.failed`` and in the manifest with
        its error; the others are made regardless.

    Examples
    --------
    >>> import tempfile, phloem.batch, phloem.data
    >>> spec = {"job": "synthesize", "inputs": [phloem.data.path("brick.png")],
    ...         "params": {"size": "32x32", "iterations": 1}, "seeds": [0, 1]}
    >>> with tempfile.TemporaryDirectory() as out:  # doctest: +SKIP
    ...     print(phloem.batch.run(spec, out_dir=out, workers=2).line())
    2 items: 2 made, 0 already done, 0 failed (2 tasks, ...)
    """
    t0 = time.perf_counter()
    if not isinstance(spec, Spec):
        spec = load_spec(spec)
    if client is not None and workers is not None:
        raise ValueError("workers: give workers for a local cluster or a client, not both")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ValueError(f"workers: expected a positive number of worker processes, got {workers!r}")
    root = Path(out_dir).absolute()
    if root.exists() and not root.is_dir():
        raise ValueError(f"out_dir: {root} exists and is not a folder")
    root.mkdir(parents=True, exist_ok=True)
    _sweep(root)
    manifest = Manifest(root)
    done = manifest.records()
    summary = Summary(total=len(spec.items), manifest=manifest.path)
    todo = [it for it in spec.items if not manifest.verified(done.get(it.name))]
    summary.skipped = summary.total - len(todo)
    # a prepared model shared by all items: built by the first, loaded by the others
    extra, cache = spec.shared_cache(root)

    def report() -> None:
        if progress is not None:
            progress(summary.skipped + summary.made + len(summary.failed), summary.total)

    report()
    if todo:
        with _interrupts_latched() as interrupted, _client(client, workers) as (c, threads, memory):
            _schedule(
                c,
                todo,
                root,
                extra,
                threads,
                memory,
                manifest,
                summary,
                report,
                # a cache made before (a stale one is remade, by every worker at worst)
                alone_first=cache is not None and not (cache.is_dir() and any(cache.iterdir())),
                interrupted=interrupted,
            )
    _sweep(root)
    summary.seconds = time.perf_counter() - t0
    return summary


_TEMPORARY = re.compile(r"\.(.+)\.\d+\.[a-z0-9_]{8}\.tmp")


def _sweep(root: Path) -> None:
    """Remove the temporaries that writers killed mid-write left in ``root`` (a killed batch's
    workers can outlive its driver by a moment); a live writer's are left alone."""
    for p in root.rglob(".*.tmp"):
        m = _TEMPORARY.fullmatch(p.name)
        if m is not None:
            _files.remove_stale_temporaries(p.parent / m.group(1))


def run_items(argvs: list[tuple[list[str], list[str]]], root: str, threads: int | None,
              max_memory: int | None) -> list[dict[str, Any]]:  # fmt: skip
    """Run a chunk of items one after the other here (in a worker): :func:`run_item` for each."""
    return [run_item(argv, targets, root, threads, max_memory) for argv, targets in argvs]


#: Items are run singly until 2 per worker have finished; their lower-quartile time then sets
#: how many later items go into one task, so that each task takes about ``_TASK_SECONDS``
#: (3 per worker are sent, so that none idles meanwhile).
_PROBE_PER_WORKER = 3
_TASK_SECONDS = 0.5


def _chunk_size(seconds: list[float], remaining: int, workers: int) -> int:
    """Items per task for the rest of a batch: enough to make a task about ``_TASK_SECONDS``
    (each task has a fixed scheduling cost), but at least 4 tasks per worker left, so that no
    worker idles long at the end."""
    if not seconds or remaining <= 0:
        return 1
    # the lower quartile: each worker's first item also reads the shared model, and the workers
    # read it side by side, so up to half of the first results are such reads
    per_item = max(float(np.percentile(seconds, 25)), 1e-3)
    return max(1, min(int(_TASK_SECONDS / per_item), remaining // (4 * workers), 64))


def _schedule(
    c: Any,
    todo: list[Item],
    root: Path,
    extra: list[str],
    threads: int | None,
    memory: int | None,
    manifest: Manifest,
    summary: Summary,
    report: Callable[[], None],
    *,
    alone_first: bool,
    interrupted: Callable[[], bool],
) -> None:
    from distributed import as_completed

    workers = max(1, len(c.scheduler_info().get("workers", {})))
    names_of: dict[str, list[str]] = {}  # task key -> its items' names
    attempt_of: dict[str, int] = {}

    def submit(chunk: list[Item], attempt: int) -> Any:
        summary.submitted += 1
        key = f"phloem-batch-{chunk[0].name}" + (f"+{len(chunk) - 1}" if len(chunk) > 1 else "") + f"-{attempt}"
        names_of[key] = [it.name for it in chunk]
        for it in chunk:
            attempt_of[it.name] = attempt
        argvs = [(it.argv(root, extra=extra), [str(it.outputs(root)), *map(str, it.extra_outputs(root).values())])
                 for it in chunk]  # fmt: skip
        return c.submit(run_items, argvs, str(root), threads, memory, key=key, pure=False)

    items = {it.name: it for it in todo}
    queue = list(todo)
    # the first item alone when it builds the shared cache the others read
    n_probe = 1 if alone_first else min(len(queue), _PROBE_PER_WORKER * workers)
    futures = as_completed()  # type: ignore[no-untyped-call]
    for it in queue[:n_probe]:
        futures.add(submit([it], 1))  # type: ignore[no-untyped-call]
    queue = queue[n_probe:]
    probe_left = n_probe
    seconds: list[float] = []
    for fut in futures:
        if interrupted():  # a Ctrl-C swallowed while waiting: stop here, not at the batch's end
            raise KeyboardInterrupt
        names = names_of.pop(fut.key)
        try:
            recs = fut.result()
        except Exception as e:  # the worker died (e.g. killed for memory) or the task could not run
            rec = {"status": "failed", "outputs": {}, "error": f"{type(e).__name__}: {_last_line(str(e))}"}
            recs = [rec] * len(names)
        fut.release()
        done = []
        for name, rec in zip(names, recs):
            item = items[name]
            if rec["status"] != "ok" and attempt_of[name] == 1:
                futures.add(submit([item], 2))  # type: ignore[no-untyped-call]  # retried alone
                continue
            if rec["status"] == "ok":
                seconds.append(float(rec["seconds"]))
            done.append(_record(item, rec, attempt_of[name]))
            if rec["status"] == "ok":
                summary.made += 1
            else:
                summary.failed[name] = str(rec["error"])
        if done:
            manifest.append(done)
            report()
        probe_left -= 1
        if queue and (probe_left <= 0 or (not alone_first and len(seconds) >= 2 * workers)):
            if alone_first and probe_left == 0:
                # the cache exists now: probe the item time on every worker before chunking
                n_probe = min(len(queue), _PROBE_PER_WORKER * workers)
                for it in queue[:n_probe]:
                    futures.add(submit([it], 1))  # type: ignore[no-untyped-call]
                queue, probe_left, alone_first = queue[n_probe:], n_probe, False
                continue
            size = _chunk_size(seconds, len(queue), workers)
            for k in range(0, len(queue), size):
                futures.add(submit(queue[k : k + size], 1))  # type: ignore[no-untyped-call]
            queue = []
