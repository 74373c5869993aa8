"""Held-out completion check: phloem against PyPatchMatch on random fills of real photos.

Random crops (``--crop`` px, photos first scaled so their short side is at most twice that) of
the real-image collection's textures, bark, leaves, strokes and branching photos (the completion
benchmark's coffee image and two-level masks left out), each with a random square hole of 1/8
to 1/4 of the crop's side. Every tool gets the same 8-bit image with the hole blacked out.
Reported per fill: the mean absolute error inside the hole against the original (0–1); then per
tool the mean error, its ratio to PyPatchMatch's, on how many fills it is lower, and the total
time (all in one run, so comparable).

Usage::

    PYTHONPATH=python:/tmp/pp-site python benches/peers/heldout_completion.py [--n 24] [--seed 0]

(PyPatchMatch: ``pip install --target /tmp/pp-site PyPatchMatch``, then remove the numpy and
Pillow it brings along from that folder.)
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np

from phloem.testing import shared_path

FOLDERS = ("textures", "bark", "leaves", "strokes", "branching")
Tool = Callable[[np.ndarray, np.ndarray], np.ndarray]  # (damaged u8, mask) -> float32 in [0, 1]


def images() -> list[Path]:
    out: list[Path] = []
    for folder in FOLDERS:
        for p in sorted(shared_path(folder).glob("*")):
            if p.suffix.lower() in (".jpg", ".jpeg", ".png") and not any(
                s in p.name for s in ("coffee", "mask", "_u16")
            ):
                out.append(p)
    return out


def cases(n: int, seed: int, crop: int) -> Iterator[tuple[str, np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    paths = images()
    if not paths:
        raise SystemExit(f"no images under {shared_path()} (set PHLOEM_SHARED_DATA)")
    for i in rng.choice(len(paths), size=n, replace=len(paths) < n):
        img = cv2.imread(str(paths[i]), cv2.IMREAD_COLOR)[..., ::-1]
        h, w = img.shape[:2]
        f = crop / min(h, w) if min(h, w) < crop else min(1.0, 2 * crop / min(h, w))
        if f != 1.0:
            interp = cv2.INTER_CUBIC if f > 1 else cv2.INTER_AREA
            img = cv2.resize(img, (max(crop, round(w * f)), max(crop, round(h * f))), interpolation=interp)
            h, w = img.shape[:2]
        y, x = rng.integers(0, h - crop + 1), rng.integers(0, w - crop + 1)
        im = np.ascontiguousarray(img[y : y + crop, x : x + crop])
        side = int(rng.integers(crop // 8, crop // 4 + 1))
        hy = int(rng.integers(side // 2 + 8, crop - side - 8))
        hx = int(rng.integers(side // 2 + 8, crop - side - 8))
        mask = np.zeros((crop, crop), bool)
        mask[hy : hy + side, hx : hx + side] = True
        yield paths[i].name, im, mask


def tools() -> dict[str, Tool]:
    import patchmatch

    import phloem

    def pm(src: np.ndarray, mask: np.ndarray) -> np.ndarray:
        return np.asarray(patchmatch.inpaint(src, mask.astype(np.uint8) * 255, patch_size=3), np.float32) / 255

    def ours(**kw: object) -> Tool:
        return lambda src, mask: phloem.texture.complete(src.astype(np.float32) / 255, mask, seed=0, **kw)

    return {"pypatchmatch": pm, "phloem": ours(), "interpolate": ours(pyramid="interpolate")}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=24, help="number of fills (default 24)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--crop", type=int, default=256)
    a = ap.parse_args(argv)
    ts = tools()
    err = dict.fromkeys(ts, 0.0)
    secs = dict.fromkeys(ts, 0.0)
    wins = dict.fromkeys(ts, 0)
    for name, u8, mask in cases(a.n, a.seed, a.crop):
        src = u8.copy()
        src[mask] = 0
        truth = u8.astype(np.float32) / 255
        row = {}
        for k, fn in ts.items():
            t0 = time.perf_counter()
            out = fn(src, mask)
            secs[k] += time.perf_counter() - t0
            row[k] = float(np.abs(out - truth)[mask].mean())
            err[k] += row[k]
        for k, e in row.items():
            wins[k] += e < row["pypatchmatch"]
        print(f"{name[:28]:<28} " + "  ".join(f"{k} {e:.4f}" for k, e in row.items()), flush=True)
    print("\n| tool | mean MAE | ratio to PyPatchMatch | fills below it | time |\n|---|---|---|---|---|")
    for k in ts:
        print(f"| {k} | {err[k] / a.n:.4f} | {err[k] / err['pypatchmatch']:.3f} | {wins[k]}/{a.n} | {secs[k]:.1f} s |")


if __name__ == "__main__":
    main()
