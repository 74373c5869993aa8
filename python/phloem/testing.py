"""Helpers for phloem's own tests and benchmarks (and for users who test code built on phloem).

Real images
    ``shared_data`` and ``shared_path`` find the project's optional real-image collection, whose
    folder is ``$PHLOEM_SHARED_DATA`` or else ``shared/data`` beside the source checkout that
    phloem is imported from or that the working directory is in; ``shared_file`` gives one of its files or skips the
    calling test when it is absent, as it is in CI.

Synthetic branching scenes with a known skeleton
    ``meander``, ``river_skeleton`` and ``river_picture`` draw a river-like picture along a
    skeleton (so the skeleton is exact, which no hand tracing of a photo gives);
    ``wavy_branch`` and ``channel_scene`` a small grey picture with a dark channel;
    ``longest_path`` the longest path of a mask's skeleton; ``input_halves`` a skeleton split in
    two, whose histogram distance is the spread the growth is judged by; ``TRACE_SETTINGS`` the
    ``branching.trace`` arguments that suit the collection's branching examples.

Synthetic leaves with known layers
    ``layered_leaf`` draws an RGBA leaf with veins, spots and blade at known pixels (its label
    map is exact), in variants that differ as leaves of one species do; ``scribbles_from`` marks
    a few short strokes of each layer, as a user would.

Everything here is imported with ``phloem`` already loaded; pytest is imported only by ``shared_file``.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from .branching import Branch, Skeleton

__all__ = [
    "TRACE_SETTINGS",
    "channel_scene",
    "input_halves",
    "layered_leaf",
    "longest_path",
    "meander",
    "river_picture",
    "river_skeleton",
    "scribbles_from",
    "shared_data",
    "shared_file",
    "shared_path",
    "wavy_branch",
]


def _beside_checkout() -> Path | None:
    """``shared/data`` beside the phloem checkout this module or the working directory is in."""
    here = Path(__file__).resolve().parents[2]  # python/phloem/testing.py -> the checkout
    cwd = Path.cwd().resolve()
    for root in (here, cwd, *cwd.parents):
        if (root / "pyproject.toml").is_file() and (root / "python" / "phloem").is_dir():
            p = root.parent / "shared" / "data"
            if p.is_dir():
                return p
    return None


def shared_data() -> Path | None:
    """The folder of the optional real-image collection, or None when it is not there."""
    root = os.environ.get("PHLOEM_SHARED_DATA")
    if not root:
        return _beside_checkout()
    p = Path(root)
    return p if p.is_dir() else None


def shared_path(*parts: str) -> Path:
    """The path of a file or folder of the real-image collection, which may not exist (for scripts
    that check ``.exists()`` and skip what is missing)."""
    return (shared_data() or Path("<PHLOEM_SHARED_DATA unset>")).joinpath(*parts)


def shared_file(*parts: str) -> Path:
    """A file of the real-image collection, or skip the running test when it is not available."""
    import pytest

    p = shared_path(*parts)
    if not p.exists():
        pytest.skip(f"{p} is not available")
    return p


# The collection's branching examples (shared_path("branching", name)) -> the trace() arguments that suit them.
TRACE_SETTINGS: dict[str, dict[str, Any]] = {
    "skimage_retina.jpg": {"kind": "dark", "channel": 1, "sigmas": (1.5, 3.0, 5.0)},
    "rivgraph_colville_delta_mask.png": {"kind": "mask"},
    "rivgraph_brahmaputra_braided_mask.png": {"kind": "mask"},
    "rivgraph_mouse_brain_vessels.png": {"kind": "dark", "sigmas": (1.5, 3.0, 5.0)},
    "mpl_jacksboro_fault_dem_u16.png": {"kind": "bright", "sigmas": (3.0, 6.0)},
    "skimage_microaneurysms.png": {"kind": "dark", "sigmas": (1.5, 3.0)},
}


def meander(
    start: tuple[float, float],
    heading: float,
    length: float,
    thickness: tuple[float, float],
    *,
    amp: float = 0.25,
    wavelength: float = 200.0,
    phase: float = 0.0,
    step: float = 4.0,
    parent: tuple[int, int] | None = None,
) -> Branch:
    """A sinuous polyline: the heading oscillates by ``amp`` radians with the given wavelength."""
    n = max(2, int(length / step) + 1)
    s = np.arange(n) * step
    head = heading + amp * np.sin(2 * math.pi * s / wavelength + phase)
    d = np.stack([np.cos(head), np.sin(head)], axis=1) * step
    pts = np.vstack([[start], start + np.cumsum(d[:-1], axis=0)])
    return Branch(pts, np.linspace(thickness[0], thickness[1], n), parent)


def river_skeleton(
    shape: tuple[int, int],
    *,
    scale: float = 1.0,
    seed: int = 0,
    children: int = 2,
    heading: float = 0.05,
    amp: float = 0.25,
) -> Skeleton:
    """A main branch across the image with ``children`` sub-branches, sized by ``scale``."""
    rng = np.random.default_rng(seed)
    h, w = shape
    main = meander(
        (0.04 * w, 0.45 * h),
        heading,
        0.9 * w,
        (7 * scale, 5 * scale),
        amp=amp,
        wavelength=220 * scale,
        phase=float(rng.uniform(0, 6)),
        step=4 * scale,
    )
    branches = [main]
    for c in range(children):
        v = int(len(main) * (0.3 + 0.4 * c / max(children - 1, 1)))
        side = 1 if c % 2 == 0 else -1
        hd = math.atan2(*(main.points[v + 1] - main.points[v])[::-1]) + side * float(rng.uniform(0.6, 0.9))
        b = meander(
            tuple(main.points[v]),
            hd,
            0.35 * min(h, w) / max(abs(math.sin(hd)), 0.5),
            (4 * scale, 2.5 * scale),
            amp=amp,
            wavelength=160 * scale,
            phase=float(rng.uniform(0, 6)),
            step=4 * scale,
            parent=(0, v),
        )
        pts = b.points
        inside = (pts[:, 0] > 2) & (pts[:, 0] < w - 3) & (pts[:, 1] > 2) & (pts[:, 1] < h - 3)
        n = int(np.argmin(inside)) if not inside.all() else len(pts)
        if n >= 3:
            branches.append(Branch(pts[:n], b.thickness[:n], (0, v)))
    return Skeleton(branches, shape)


def river_picture(skeleton: Skeleton, *, seed: int = 0) -> np.ndarray:
    """The river picture (float32 RGB in [0, 1]) of a skeleton: textured green-brown land and a
    darker blue channel drawn along the skeleton with its thickness and soft banks."""
    assert skeleton.shape is not None
    h, w = skeleton.shape
    rng = np.random.default_rng(seed)
    smooth: np.ndarray = cv2.GaussianBlur(rng.normal(size=(h, w)).astype(np.float32), (0, 0), 12)
    smooth /= smooth.std() + 1e-6
    fine: np.ndarray = cv2.GaussianBlur(rng.normal(size=(h, w)).astype(np.float32), (0, 0), 1.2)
    fine /= fine.std() + 1e-6
    land = np.stack(
        [0.45 + 0.06 * smooth + 0.04 * fine, 0.52 + 0.05 * smooth + 0.04 * fine, 0.30 + 0.03 * smooth + 0.03 * fine], -1
    )
    water: np.ndarray = np.zeros((h, w), np.float32)
    for b in skeleton.branches:
        for (p, q), (r0, r1) in zip(zip(b.points[:-1], b.points[1:]), zip(b.thickness[:-1], b.thickness[1:])):
            r = 0.5 * (r0 + r1)
            cv2.line(
                water,
                tuple(round(v * 16) for v in p),
                tuple(round(v * 16) for v in q),
                1.0,
                thickness=max(1, round(2 * r)),
                lineType=cv2.LINE_AA,
                shift=4,
            )
    water = cv2.GaussianBlur(water, (0, 0), 1.5)[..., None]
    river = np.stack([0.10 + 0.02 * fine, 0.18 + 0.03 * fine, 0.35 + 0.04 * smooth], -1)
    # A lighter sandy bank just outside the water.
    bank = np.clip(cv2.GaussianBlur(water[..., 0], (0, 0), 4) * 2 - water[..., 0] * 2, 0, 1)[..., None]
    land = land * (1 - 0.6 * bank) + np.array([0.75, 0.70, 0.55], np.float32) * 0.6 * bank
    out: np.ndarray = np.clip(land * (1 - water) + river * water, 0, 1).astype(np.float32)
    return out


def wavy_branch(
    start: tuple[float, float],
    heading: float,
    length: float,
    r: tuple[float, float],
    *,
    phase: float = 0.0,
    amp: float = 0.3,
    parent: tuple[int, int] | None = None,
) -> Branch:
    """A branch of points 3 px apart whose heading oscillates by ``amp`` with a 90 px wavelength."""
    return meander(start, heading, length, r, amp=amp, wavelength=90.0, phase=phase, step=3.0, parent=parent)


def channel_scene(seed: int = 0) -> tuple[np.ndarray, Skeleton]:
    """A grey textured picture (128, 224) with a dark branching channel drawn along a known skeleton."""
    rng = np.random.default_rng(seed)
    main = wavy_branch((8, 60), 0.05, 210, (4.0, 3.0), phase=1.0)
    child = wavy_branch(tuple(main.points[30]), 0.9, 60, (3.0, 2.0), phase=0.0, amp=0.2, parent=(0, 30))
    sk = Skeleton([main, child], (128, 224))
    img = 0.7 + 0.05 * cv2.GaussianBlur(rng.normal(size=sk.shape).astype(np.float32), (0, 0), 1.0) / 0.2
    return np.clip(np.where(sk.mask(), 0.15 + 0.03 * img, img), 0, 1).astype(np.float32), sk


def longest_path(mask: np.ndarray) -> np.ndarray:
    """(row, col) pixels of the longest path of the skeleton of a mask (two breadth-first sweeps)."""
    from collections import deque

    from skimage.morphology import skeletonize

    pts = {(int(y), int(x)) for y, x in np.argwhere(skeletonize(mask))}  # type: ignore[no-untyped-call]

    def sweep(start: tuple[int, int]) -> tuple[tuple[int, int], dict[tuple[int, int], tuple[int, int] | None]]:
        prev: dict[tuple[int, int], tuple[int, int] | None] = {start: None}
        q, last = deque([start]), start
        while q:
            last = u = q.popleft()
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    v = (u[0] + dy, u[1] + dx)
                    if v in pts and v not in prev:
                        prev[v] = u
                        q.append(v)
        return last, prev

    a, _ = sweep(min(pts))
    b, prev = sweep(a)
    path = [b]
    while (p := prev[path[-1]]) is not None:
        path.append(p)
    return np.array(path[::-1], float)


def input_halves(skeleton: Skeleton) -> list[Skeleton]:
    """A skeleton (e.g. a bending model's resampled ``source``) split in two: alternate trees, or
    alternate branches for fewer than 4 trees; branches under 3 vertices (no angle) are left out.
    The histogram distance between the halves is the sampling spread an output's distance to the
    input is measured against."""
    tree: list[int] = []
    for i, b in enumerate(skeleton.branches):
        tree.append(i if b.parent is None else tree[b.parent[0]])
    rank = {r: j for j, r in enumerate(sorted(set(tree)))}
    key = [rank[t] for t in tree] if len(rank) >= 4 else list(range(len(tree)))
    return [
        Skeleton(
            [Branch(b.points, b.thickness) for i, b in enumerate(skeleton.branches) if key[i] % 2 == j and len(b) >= 3]
        )
        for j in (0, 1)
    ]


#: Colours of :func:`layered_leaf`: veins, spots, blade (RGB in [0, 1]).
LEAF_COLORS = ((0.72, 0.78, 0.38), (0.45, 0.28, 0.12), (0.16, 0.42, 0.12))


def layered_leaf(
    size: tuple[int, int] = (160, 96), *, variant: int = 0, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """An RGBA leaf with three layers and its label map (1 veins, 2 spots, 3 blade, 0 off the leaf).

    The blade is an ellipse with a petiole; the veins a midrib and four pairs of side veins
    (3 px wide); the spots five small brown disks; the colours carry a little noise. Each
    ``variant`` changes the blade's width and length, the side veins' angles and the spots'
    places, as leaves of one species differ; ``seed`` the noise.
    """
    h, w = size
    rng = np.random.default_rng([variant, 7])
    noise = np.random.default_rng(seed)
    labels = np.zeros((h, w), np.uint8)
    cx, cy = w // 2, int(h * 0.45)
    ax, ay = int(w * (0.36 + 0.04 * rng.uniform(-1, 1))), int(h * (0.38 + 0.03 * rng.uniform(-1, 1)))
    cv2.ellipse(labels, (cx, cy), (ax, ay), 0, 0, 360, 3, -1)
    cv2.line(labels, (cx, cy + ay - 2), (cx, min(h - 3, cy + ay + h // 10)), 1, 3)  # petiole, vein-coloured
    cv2.line(labels, (cx, cy - ay + 4), (cx, cy + ay - 2), 1, 3)
    for j in range(4):
        y = cy - ay // 2 + j * ay // 3
        ang = math.radians(35 + 8 * rng.uniform(-1, 1))
        for side in (-1, 1):
            end = (int(cx + side * ax * 0.8), int(y - ax * 0.8 * math.tan(ang)))
            cv2.line(labels, (cx, y), end, 1, 3)
    inside = np.argwhere(labels == 3)
    for y, x in inside[rng.choice(len(inside), 5, replace=False)]:
        cv2.circle(labels, (int(x), int(y)), 4, 2, -1)
    labels[(labels == 2) & (cv2.erode((labels > 0).astype(np.uint8), np.ones((5, 5), np.uint8)) == 0)] = 3
    img = np.zeros((h, w, 4), np.float32)
    for k, c in enumerate(LEAF_COLORS, start=1):
        img[labels == k, :3] = c
    img[..., :3] += noise.normal(0.0, 0.02, (h, w, 3)).astype(np.float32)
    img[..., 3] = labels > 0
    return np.clip(img, 0.0, 1.0), labels.astype(np.int32)


def scribbles_from(labels: np.ndarray, *, strokes: int = 6, seed: int = 0) -> np.ndarray:
    """A few short strokes inside each layer of a label map: short segments of 5 px between
    random pixels of the layer's interior, labelled as the layer (0 elsewhere)."""
    rng = np.random.default_rng(seed)
    out = np.zeros(labels.shape, np.int32)
    for k in range(1, int(labels.max()) + 1):
        core = cv2.erode((labels == k).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        pts = np.argwhere(core if core.any() else labels == k)
        for y, x in pts[rng.choice(len(pts), min(strokes, len(pts)), replace=False)]:
            y2, x2 = pts[
                int(np.argmin(np.abs(pts - (y, x)).sum(axis=1) + 1000 * (np.abs(pts - (y, x)).sum(axis=1) < 4)))
            ]
            seg = np.zeros(labels.shape, np.uint8)
            cv2.line(seg, (int(x), int(y)), (int(x2), int(y2)), 1, 1)
            out[(seg > 0) & (labels == k)] = k
    return out
