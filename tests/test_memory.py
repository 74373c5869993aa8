"""The memory budget (phloem._memory): estimates against measured peaks, refusals, max_memory checks."""

from __future__ import annotations

import importlib.util
import math
import resource
from pathlib import Path

import numpy as np
import pytest

import phloem
from phloem import _memory

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("_memory_bench", ROOT / "benches" / "memory" / "measure.py")
assert _spec is not None and _spec.loader is not None
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)

GB = 2**30


@pytest.mark.parametrize(
    ("job", "n"), [(job, n) for job, case in bench.CASES.items() for n in case[3]], ids=lambda v: str(v)
)
def test_estimate_is_within_a_factor_of_2_of_the_measured_peak(job, n):
    # each case in its own interpreter: ru_maxrss after the job minus after the imports and inputs
    got, est = bench.measure(job, n)
    assert got > 0
    assert got / 2 <= est <= 2 * got, f"{job} at {n}²: estimate {est / 1e6:.0f} MB, measured {got / 1e6:.0f} MB"


@pytest.fixture(scope="module")
def spots():
    yy, xx = np.mgrid[:64, :64]
    return np.sin(yy / 4.0) * np.sin(xx / 5.0) > 0.3


@pytest.fixture(scope="module")
def lab(spots):
    return spots.astype(np.int32)


@pytest.fixture(scope="module")
def photo():
    return phloem.data.bark()[:96, :96, :3].copy()


@pytest.fixture(scope="module")
def branch():
    img = np.full((48, 64), 0.8, np.float32)
    img[20:26, :] = 0.1
    src = phloem.branching.Skeleton([phloem.branching.Branch([[2, 22.5], [61, 22.5]], 3.0)], (48, 64))
    return img, src


@pytest.fixture(scope="module")
def tree_lib():
    img = np.zeros((120, 80, 4), np.float32)
    img[..., 1] = 0.5
    img[10:70, 10:70, 3] = 1.0
    img[70:110, 35:45, 3] = 1.0
    return img, phloem.trees.Library.from_images([img, img[:, ::-1]], size=64)


def _calls(spots, lab, photo, branch, tree_lib, size):
    """Every public job, made big by ``size`` (an output side), as (name of the big argument, call)."""
    img, src = branch
    tree, lib = tree_lib
    big_lab = np.zeros((size, size), np.int32) if size <= 4096 else None
    li = (photo.mean(axis=2) > 0.3).astype(np.int32)
    tgt = phloem.branching.Skeleton([phloem.branching.Branch([[2, 22.5], [40, 22.5]], 3.0)], (size, size))
    return {
        "shapes.synthesize": ("size", lambda mm: phloem.shapes.synthesize(spots, size, patch_size=7, max_memory=mm)),
        "shapes.synthesize_labels": (
            "size",
            lambda mm: phloem.shapes.synthesize_labels(lab, size, patch_size=7, max_memory=mm),
        ),
        "bark.synthesize_labels": ("size", lambda mm: phloem.bark.synthesize_labels(lab, size, max_memory=mm)),
        "bark.generate": ("size", lambda mm: phloem.bark.generate(photo, size, max_memory=mm)),
        "texture.synthesize": ("size", lambda mm: phloem.texture.synthesize(photo, size, max_memory=mm)),
        "texture.quilt": ("size", lambda mm: phloem.texture.quilt(photo, size, max_memory=mm)),
        "texture.by_numbers": (
            "labels_out",
            lambda mm: phloem.texture.by_numbers(photo, li, big_lab, max_memory=mm),
        ),
        "branching.synthesize": (
            "size",
            lambda mm: phloem.branching.synthesize(img, src, size=size, max_memory=mm),
        ),
        "branching.grow": (
            "size",
            lambda mm: phloem.branching.grow(
                phloem.branching.BendingModel.fit(src, h=2.0), size=size, branch_length=20, max_memory=mm
            ),
        ),
        "branching.render": ("target_skeleton", lambda mm: phloem.branching.render(img, src, tgt, max_memory=mm)),
        "trees.Library.from_images": (
            "size",
            lambda mm: phloem.trees.Library.from_images([tree], size=size, max_memory=mm),
        ),
        "trees.variation": ("library", lambda mm: phloem.trees.variation(lib, max_memory=mm)),
        "trees.vary": ("library", lambda mm: phloem.trees.vary(tree, lib, n_variations=1, max_memory=mm)),
    }


JOBS = [
    "shapes.synthesize", "shapes.synthesize_labels", "bark.synthesize_labels", "bark.generate", "texture.synthesize",
    "texture.quilt", "texture.by_numbers", "branching.synthesize", "branching.grow", "branching.render", "trees.Library.from_images",
    "trees.variation", "trees.vary",
]  # fmt: skip


@pytest.mark.parametrize("job", [j for j in JOBS if j != "texture.by_numbers"])  # labels_out: an array
def test_a_huge_request_is_refused_before_it_allocates(job, spots, lab, photo, branch, tree_lib):
    # 16000² (under max_pixels) needs 3 to 100 GB: refused at once under 2 GiB, in one line naming the argument
    name, call = _calls(spots, lab, photo, branch, tree_lib, 16_000)[job]
    if job.startswith("trees.v"):
        call = _calls(spots, lab, photo, branch, tree_lib, 64)[job][1]
        with pytest.raises(phloem.MemoryLimitError, match=rf"^{name}: .* over the memory limit of .*max_memory"):
            call(1000)
        return
    with pytest.raises(phloem.MemoryLimitError) as e:
        call(2 * GB)
    msg = str(e.value)
    assert msg.startswith(f"{name}: ") and "needs about" in msg and "max_memory" in msg and "\n" not in msg
    assert "over the memory limit of 2 GiB" in msg  # the estimate and the limit
    assert isinstance(e.value, ValueError)


@pytest.mark.parametrize("job", JOBS)
def test_max_memory_too_small_refuses_a_small_job_and_enough_lets_it_run(job, spots, lab, photo, branch, tree_lib):
    name, call = _calls(spots, lab, photo, branch, tree_lib, 96)[job]
    with pytest.raises(phloem.MemoryLimitError, match=rf"^{name}: "):
        call(1000)
    call(2 * GB)  # the same job runs under a limit that fits it


def test_the_default_limit_refuses_terabytes(spots):
    with pytest.raises(phloem.MemoryLimitError, match=r"^size: 100000×100000 \(height×width\) needs about 1.36 TiB"):
        phloem.shapes.synthesize(spots, 100_000)


def test_patch_nnf_knn_and_complete_check_the_budget(photo):
    hole = np.zeros(photo.shape[:2], bool)
    hole[40:50, 40:50] = True
    with pytest.raises(phloem.MemoryLimitError, match=r"^target: 96×96 \(height×width\) needs about"):
        phloem.patch.nnf(photo, photo, max_memory=1000)
    with pytest.raises(phloem.MemoryLimitError, match=r"^k: 2 neighbours"):
        phloem.patch.knn(photo, 2, max_memory=1000)
    with pytest.raises(phloem.MemoryLimitError, match=r"^image: 96×96"):
        phloem.texture.complete(photo, hole, max_memory=1000)
    phloem.patch.nnf(photo, photo, max_memory=GB)
    phloem.patch.knn(photo, 2, max_memory=GB)
    phloem.texture.complete(photo, hole, max_memory=GB)


@pytest.mark.parametrize("bad", [0, -1, math.nan, "abc", "8G", 1.5, True])
def test_bad_max_memory_is_refused(bad, spots):
    with pytest.raises((ValueError, TypeError), match=r"^max_memory: expected a positive int of bytes or None"):
        phloem.shapes.synthesize(spots, 32, patch_size=7, max_memory=bad)


@pytest.mark.parametrize(
    ("text", "value"), [("8G", 8 * 2**30), ("512M", 512 * 2**20), ("1000000", 10**6), ("1.5k", 1536), ("2GiB", 2**31)]
)
def test_parse_memory(text, value):
    assert _memory.parse_memory(text) == value


@pytest.mark.parametrize("text", ["0", "-1", "abc", "nan", "inf", "", "8X", "1e9"])
def test_parse_memory_refuses(text):
    with pytest.raises(ValueError, match="expected a positive number of bytes"):
        _memory.parse_memory(text)


def test_default_limit_is_a_fraction_of_the_smallest_of_ram_cgroup_and_rlimit(monkeypatch):
    monkeypatch.setattr(_memory, "_machine_memory", lambda: 16 * GB)
    monkeypatch.setattr(resource, "getrlimit", lambda r: (resource.RLIM_INFINITY, resource.RLIM_INFINITY))
    assert _memory.default_limit() == int(16 * GB * _memory.FRACTION)
    monkeypatch.setattr(resource, "getrlimit", lambda r: (4 * GB, resource.RLIM_INFINITY))
    assert _memory.default_limit() == int(4 * GB * _memory.FRACTION)


def test_machine_memory_reads_the_cgroup_limit(monkeypatch):
    _memory._machine_memory.cache_clear()
    monkeypatch.setattr(_memory, "_cgroup_limit", lambda: 2 * GB)
    try:
        assert _memory._machine_memory() == 2 * GB
    finally:
        _memory._machine_memory.cache_clear()


def test_bark_generate_refuses_before_computing_the_input_labels(photo, monkeypatch):
    # the input labels take seconds on a big photo; a huge size must not wait for them
    def boom(*args, **kwargs):
        raise AssertionError("input_labels ran before the memory check")

    monkeypatch.setattr(phloem.bark.pipeline, "input_labels", boom)
    with pytest.raises(phloem.MemoryLimitError, match=r"^size: 100000×100000"):
        phloem.bark.generate(photo, 100_000)
