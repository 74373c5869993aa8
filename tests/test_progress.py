"""The progress bridge: Ctrl-C and a raising progress callback stop long Rust work promptly,
and a stopped run leaves its thread pool fit for the next call."""

from __future__ import annotations

import _thread
import hashlib
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import phloem
from phloem import blend, patch, seams, shapes, texture

# The interrupt must be acted on within this many seconds (the promise is "about a second";
# the margin is for a machine shared with other jobs).
LATENCY = 1.5


def _stripes(h: int, w: int, period: int) -> np.ndarray:
    return np.repeat((np.arange(w)[None, :] // period % 2).astype(np.int32), h, axis=0)


def _tbn_job(bark: np.ndarray, size: int, threads: int = 1, **kw: Any) -> Callable[[], Any]:
    lum = bark.mean(axis=2)
    la = (lum > np.median(lum)).astype(np.int32)
    lb = _stripes(size, size, 40)
    return lambda: texture.by_numbers(bark, la, lb, seed=0, threads=threads, **kw)


def _shapes_job(size: int) -> Callable[[], Any]:
    yy, xx = np.mgrid[0:96, 0:96]
    blob = (np.sin(yy / 7.0) + np.cos(xx / 5.0) > 0.3) & ((yy - 48) ** 2 + (xx - 48) ** 2 < 46**2)
    return lambda: shapes.synthesize(blob, (size, size), seed=0, threads=1)


def _nnf_job(rng: np.random.Generator, size: int) -> Callable[[], Any]:
    a = rng.random((size, size, 3), dtype=np.float32)
    b = rng.random((size, size, 3), dtype=np.float32)
    return lambda: patch.nnf(a, b, patch_size=7, iterations=200, seed=0, threads=1)


def _interrupt_latency(job: Callable[[], Any], delay: float = 0.5) -> float:
    """Seconds from a simulated Ctrl-C, `delay` seconds into `job`, to its KeyboardInterrupt."""
    fired: list[float] = []

    def fire() -> None:
        fired.append(time.monotonic())
        _thread.interrupt_main()

    timer = threading.Timer(delay, fire)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            job()
        return time.monotonic() - fired[0]
    finally:
        timer.cancel()
        timer.join()


def _digest(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()


@pytest.mark.parametrize("init", ["smart", "random"])
def test_ctrl_c_stops_texture_by_numbers(bark: np.ndarray, init: str) -> None:
    # Smart initialisation alone runs for seconds at this size; random starts the solver at once.
    assert _interrupt_latency(_tbn_job(bark, 1024, init=init)) < LATENCY


def test_ctrl_c_stops_graph_cut_compositing(bark: np.ndarray) -> None:
    # Past the solver's last iteration the compositing rounds run alone: interrupt there.
    fired: list[float] = []
    timers: list[threading.Timer] = []

    def fire() -> None:
        fired.append(time.monotonic())
        _thread.interrupt_main()

    def progress(done: int, total: int) -> None:
        if done == total:
            timers.append(threading.Timer(0.3, fire))
            timers[-1].start()

    try:
        with pytest.raises(KeyboardInterrupt):
            _tbn_job(bark, 256, init="random", iterations=1, composite=3, progress=progress)()
        assert time.monotonic() - fired[0] < LATENCY
    finally:
        for t in timers:
            t.cancel()
            t.join()


def test_ctrl_c_stops_shape_synthesis() -> None:
    assert _interrupt_latency(_shapes_job(2048)) < LATENCY


def test_ctrl_c_stops_patchmatch() -> None:
    assert _interrupt_latency(_nnf_job(np.random.default_rng(0), 512)) < LATENCY


def test_ctrl_c_stops_seamless_blending() -> None:
    # A tolerance f32 never reaches: 1000 PCG iterations on a 2048² region run for about 5 s.
    rng = np.random.default_rng(0)
    n = 2048
    src = rng.random((n, n, 3), dtype=np.float32)
    dst = rng.random((n, n, 3), dtype=np.float32)
    mask = np.zeros((n, n), bool)
    mask[1:-1, 1:-1] = True

    def job() -> Any:
        return blend.seamless(src, dst, mask, (0, 0), tol=1e-12, max_iterations=1000, threads=1)

    assert _interrupt_latency(job, delay=0.3) < LATENCY


def test_ctrl_c_stops_grid_maxflow() -> None:
    # Random 8-connected 1024² graph, terminals on half the pixels: Boykov–Kolmogorov runs
    # for about 15 s.
    rng = np.random.default_rng(0)
    n = 1024
    source = rng.random((n, n), dtype=np.float32) * (rng.random((n, n)) < 0.5)
    sink = rng.random((n, n), dtype=np.float32) * (rng.random((n, n)) < 0.5)
    edges = rng.random((n, n, 4), dtype=np.float32)

    def job() -> Any:
        return seams.grid_maxflow(source, sink, edges, connectivity=8, threads=1)

    assert _interrupt_latency(job, delay=0.3) < LATENCY


def test_a_raising_progress_callback_cancels_the_run_with_its_exception(bark: np.ndarray) -> None:
    class Stop(Exception):
        pass

    calls: list[tuple[int, int]] = []
    raised_at: list[float] = []

    def progress(done: int, total: int) -> None:
        calls.append((done, total))
        raised_at.append(time.monotonic())
        raise Stop

    with pytest.raises(Stop):
        _tbn_job(bark, 1024, init="random", progress=progress)()
    assert len(calls) == 1, "the callback is not called again once it raised"
    assert time.monotonic() - raised_at[0] < LATENCY

    def shape_progress(done: int, total: int) -> None:
        raised_at.append(time.monotonic())
        raise Stop

    yy, xx = np.mgrid[0:96, 0:96]
    blob = (yy - 48) ** 2 + (xx - 48) ** 2 < 40**2
    with pytest.raises(Stop):
        shapes.synthesize(blob, (1024, 1024), seed=0, threads=1, progress=shape_progress)
    assert time.monotonic() - raised_at[-1] < LATENCY


def test_progress_is_reported_in_order_on_the_calling_thread(bark: np.ndarray) -> None:
    seen: list[tuple[int, int, int]] = []
    _tbn_job(bark, 96, progress=lambda d, t: seen.append((d, t, threading.get_ident())))()
    assert seen, "progress was reported"
    assert {s[2] for s in seen} == {threading.get_ident()}
    assert [s[0] for s in seen] == list(range(1, seen[-1][1] + 1))


SMALL = """
import hashlib, sys
import numpy as np
import phloem
from phloem import texture
bark = phloem.data.bark()[..., :3].copy()
lum = bark.mean(axis=2)
la = (lum > np.median(lum)).astype(np.int32)
lb = np.repeat((np.arange(80)[None, :] // 20 % 2).astype(np.int32), 80, axis=0)
out = texture.by_numbers(bark, la, lb, seed=3, threads=2)
print(hashlib.sha256(np.ascontiguousarray(out).tobytes()).hexdigest())
"""


def test_a_cancelled_run_leaves_the_pool_usable(bark: np.ndarray) -> None:
    assert _interrupt_latency(_tbn_job(bark, 1024, init="random", threads=2)) < LATENCY
    # The same pool (two workers) serves the next call, and gives what a fresh process does.
    lum = bark.mean(axis=2)
    la = (lum > np.median(lum)).astype(np.int32)
    lb = _stripes(80, 80, 20)
    here = _digest(texture.by_numbers(bark, la, lb, seed=3, threads=2))
    env = dict(os.environ, PYTHONPATH=str(Path(phloem.__file__).resolve().parents[1]))
    fresh = subprocess.run(
        [sys.executable, "-c", SMALL], env=env, capture_output=True, text=True, check=True, timeout=300
    ).stdout.strip()
    assert here == fresh
