"""How well ``branching.trace`` finds the structure a person drew: photos against their manual masks.

    python benches/quality/branching_trace_truth.py [--crackforest REPO] [--deepcrack REPO]
        [--crack500 REPO] [--drive REPO] [--chase REPO] [--every N]
        [--fractions F ...] [--kinds bright|dark ...]

Public segmentation datasets pair photos of cracks and retinas with masks drawn by hand. Each
photo is traced with ``trace``'s defaults (``valid`` from ``valid_region``, as ``synthesize``
traces) and, in the same run, with Otsu's threshold of the ridge response (the default before
the grain rule, ``docs/pipelines/branching.md``); each mask is traced with ``kind="mask"``;
the two skeletons are scored by ``phloem.metrics.skeleton_agreement`` (precision: traced
points near the drawn structure; recall: drawn points near the trace). Each ``REPO`` is a clone
(a bare one will do) of the repository named below, read at its commit with ``git show``;
nothing is written. ``--every N`` scores every N-th pair. ``--fractions`` also scores the trace
at those fractions of the default threshold (with the default gap), ``--kinds`` with that
polarity forced; each row counts the photos it scores better or worse than the default.
"""

from __future__ import annotations

import argparse
import inspect
import io
import math
import subprocess
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image
from scipy.io import loadmat

from phloem.branching import trace, valid_region
from phloem.branching.trace import (
    DEFAULT_SIGMAS,
    _default_gap,
    _gray,
    _otsu,
    _photo_response,
    _resolve_kind,
    _stable_threshold,
)
from phloem.metrics import skeleton_agreement

# name: (repository, commit, description)
SOURCES = {
    "crackforest": ("cuilimeng/CrackForest-dataset", "ed57c2d", "118 road photos 480x320 (CFD)"),
    "deepcrack": ("jklimack/CrackSegmentation", "f7aac20", "DeepCrack's 237 test photos 544x384"),
    "crack500": (
        "zfsu3722/MTS-Based-Lightweight-Pavement-Crack-Detection-Model",
        "9e51319",
        "Crack500's 93 test photos 640x360",
    ),
    "drive": ("lixiang007666/My_Unet", "96138a3", "DRIVE's 40 fundus photos 565x584"),
    "chase": ("mipple1986/data", "92b9449", "CHASE_DB1's 28 fundus photos 999x960"),
}


def _git(repo: Path, *args: str) -> bytes:
    return subprocess.run(["git", "-C", str(repo), *args], check=True, capture_output=True).stdout


def _files(repo: Path, commit: str, folder: str) -> list[str]:
    return sorted(p for p in _git(repo, "ls-tree", "-r", "--name-only", commit, folder).decode().split("\n") if p)


def _image(data: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"), np.float32) / 255.0


def _mask(data: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(data)).convert("L")) > 127


def pairs(name: str, repo: Path) -> Iterator[tuple[str, np.ndarray, np.ndarray]]:
    """``(id, photo, drawn mask)`` of one dataset, read from its clone ``repo``."""
    commit = SOURCES[name][1]

    def show(path: str) -> bytes:
        return _git(repo, "show", f"{commit}:{path}")

    if name == "crackforest":
        for p in _files(repo, commit, "groundTruth/"):
            n = Path(p).stem
            seg = loadmat(io.BytesIO(show(p)))["groundTruth"][0, 0]["Segmentation"]
            yield n, _image(show(f"image/{n}.jpg")), seg == 2  # label 2 is crack
    elif name == "deepcrack":
        for p in _files(repo, commit, "DeepCrack/test_img/"):
            n = Path(p).stem
            yield n, _image(show(p)), _mask(show(f"DeepCrack/test_lab/{n}.png"))
    elif name == "crack500":
        for p in _files(repo, commit, "dataset/c5_640_360/test_img/"):
            n = Path(p).stem
            yield n, _image(show(p)), _mask(show(f"dataset/c5_640_360/test_lab/{n}_mask.png"))
    elif name == "drive":
        for split in ("training", "test"):
            for p in _files(repo, commit, f"DRIVE/{split}/images/"):
                n = Path(p).name.split("_")[0]
                yield f"{n}_{split}", _image(show(p)), _mask(show(f"DRIVE/{split}/1st_manual/{n}_manual1.gif"))
    elif name == "chase":
        for p in _files(repo, commit, "CHASEDB1/"):
            if p.endswith(".jpg"):
                yield Path(p).stem, _image(show(p)), _mask(show(p[:-4] + "_1stHO.png"))


MIN_AREA = inspect.signature(trace).parameters["min_area"].default


def thresholds(img: np.ndarray, valid: np.ndarray | None, *, default: bool) -> tuple[float, float, float]:
    """Otsu's threshold of the ridge response ``trace`` computes for ``img`` with its defaults,
    and with ``default`` the default threshold (the grain rule's) and its default gap (else NaN)."""
    gray = _gray(img, None)
    kind = _resolve_kind(gray, DEFAULT_SIGMAS)
    resp = _photo_response(gray, DEFAULT_SIGMAS, kind, valid)
    if not default:  # the grain rule's climb costs a few more masks; only the fractions need it
        return _otsu(resp), math.nan, math.nan
    t, climb, _ = _stable_threshold(resp, MIN_AREA)
    return _otsu(resp), t, _default_gap(DEFAULT_SIGMAS, kind) * climb


def variants(fractions: Sequence[float], kinds: Sequence[str]) -> list[str]:
    """The names of the traces scored per photo: the default, Otsu's threshold, then ``fractions``
    of the default threshold (with the default gap) and ``kinds`` forced."""
    return ["default", "Otsu's threshold", *(f"{f:g} x default threshold" for f in fractions)] + [
        f"kind={k}" for k in kinds
    ]


def score(
    img: np.ndarray, drawn: np.ndarray, fractions: Sequence[float] = (), kinds: Sequence[str] = ()
) -> list[tuple[float, float, float]] | None:
    """``(precision, recall, F1)`` of each of :func:`variants`' traces; None: nothing drawn."""
    try:
        truth = trace(drawn, kind="mask")
    except ValueError:  # an empty or all-structure mask
        return None
    ok = valid_region(img)
    valid = None if ok.all() else ok
    otsu, t, gap = thresholds(img, valid, default=bool(fractions))
    options: list[dict[str, Any]] = [{}, {"threshold": otsu}]
    options += [{"threshold": f * t, "gap": gap} for f in fractions]
    options += [{"kind": k} for k in kinds]
    out = []
    for opts in options:
        try:
            a = skeleton_agreement(truth, trace(img, valid=valid, **opts))
            out.append((a.precision, a.recall, a.f1))
        except ValueError:  # nothing traced
            out.append((0.0, 0.0, 0.0))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    for name, (repo, commit, what) in SOURCES.items():
        ap.add_argument(f"--{name}", type=Path, help=f"clone of github.com/{repo} (read at {commit}): {what}")
    ap.add_argument("--every", type=int, default=1, help="score every N-th pair (default 1: all)")
    ap.add_argument(
        "--fractions", type=float, nargs="+", default=[], help="also trace at these fractions of the default threshold"
    )
    ap.add_argument(
        "--kinds", choices=("bright", "dark"), nargs="+", default=[], help="also trace with this ridge polarity forced"
    )
    args = ap.parse_args()
    names = variants(args.fractions, args.kinds)
    print("| dataset | pairs | trace | P / R / F1 | F1 >= 0.8 | F1 vs the default's, +/- 0.05 |")
    print("|---|---|---|---|---|---|")
    for name in SOURCES:
        repo = getattr(args, name)
        if repo is None:
            continue
        rows = [
            s
            for i, (_, img, drawn) in enumerate(pairs(name, repo))
            if i % args.every == 0 and (s := score(img, drawn, args.fractions, args.kinds))
        ]
        if not rows:
            continue
        r = np.asarray(rows)  # (pairs, variants, [P, R, F1])
        for j, label in enumerate(names):
            m = r[:, j].mean(0)
            better = int((r[:, j, 2] > r[:, 0, 2] + 0.05).sum())
            worse = int((r[:, j, 2] < r[:, 0, 2] - 0.05).sum())
            print(
                f"| {name} | {len(r)} | {label} | {m[0]:.3f} / {m[1]:.3f} / {m[2]:.3f} "
                f"| {int((r[:, j, 2] >= 0.8).sum())} | {'' if j == 0 else f'+{better} / -{worse}'} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
