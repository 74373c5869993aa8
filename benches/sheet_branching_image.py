"""Contact sheet of fragment-based image synthesis (Sibbing et al. 2010 §5): look before trusting numbers.

    python benches/sheet_branching_image.py --out out/branching_image_sheet.png

Each row: input | input with the source skeleton (red) and its fragment disks (yellow) |
target skeleton | structure synthesis (§5.1–5.3, gaps black) | final image with the gaps
completed (§5.4) | fragment placement map (one colour per target fragment, white = completed).
Rows: a synthetic river (drawn from a known skeleton) re-rendered along a new skeleton;
the same with every §5.3 stage switched off (plain rigid copy); a grey vessel picture along a
rotated, bent skeleton; identity (target = source).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from branching_scene import picture, tree
from phloem.branching import Skeleton, fragments, render
from sheet_texture import _fit, _label, write_sheet


def _rgb(img: np.ndarray) -> np.ndarray:
    img = img[..., :3] if img.ndim == 3 else img[..., None]
    return np.repeat(img, 3, axis=2) if img.shape[2] == 1 else img


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


def row(name: str, img: np.ndarray, src: Skeleton, tgt: Skeleton, **kw: object) -> list[np.ndarray]:
    t0 = time.perf_counter()
    res = render(img, src, tgt, seed=0, full_output=True, **kw)  # type: ignore[call-overload]
    dt = time.perf_counter() - t0
    print(f"{name}: {len(res.targets)} target fragments from {len(res.sources)}, {dt:.2f} s")
    return [
        _label(_fit(img), f"{name}: input"),
        _label(_fit(_disks(_rgb(img), src)), "source skeleton + fragments"),
        _label(_fit(tgt.draw(shape=tgt.shape, width=2)), "target skeleton"),
        _label(_fit(_rgb(res.structure)), "structure (5.1-5.3)"),
        _label(_fit(_rgb(res.image)), f"output, {dt:.1f} s"),
        _label(_fit(_labels(res.labels)), "fragment map"),
    ]


def vessels() -> tuple[np.ndarray, Skeleton, Skeleton]:
    sys.path.insert(0, str(Path(__file__).parents[1] / "tests"))
    from test_branching_image import _scene, _wavy

    img, sk = _scene()
    main = _wavy((20, 20), 0.5, 200, (4.0, 3.0), phase=3.0, amp=0.4)
    child = _wavy(tuple(main.points[40]), -0.6, 50, (3.0, 2.0), parent=(0, 40))
    return img, sk, Skeleton([main, child], (160, 200))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="out/branching_image_sheet.png")
    args = ap.parse_args()
    src = tree((300, 500), seed=1)
    img = picture(src, seed=1)
    tgt = tree((340, 560), seed=5, children=3, heading=-0.1, amp=0.35)
    vimg, vsrc, vtgt = vessels()
    rows = [
        row("river", img, src, tgt),
        row("river, no 5.3", img, src, tgt, deform=False, photometric=False, seams=False),
        row("vessels", vimg, vsrc, vtgt),
        row("identity", img, src, src),
    ]
    write_sheet(rows, args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
