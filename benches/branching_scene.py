"""Synthetic branching scenes with a known skeleton, for the image-synthesis bench and sheet.

A river-like picture: textured green-brown land (smooth plus fine noise) and a darker blue
channel drawn along the skeleton with its thickness and soft banks. Because the picture is
drawn from the skeleton, the skeleton is exact, which no hand tracing of a photo gives.
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from phloem.branching import Branch, Skeleton

# The real examples of ../shared/data/branching -> the trace() arguments that suit them.
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


def tree(
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


def picture(skeleton: Skeleton, *, seed: int = 0) -> np.ndarray:
    """Draw the river picture (float32 RGB in [0, 1]) of a skeleton."""
    assert skeleton.shape is not None
    h, w = skeleton.shape
    rng = np.random.default_rng(seed)
    smooth = cv2.GaussianBlur(rng.normal(size=(h, w)).astype(np.float32), (0, 0), 12)
    smooth /= smooth.std() + 1e-6
    fine = cv2.GaussianBlur(rng.normal(size=(h, w)).astype(np.float32), (0, 0), 1.2)
    fine /= fine.std() + 1e-6
    land = np.stack(
        [0.45 + 0.06 * smooth + 0.04 * fine, 0.52 + 0.05 * smooth + 0.04 * fine, 0.30 + 0.03 * smooth + 0.03 * fine], -1
    )
    water = np.zeros((h, w), np.float32)
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
    return np.clip(land * (1 - water) + river * water, 0, 1).astype(np.float32)
