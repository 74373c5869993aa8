"""Contact sheet of fragment-based image synthesis (Sibbing et al. 2010 §5): look before trusting numbers.

    python -m benches.sheets.sheet_branching_image --out out/branching_image_sheet.png

Each row: input | input with the source skeleton (red) and its fragment disks (yellow) |
target skeleton | structure synthesis (§5.1–5.3, gaps black) | final image with the gaps
completed (§5.4) | fragment placement map (one colour per target fragment, white = completed).
Rows: a synthetic river (drawn from a known skeleton) re-rendered along a new skeleton;
the same with every §5.3 stage switched off (plain rigid copy); a grey vessel picture along a
rotated, bent skeleton; identity (target = source); the river along a target grown by
phloem.branching.grow from models learnt on its source skeleton (§4 then §5); when ../shared/data is there, one real
channel of the Colville delta water mask painted along its 180°-turned copy; Fig. 8: the river
photographed at a slant (a synthetic homography), rectified, synthesised frontally along the
river target and distorted back. Last row: 2×
crops around two furcations of the river: full pipeline (with the target skeleton), full
pipeline, and without §5.3.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import cv2
import numpy as np

import phloem
from phloem.branching import (
    BendingModel,
    Branch,
    FurcationModel,
    RenderResult,
    Skeleton,
    fragments,
    grow,
    rectify,
    render,
    unrectify,
)
from phloem.testing import channel_scene as _scene
from phloem.testing import longest_path as _longest_path
from phloem.testing import river_picture as picture
from phloem.testing import river_skeleton as tree
from phloem.testing import shared_path
from phloem.testing import wavy_branch as _wavy

from ._sheet import _fit, _label, _rgb, write_sheet


def _disks(img: np.ndarray, sk: Skeleton) -> np.ndarray:
    out = sk.draw(img, width=2)
    for f in fragments(img, sk):
        col = (1.0, 1.0, 0.0) if not f.furcation else (0.0, 1.0, 1.0)
        cv2.circle(
            out,
            (round(f.center[0] * 16), round(f.center[1] * 16)),
            round(f.radius * 16),
            col,
            1,
            cv2.LINE_AA,
            shift=4,
        )
    return out


def _labels(lab: np.ndarray) -> np.ndarray:
    rng = np.random.default_rng(0)
    pal = rng.uniform(0.2, 1.0, size=(int(lab.max()) + 2, 3)).astype(np.float32)
    vis = pal[np.maximum(lab, 0)]
    vis[lab < 0] = 1.0
    edge = cv2.morphologyEx(lab.astype(np.float32), cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8)) > 0
    vis[edge] = 0.0
    return vis


def row(
    name: str, img: np.ndarray, src: Skeleton, tgt: Skeleton, keep: list[RenderResult] | None = None, **kw: Any
) -> list[np.ndarray]:
    t0 = time.perf_counter()
    res = render(img, src, tgt, seed=0, full_output=True, **kw)
    dt = time.perf_counter() - t0
    print(f"{name}: {len(res.targets)} target fragments from {len(res.sources)}, {dt:.2f} s")
    if keep is not None:
        keep.append(res)
    return [
        _label(_fit(img), f"{name}: input"),
        _label(_fit(_disks(_rgb(img), src)), "source skeleton + fragments"),
        _label(_fit(tgt.draw(size=tgt.shape, width=2)), "target skeleton"),
        _label(_fit(_rgb(res.structure)), "structure (5.1-5.3)"),
        _label(_fit(_rgb(res.image)), f"output, {dt:.1f} s"),
        _label(_fit(_labels(res.labels)), "fragment map"),
    ]


def vessels() -> tuple[np.ndarray, Skeleton, Skeleton]:
    img, sk = _scene()
    main = _wavy((20, 20), 0.5, 200, (4.0, 3.0), phase=3.0, amp=0.4)
    child = _wavy(tuple(main.points[40]), -0.6, 50, (3.0, 2.0), parent=(0, 40))
    return img, sk, Skeleton([main, child], (160, 200))


def colville() -> tuple[np.ndarray, Skeleton, Skeleton] | None:
    """The Colville delta water mask (RivGraph, ../shared/data; never committed): one channel
    traced automatically (as in the shared test), painted along its 180°-turned copy."""
    path = shared_path("branching", "rivgraph_colville_delta_mask.png")
    if not path.exists():
        return None
    m = phloem.io.read_image(path)
    water = (m[..., 0] if m.ndim == 3 else m) > 0.5
    y0, y1, x0, x1 = 540, 1000, 280, 420
    _, lab, stats, _ = cv2.connectedComponentsWithStats(water[y0:y1, x0:x1].astype(np.uint8), connectivity=8)
    big = lab == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    pts = _longest_path(big)[::6]
    thick = cv2.distanceTransform(big.astype(np.uint8), cv2.DIST_L2, 5)[pts[:, 0].astype(int), pts[:, 1].astype(int)]
    xy = pts[:, ::-1] + [x0, y0]
    crop = (slice(400, 1150), slice(100, 700))
    off = np.array([100.0, 400.0])
    src = Skeleton([Branch(xy - off, thick)], (750, 600))
    tgt = Skeleton([Branch(2 * xy.mean(axis=0) - xy - off, thick)], (750, 600))
    return np.ascontiguousarray(m[crop]), src, tgt


def _persp(Hm: np.ndarray, pts: np.ndarray) -> np.ndarray:
    q = np.c_[pts, np.ones(len(pts))] @ Hm.T
    return q[:, :2] / q[:, 2:]


def tgt_like(frame: Skeleton, tgt: Skeleton) -> Skeleton:
    """The target skeleton scaled into the rectified frame."""
    assert frame.shape is not None and tgt.shape is not None
    sy, sx = frame.shape[0] / tgt.shape[0], frame.shape[1] / tgt.shape[1]
    return Skeleton([Branch(b.points * [sx, sy], b.thickness, b.parent) for b in tgt.branches], frame.shape)


def _zoom(a: np.ndarray, crop: tuple[slice, slice]) -> np.ndarray:
    return cv2.resize(np.ascontiguousarray(a[crop]), (256, 256), interpolation=cv2.INTER_NEAREST)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="out/branching_image_sheet.png")
    args = ap.parse_args()
    src = tree((300, 500), seed=1)
    img = picture(src, seed=1)
    tgt = tree((340, 560), seed=5, children=3, heading=-0.1, amp=0.35)
    vimg, vsrc, vtgt = vessels()
    kept: list[RenderResult] = []
    rows = [
        row("river", img, src, tgt, kept),
        row("river, no 5.3", img, src, tgt, kept, deform=False, photometric=False, seams=False),
        row("vessels", vimg, vsrc, vtgt),
        row("identity", img, src, src),
    ]
    # The whole §4 + §5 pipeline: models learnt from the source skeleton grow the target.
    grown = grow(BendingModel.fit(src), FurcationModel.fit(src), size=(320, 560), seed=3, generations=2)
    rows.append(row("river, grown target", img, src, grown))
    # Fig. 8: a slanted view of the river, rectified, synthesised frontally, distorted back.
    h, w = src.shape  # type: ignore[misc]
    quad = np.float32([[0, 0], [w, 0], [w, h], [0, h]])
    tilt = cv2.getPerspectiveTransform(quad, np.float32([[90, 0], [w - 90, 0], [w, h], [0, h]]))
    slanted = cv2.warpPerspective(img, tilt, (w, h))
    ssk = Skeleton([Branch(_persp(tilt, b.points), b.thickness, b.parent) for b in src.branches], (h, w))
    rect, rsk, Hm, valid = rectify(slanted, ssk, np.linalg.inv(tilt))
    t0 = time.perf_counter()
    out = render(rect, rsk, tgt_like(rsk, tgt), seed=0, valid=valid)
    dt = time.perf_counter() - t0
    rows.append(
        [
            _label(_fit(slanted), "Fig. 8: slanted input"),
            _label(_fit(_disks(rect, rsk)), "rectified + skeleton"),
            _label(_fit(out), f"synthesised frontally, {dt:.1f} s"),
            _label(_fit(unrectify(out, Hm, (h, w))), "distorted back"),
            _fit(np.ones((8, 8, 3), np.float32)),
            _fit(np.ones((8, 8, 3), np.float32)),
        ]
    )
    real = colville()
    if real is not None:
        rows.append(row("Colville channel", *real))
    # 2x crops around the first furcations: seams and junctions are invisible at sheet scale.
    full, plain = kept
    tiles = []
    for g in [g for g in full.targets if g.furcation][:2]:
        y0, x0 = max(0, int(g.center[1]) - 64), max(0, int(g.center[0]) - 64)
        crop = (slice(y0, y0 + 128), slice(x0, x0 + 128))
        tiles += [
            _label(_zoom(tgt.draw(full.image), crop), "zoom x2: output + skeleton"),
            _label(_zoom(full.image, crop), "zoom x2: output"),
            _label(_zoom(plain.image, crop), "zoom x2: no 5.3"),
        ]
    rows.append(tiles)
    write_sheet(rows, args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
