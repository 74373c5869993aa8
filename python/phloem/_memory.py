"""The memory budget: every job estimates its peak memory from its arguments before it allocates.

A request over the limit is refused with :class:`MemoryLimitError` (a ``ValueError``, so the
CLI reports it in one line with exit status 2) instead of growing until the operating system
kills the process or Rust aborts on a failed allocation. The estimates are arithmetic on the
sizes of each job's peak buffers (``docs/hardening/memory.md`` gives the model of each job and
the measurements its constants come from); they cost nothing next to the job.
"""

from __future__ import annotations

import contextlib
import math
import numbers
import os
import re
import resource
from functools import lru_cache
from typing import Any

__all__ = ["MemoryLimitError", "check", "default_limit", "format_bytes", "limit", "parse_memory"]

#: The share of the machine's memory a job may plan to use by default: the estimates are within
#: a factor of 2 of the measured peak, and the rest is left to the interpreter, the inputs, the
#: outputs a caller keeps and whatever else runs on the machine.
FRACTION = 0.75

_UNITS = {"": 1, "B": 1, "K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40}


class MemoryLimitError(ValueError):
    """A job's estimated peak memory is over the limit (``max_memory=``, ``--max-memory``).

    Examples
    --------
    >>> import numpy as np, phloem
    >>> spots = np.indices((64, 64)).sum(axis=0) % 9 < 4
    >>> phloem.shapes.synthesize(spots, 100_000)
    Traceback (most recent call last):
    ...
    phloem._memory.MemoryLimitError: size: 100000×100000 (height×width) needs about 1.36 TiB, over the memory limit ...
    >>> isinstance(phloem.MemoryLimitError(), ValueError)
    True
    """


def _cgroup_limit() -> int | None:
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            with open(path) as f:
                text = f.read().strip()
        except OSError:
            continue
        if text.isdigit() and int(text) < 2**60:  # cgroup v1 writes a huge number for "no limit"
            return int(text)
    return None


@lru_cache(maxsize=1)
def _machine_memory() -> int:
    """The smallest of physical RAM, the cgroup's memory.max and RLIMIT_AS (bytes)."""
    found = []
    with contextlib.suppress(ValueError, OSError, AttributeError):
        found.append(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    cg = _cgroup_limit()
    if cg is not None:
        found.append(cg)
    return min(found) if found else 8 * 2**30


def default_limit() -> int:
    """:data:`FRACTION` of the machine's memory (RLIMIT_AS is read on each call: it can change)."""
    mem = _machine_memory()
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY and soft > 0:
        mem = min(mem, soft)
    return int(mem * FRACTION)


def format_bytes(n: float) -> str:
    """``n`` bytes in the binary units ``--max-memory`` reads (``8G`` is 8 GiB)."""
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{int(n)} bytes"


def limit(max_memory: Any) -> int:
    """The checked ``max_memory`` (a positive int of bytes), or the default for None."""
    if max_memory is None:
        return default_limit()
    if isinstance(max_memory, bool) or not isinstance(max_memory, numbers.Integral):
        raise TypeError(f"max_memory: expected a positive int of bytes or None, got {max_memory!r}")
    if int(max_memory) < 1:
        raise ValueError(f"max_memory: expected a positive int of bytes or None, got {max_memory!r}")
    return int(max_memory)


def parse_memory(text: str) -> int:
    """``--max-memory``: bytes, or a number with K, M, G or T (powers of 1024), e.g. ``8G``, ``512M``."""
    m = re.fullmatch(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*([KMGT]?)i?B?\s*", text, re.IGNORECASE)
    value = float(m.group(1)) * _UNITS[m.group(2).upper()] if m else math.nan
    if not (value >= 1 and math.isfinite(value)):
        raise ValueError(f"expected a positive number of bytes such as 8G, 512M or 1000000, got {text!r}")
    return int(value)


def check(estimate: float, max_memory: Any, name: str, what: str) -> None:
    """Refuse a job whose ``estimate`` (bytes) is over the limit; ``name`` is the argument that
    made it big and ``what`` says its value (e.g. ``"100000×100000"``)."""
    cap = limit(max_memory)
    if estimate > cap:
        raise MemoryLimitError(
            f"{name}: {what} needs about {format_bytes(estimate)}, over the memory limit of {format_bytes(cap)}; "
            f"ask for less or raise max_memory (default {FRACTION:.0%} of this machine's memory)"
        )


def check_size(estimate: float, max_memory: Any, size: tuple[int, ...], name: str = "size") -> None:
    """:func:`check` for a job made big by its output ``size`` ``(height, width)``."""
    check(estimate, max_memory, name, f"{size[0]}×{size[1]} (height×width)")


# The models: bytes per pixel of each job's peak buffers, per output pixel (and per exemplar or
# source pixel where it holds copies of those), calibrated by benches/memory/measure.py with 2
# threads (docs/hardening/memory.md). A pyramid adds a third of its finest level at most; the
# constants include that. Per-thread buffers are patch-sized and negligible.


def _px(shape: tuple[int, ...]) -> int:
    return int(shape[0]) * int(shape[1])


def _ch(shape: tuple[int, ...]) -> int:
    return int(shape[2]) if len(shape) > 2 else 1


def shapes_synthesize(size: tuple[int, int], example: tuple[int, ...]) -> int:
    """Boundary-patch shape synthesis: the output's level maps, distance and boundary fields and
    the matched patch offsets (i32/f32 each, over the pyramid), ~150 B per output pixel."""
    return 150 * _px(size) + 150 * _px(example)


def shapes_labels(size: tuple[int, int], example: tuple[int, ...], k: int) -> int:
    """The joint (and layered) label synthesis: the shape engine's buffers plus one signed
    distance/indicator field per label (~26 B per label and pixel)."""
    return (125 + 26 * k) * (_px(size) + _px(example))


def texture_synthesize(size: tuple[int, int], example: tuple[int, ...]) -> int:
    """Texture optimisation: the output, the vote accumulators and the exemplar level (f32 per
    channel), the field and distances (i32 ×2, f32) and the robust weights."""
    return (75 + 25 * _ch(example)) * _px(size) + 8 * _ch(example) * _px(example)


def quilt(size: tuple[int, int], example: tuple[int, ...]) -> int:
    """Quilting: the output and its sources (f32 per channel, i32 ×2) and the seam labels; the
    masked SSD over the whole exemplar per block (f32 per channel and exemplar pixel, a few)."""
    return (20 + 4 * _ch(example)) * _px(size) + 48 * _ch(example) * _px(example)


def by_numbers(size: tuple[int, int], example: tuple[int, ...], channels: int) -> int:
    """Texture-by-numbers: the engine's output pyramid, its features and label-distance maps,
    the sources and k-coherence candidates per pixel, and the result copied out."""
    return (200 + 30 * channels) * _px(size) + (200 + 30 * channels) * _px(example)


def complete(shape: tuple[int, ...], pad: int = 0) -> int:
    """Completion works on the whole image: values and gradients (3 × channels f32), the vote
    accumulators, the hole pyramid and the field and distances. A tileable completion also holds
    the features and source mask grown by ``pad`` on every side (the source of its patches)."""
    grown = 0 if pad <= 0 else (12 * _ch(shape) + 1) * (shape[0] + 2 * pad) * (shape[1] + 2 * pad)
    return (100 + 40 * _ch(shape)) * _px(shape) + grown


def leaves_analyze(size: tuple[int, int], n_exemplars: int, n_layers: int) -> int:
    """Leaf analysis holds per exemplar, on the canvas, the posed, aligned and peeled RGBA leaf
    and both fields (64 B per pixel) and per layer its mask, D and RGBA layer (21 B), beside the
    colour and spatial maps of one induction (12 B per exemplar) and one completion's buffers."""
    per = 64 + 21 * max(0, n_layers - 1) + 12
    return per * n_exemplars * _px(size) + complete((*size, 3))


def bark(size: tuple[int, int], example: tuple[int, ...], channels: int) -> int:
    """The bark pipeline's peak is its texture-by-numbers stage, with the label maps and the
    sources held beside it."""
    return by_numbers(size, example, channels) + 60 * _px(size)


def branching(size: tuple[int, int], image: tuple[int, ...]) -> int:
    """Rendering a branching image: the output and the completion of its gaps (f32 per channel),
    the fragment-coverage, seam and branch maps per pixel."""
    c = _ch(image)
    return (100 + 20 * c) * _px(size) + (100 + 20 * c) * _px(image) + 5 * 2**20


def grow(size: tuple[int, int], *, colonize: bool, guide: bool) -> int:
    """Growing a skeleton: the colonisation density and its two owner maps (f32, i32 ×2) and
    the guide's distance and direction maps (f64 ×2) over the canvas."""
    return (12 * colonize + 16 * guide) * _px(size) + 2**20


def trees(size: int, n_trees: int) -> int:
    """Tree billboards: each prepared tree holds its RGBA image, alpha and crown/trunk maps at
    ``size``², and a variation warps and blends at that size."""
    return (30 * n_trees + 30) * size * size


def nnf(source: tuple[int, ...], target: tuple[int, ...], k: int = 1, kdtree: bool = False) -> int:
    """PatchMatch: the field and distances per target pixel and neighbour (i32 ×2, f32, and the
    candidate heaps), the padded copies of both images (f32 per channel); the kd-tree search
    adds its reduced patch vectors and tree nodes per source pixel."""
    c = _ch(target)
    return (28 + 10 * c + 18 * (k - 1)) * _px(target) + (4 * c + (120 if kdtree else 0)) * _px(source)


def strokes_edit(size: tuple[int, int], image: tuple[int, ...]) -> int:
    """Stroke-based editing: the canvas (RGBA f32), its piece labels and the copies the clean-up
    and the Poisson pasting make (about 64 B per output pixel); the source's RGBA copy, its
    distance maps and the strokes' parts (about 64 B per source pixel), plus 4 MB; checked
    against benches/memory/measure.py (peaks of 21–26 and 48–66 MB at 512² and 1024²)."""
    return 64 * _px(size) + 64 * _px(image) + 2**22
