"""Peak memory of each job against its estimate (docs/hardening/memory.md).

Each case runs in its own subprocess: the peak resident memory during the job minus the resident
memory after importing phloem and building the inputs (the baseline), next to ``phloem._memory`` 's estimate
of the same call. ``python benches/memory/measure.py [JOB ...]`` prints a table.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import phloem

# (job, setup code defining the inputs, the call with {n} for the size) — each a few seconds at most
SETUP = {
    "spots": "yy, xx = np.mgrid[:64, :64]; spots = np.sin(yy / 4.0) * np.sin(xx / 5.0) > 0.3",
    "lab": "yy, xx = np.mgrid[:64, :64]; lab = (np.sin(yy / 4.0) * np.sin(xx / 5.0) > 0.3) + 2 * (np.cos(xx / 6.0 + yy / 9.0) > 0.8)",
    "bark": "img = phloem.data.bark()[:96, :96]; li = phloem.bark.input_labels(img, 2)",
    "hole": "img = phloem.data.bark()",
    "branch": (
        "import cv2; img = np.full((96, 128), 0.8, np.float32); cv2.line(img, (5, 90), (70, 40), 0.1, 5); "
        "cv2.line(img, (70, 40), (125, 5), 0.1, 4); cv2.line(img, (70, 40), (90, 92), 0.1, 3); "
        "src = phloem.branching.trace(img, kind='dark', sigmas=(1.5, 2.5))"
    ),
    "grow": (
        "from phloem.branching.synthetic import synthetic_skeleton; "
        "bend = phloem.branching.BendingModel.fit(synthetic_skeleton(0), h=2.0)"
    ),
    "stroke": (
        "img = np.zeros((120, 400, 4), np.float32); img[..., :3] = np.resize(phloem.data.bark()[..., :3], (120, 400, 3)); "
        "img[40:80, 10:390, 3] = 1.0"
    ),
    "tree": (
        "img = np.zeros((120, 80, 4), np.float32); img[..., 1] = 0.5; img[..., 3] = 0; "
        "img[10:70, 10:70, 3] = 1.0; img[70:110, 35:45, 3] = 1.0"
    ),
}
CASES: dict[str, tuple[str, str, str, tuple[int, int]]] = {
    # job: (setup, call, estimate call, two sizes)
    "shapes.synthesize": (
        "spots",
        "phloem.shapes.synthesize(spots, {n}, patch_size=7, threads=2)",
        "M.shapes_synthesize(({n}, {n}), (64, 64))",
        (512, 1024),
    ),
    "shapes.synthesize_labels": (
        "lab",
        "phloem.shapes.synthesize_labels(lab, {n}, method='joint', patch_size=7, threads=2)",
        "M.shapes_labels(({n}, {n}), (64, 64), 4)",
        (384, 768),
    ),
    "texture.synthesize": (
        "hole",
        "phloem.texture.synthesize(img, {n}, threads=2)",
        "M.texture_synthesize(({n}, {n}), img.shape)",
        (256, 512),
    ),
    "texture.quilt": (
        "hole",
        "phloem.texture.quilt(img, {n}, threads=2)",
        "M.quilt(({n}, {n}), img.shape)",
        (512, 1024),
    ),
    "texture.by_numbers": (
        "bark",
        "phloem.texture.by_numbers(img, li, np.tile(li, ({n} // 96, {n} // 96)), threads=2)",
        "M.by_numbers(({n}, {n}), img.shape, 4)",
        (192, 384),
    ),
    "texture.complete": (
        "hole",
        "m = np.zeros(({n}, {n}), bool); m[{n}//3:{n}//2, {n}//3:{n}//2] = True; "
        "phloem.texture.complete(np.resize(img, ({n}, {n}, 4)), m, threads=2)",
        "M.complete(({n}, {n}, 4))",
        (256, 512),
    ),
    "bark.generate": (
        "bark",
        "phloem.bark.generate(img, {n}, threads=2)",
        "M.bark(({n}, {n}), img.shape, 3)",
        (192, 384),
    ),
    "branching.synthesize": (
        "branch",
        "phloem.branching.synthesize(img, src, size={n}, threads=2)",
        "M.branching(({n}, {n}), img.shape)",
        (192, 384),
    ),
    "branching.grow": (
        "grow",
        "phloem.branching.grow(bend, size={n}, seed=0, branch_length=60, max_length=2000)",
        "M.grow(({n}, {n}), colonize=True, guide=False)",
        (1024, 2048),
    ),
    "trees.variation": (
        "tree",
        "lib = phloem.trees.Library.from_images([img, img[:, ::-1], img[20:]], size={n}); "
        "phloem.trees.variation(lib, seed=3)",
        "M.trees({n}, 3)",
        (512, 1024),
    ),
    "strokes.edit": (
        "stroke",
        "phloem.strokes.edit(img, [[[15, 60], [385, 60]]], [[[20, 30], [{n} // 2, {n} // 2], [{n} - 20, {n} - 60]]], "
        "size=({n}, {n}), threads=2)",
        "M.strokes_edit(({n}, {n}), img.shape)",
        (512, 1024),
    ),
    "patch.nnf": (
        "hole",
        "a = np.resize(img, ({n}, {n}, 4)); phloem.patch.nnf(a, a[::-1].copy(), threads=2)",
        "M.nnf(({n}, {n}, 4), ({n}, {n}, 4))",
        (512, 1024),
    ),
}

# The peak is read as VmHWM after resetting it (clear_refs 5, Linux >= 4.0) once the inputs are
# built: ru_maxrss keeps any earlier transient peak (an import's, the inputs'), whose freed pages
# the job then reuses unseen, so its difference undercounts by as much as that peak.
PROG = """
import json, resource, sys, numpy as np, phloem
from phloem import _memory as M
{setup}
def status(key):
    with open("/proc/self/status") as f:
        return next(int(l.split()[1]) * 1024 for l in f if l.startswith(key + ":"))
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")
base = status("VmRSS")
est = {estimate}
{call}
peak = status("VmHWM")
print(json.dumps([peak - base, est]))
"""


def measure(job: str, n: int, env: dict[str, str] | None = None) -> tuple[int, int]:
    """(measured peak over baseline, estimate) in bytes for ``job`` at size ``n``."""
    setup, call, estimate, _ = CASES[job]
    code = PROG.format(setup=SETUP[setup], call=call.format(n=n), estimate=estimate.format(n=n))
    env = {
        **os.environ,
        "PYTHONPATH": str(Path(phloem.__file__).resolve().parents[1]),
        "PHLOEM_NUM_THREADS": "2",
        **(env or {}),
    }
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300, check=True)
    got, est = json.loads(out.stdout.strip().splitlines()[-1])
    return int(got), int(est)


if __name__ == "__main__":
    jobs = sys.argv[1:] or list(CASES)
    print("| job | size | estimate (MB) | measured peak − baseline (MB) | ratio |")
    print("|---|---|---|---|---|")
    for job in jobs:
        for n in CASES[job][3]:
            got, est = measure(job, n)
            print(f"| {job} | {n}² | {est / 1e6:.0f} | {got / 1e6:.0f} | {est / max(got, 1):.2f} |", flush=True)
