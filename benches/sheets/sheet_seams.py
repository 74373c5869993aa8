"""Contact sheet of the graph-cut jobs: look at it before trusting any number.

    python -m benches.sheets.sheet_seams out/seams_sheet.png

Quilting rows (bark, water, brick): exemplar | quilt with the Kwatra cost | its pieces
(each exemplar offset one colour, seams in red) | quilt with the gradient cost | randomly
placed blocks with straight cuts, for comparison. Seam rows: a disk-shaped fragment (b) laid
over existing content (a) as in Sibbing et al. §5.3: the overlap | the seam with the
Kwatra, gradient and Luo costs (a = dark, b = light, seam red) | the composite. Fragment
row (the whole §5.3 composition): a colour-shifted disk fragment pasted | cut along the seam |
plus Poisson correction | plus the paper's extra constraint (colours kept where the fragment
has no neighbour) | the interpolated displacement field of a bent skeleton, applied to a grid.
"""

from __future__ import annotations

import sys
import time
from dataclasses import astuple
from pathlib import Path

import numpy as np

import phloem
from phloem.seams import seam

from ._sheet import ROOT, TILE, _fit, _label, write_sheet


def _edges(labels: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """Pixels whose right or lower neighbour has another label (both inside ``valid``)."""
    ok = np.ones(labels.shape, bool) if valid is None else valid
    edge = np.zeros(labels.shape, bool)
    edge[:, 1:] |= (labels[:, 1:] != labels[:, :-1]) & ok[:, 1:] & ok[:, :-1]
    edge[1:, :] |= (labels[1:, :] != labels[:-1, :]) & ok[1:, :] & ok[:-1, :]
    return edge


def _pieces(src: np.ndarray) -> np.ndarray:
    yy, xx = np.mgrid[0 : src.shape[0], 0 : src.shape[1]]
    off = (src[..., 0] - yy) * 4096 + (src[..., 1] - xx)
    _, ids = np.unique(off, return_inverse=True)
    ids = ids.reshape(off.shape)
    rng = np.random.default_rng(0)
    colours = rng.uniform(0.25, 0.9, (ids.max() + 1, 3)).astype(np.float32)
    vis = colours[ids]
    vis[_edges(off)] = (1, 0, 0)
    return vis


def _seam_overlay(img: np.ndarray, labels: np.ndarray, valid: np.ndarray) -> np.ndarray:
    vis = img.copy()
    vis[_edges(labels, valid)] = (1, 0, 0)
    return vis


def _random_blocks(ex: np.ndarray, size: int, block: int) -> np.ndarray:
    rng = np.random.default_rng(1)
    out = np.zeros((size, size, 3), np.float32)
    for i in range(0, size, block):
        for j in range(0, size, block):
            ty, tx = rng.integers(0, ex.shape[0] - block), rng.integers(0, ex.shape[1] - block)
            piece = ex[ty : ty + block, tx : tx + block]
            out[i : i + block, j : j + block] = piece[: size - i, : size - j]
    return out


def _rgb3(img: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(np.repeat(img[..., None], 3, axis=2) if img.ndim == 2 else img[..., :3])


def quilt_row(name: str, ex: np.ndarray) -> list[np.ndarray]:
    ex = _rgb3(ex)
    t0 = time.perf_counter()
    out, src = astuple(phloem.texture.quilt(ex, 384, seed=1, full_output=True))
    dt = time.perf_counter() - t0
    grad = phloem.texture.quilt(ex, 384, seed=1, cost="gradient")
    rep = phloem.metrics.repetition(out)
    return [
        _label(_fit(ex), f"{name} exemplar {ex.shape[1]}x{ex.shape[0]}"),
        _label(_fit(out), f"quilt kwatra {dt:.2f}s rep {rep:.2f}"),
        _label(_fit(_pieces(src)), "pieces and seams"),
        _label(_fit(grad), "quilt gradient cost"),
        _label(_fit(_random_blocks(ex, 384, 64)), "random blocks, straight cuts"),
    ]


def _disk_scene(ex: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Old content left of column 100 (a) and a disk fragment's footprint (new), 160²."""
    yy, xx = np.mgrid[0:160, 0:160]
    old = xx < 100
    new = (yy - 80) ** 2 + (xx - 95) ** 2 < 60**2
    a = np.zeros((160, 160, 3), np.float32)
    a[old] = ex[:160, :160][old]
    return a, old, new


def seam_row(ex: np.ndarray) -> list[np.ndarray]:
    ex = _rgb3(ex)
    a, old, new = _disk_scene(ex)
    b = np.zeros_like(a)
    b[new] = ex[60:220, 90:250][new]
    region = old & new
    over = 0.35 * a + 0.65 * b
    over[~region] *= 0.4
    tiles = [_label(_fit(over), "overlap (bright) of a and disk b")]
    composites = {}
    for cost in ("kwatra", "gradient", "luo"):
        take_b = seam(a, b, region, a_mask=old, b_mask=new, cost=cost)
        composites[cost] = np.where(take_b[..., None], b, a)
        tiles.append(_label(_fit(_seam_overlay(composites[cost], take_b, old | new)), f"seam, {cost} cost"))
    tiles.append(_label(_fit(composites["gradient"]), "composite (gradient)"))
    return tiles


def fragment_row(ex: np.ndarray) -> list[np.ndarray]:
    ex = _rgb3(ex)
    a, old, new = _disk_scene(ex)
    h = w = 160
    yy, xx = np.mgrid[0:h, 0:w]
    src = np.clip(ex[60 : 60 + h, 90 : 90 + w] * np.float32([1.25, 1.1, 0.85]), 0, 1)  # the fragment's source
    b = np.zeros((h, w, 3), np.float32)
    b[new] = src[new]
    naive = np.where(new[..., None], b, a)
    take_b = seam(a, b, old & new, a_mask=old, b_mask=new, cost="gradient")
    cut = np.where(take_b[..., None], b, a)
    frag = take_b & new
    # Poisson: the fragment's gradients, the output's values around it (black where empty).
    plain = phloem.blend.seamless(src, cut, frag, (0, 0))
    # Sibbing §5.3: also keep the fragment's colours on its border where no old content is.
    pad = np.pad(frag, 1)
    border = frag & ~(pad[:-2, 1:-1] & pad[2:, 1:-1] & pad[1:-1, :-2] & pad[1:-1, 2:])
    near_old = np.zeros_like(old)
    near_old[:, 1:] |= old[:, :-1] & ~frag[:, :-1]
    near_old[:, :-1] |= old[:, 1:] & ~frag[:, 1:]
    near_old[1:] |= old[:-1] & ~frag[:-1]
    near_old[:-1] |= old[1:] & ~frag[1:]
    fixed = border & ~near_old
    kept = phloem.blend.seamless(src, cut, frag, (0, 0), fixed=fixed)
    # Displacement field: a straight skeleton bent into an arc; vectors at its points.
    region = (yy - 80) ** 2 + (xx - 80) ** 2 < 70**2
    ys = np.arange(20, 141, 10)
    pts = np.stack([ys, np.full_like(ys, 80)], 1)
    vec = np.stack([np.zeros(len(ys)), 18 * np.sin(np.pi * (ys - 20) / 120)], 1)
    field = phloem.blend.interpolate_field(region, pts, vec)
    grid = np.full((h, w, 3), 0.9, np.float32)
    grid[(yy % 12 == 0) | (xx % 12 == 0)] = 0.2
    import cv2

    mx = (xx - np.nan_to_num(field[..., 1])).astype(np.float32)
    my = (yy - np.nan_to_num(field[..., 0])).astype(np.float32)
    warped = cv2.remap(grid, mx, my, cv2.INTER_LINEAR)
    warped[~region] *= 0.5
    for y, x in pts:
        cv2.circle(warped, (int(x + 18 * np.sin(np.pi * (y - 20) / 120)), int(y)), 2, (1, 0, 0), -1)
    return [
        _label(_fit(naive), "fragment pasted (colour-shifted)"),
        _label(_fit(cut), "cut along the gradient seam"),
        _label(_fit(plain), "+ Poisson (empty output = black)"),
        _label(_fit(kept), "+ colours kept on free border"),
        _label(_fit(warped), "displacement field on a grid"),
    ]


def main(out: Path) -> None:
    water = phloem.io.read_image(ROOT / "tests" / "data" / "water.jpg")
    rows = [
        quilt_row("bark", phloem.data.bark()),
        quilt_row("water", water),
        quilt_row("brick", phloem.data.brick()),
        seam_row(phloem.data.bark()),
        fragment_row(phloem.data.bark()),
    ]
    sheet = write_sheet(rows, out)
    print(f"wrote {out} ({sheet.shape[1]}x{sheet.shape[0]}); tile {TILE}px")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/seams_sheet.png"))
