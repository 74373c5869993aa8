"""How much of the leaves pipeline's vein layer is veins, and what induction makes of it (issue 17).

    PYTHONPATH=python PHLOEM_SHARED_DATA=../shared/data python -m benches.quality.leaves_veins [--scribbles PNG]

Analyses the contact sheet's leaf set (``benches.sheets.sheet_leaves``: the committed scribbles
on leaf 0 of ``leafarea_A300-1``, three more leaves of the species) and prints:

- per expanded layer on the training leaf: its share of the leaf, the share of it that lies on
  a main vein (within 2.5 px of the reference below) and the share of the reference it covers
  (within 2 px);
- per induced layer: λ, δ, the Eq. 4 objective, and on each exemplar the IoU of the induced
  layer with the training leaf's layer (the leaves are aligned) and its share on the
  exemplar's own main-vein reference;
- the midrib alone: the vein layer within 10 px of the line fitted to the midrib strokes,
  induced the same way (its λ, objective and IoUs).

The main-vein reference (defined here, not part of the pipeline): on CIELAB L* of the leaf,
the ridge filter of ``phloem.branching.trace`` at scales 1, 1.5 and 2 px, dark and bright
lines above the 96th percentile of the leaf, thinned to their skeleton, components of at least
50 px kept, 8 px away from the margin. It finds the midrib and the strong lateral veins, and
misses the faint ones, so the on-vein shares are lower bounds. Needs the shared scans.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy import ndimage  # type: ignore[import-untyped]
from skimage.morphology import skeletonize

from benches.sheets.sheet_leaves import DEFAULT, SCRIBBLES, SHARED, _leaf
from phloem import leaves
from phloem._ridges import ridge_response
from phloem.leaves.color import _lab


def main_veins(rgba: np.ndarray) -> np.ndarray:
    """The main-vein reference of a leaf (module docstring), a skeleton mask."""
    leaf = rgba[..., 3] > 0.5
    lightness = np.ascontiguousarray(_lab(np.ascontiguousarray(rgba, dtype=np.float32))[..., 0])
    inner = ndimage.distance_transform_edt(leaf) > 8
    out = np.zeros(leaf.shape, bool)
    for polarity in ("dark", "bright"):
        r = ridge_response(lightness, (1.0, 1.5, 2.0), polarity)
        skel = skeletonize((r > np.percentile(r[leaf], 96)) & inner)
        lab, _ = ndimage.label(skel, np.ones((3, 3)))
        keep = np.bincount(lab.ravel()) >= 50
        keep[0] = False
        out |= keep[lab]
    return out


def on_veins(layer: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """(share of ``layer`` within 2.5 px of ``ref``, share of ``ref`` within 2 px of ``layer``)."""
    if not layer.any():
        return 0.0, 0.0
    d_ref = ndimage.distance_transform_edt(~ref)
    d_lay = ndimage.distance_transform_edt(~layer)
    return float((d_ref[layer] <= 2.5).mean()), float((d_lay[ref] <= 2.0).mean())


def iou(a: np.ndarray, b: np.ndarray) -> float:
    u = int((a | b).sum())
    return int((a & b).sum()) / u if u else 0.0


def midrib(vein: np.ndarray, strokes: np.ndarray, leaf: np.ndarray) -> np.ndarray:
    """The vein layer within 10 px of the line fitted to the vein strokes on the leaf's long axis."""
    ys, xs = np.nonzero(leaf)
    centre = np.array([xs.mean(), ys.mean()])
    axis = np.linalg.eigh(np.cov(np.stack([xs - centre[0], ys - centre[1]])))[1][:, 1]
    normal = np.array([-axis[1], axis[0]])
    comp, k = ndimage.label(strokes, np.ones((3, 3)))
    on_axis = np.zeros_like(strokes)
    for j in range(1, k + 1):
        yy, xx = np.nonzero(comp == j)
        if np.abs((np.stack([xx, yy], 1) - centre) @ normal).mean() < 20:
            on_axis |= comp == j
    yy, xx = np.nonzero(on_axis)
    t = (np.stack([xx, yy], 1) - centre) @ axis
    poly = np.polyfit(t, (np.stack([xx, yy], 1) - centre) @ normal, 2)  # a slightly bent midrib
    gy, gx = np.mgrid[: leaf.shape[0], : leaf.shape[1]]
    p = np.stack([gx - centre[0], gy - centre[1]], -1)
    off = p @ normal - np.polyval(poly, p @ axis)
    return vein & (np.abs(off) <= 10)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--scribbles", type=Path, default=SCRIBBLES, help="strokes on the training leaf (default: committed)"
    )
    args = ap.parse_args()
    if not SHARED.is_dir():
        sys.exit(f"leaves_veins: {SHARED} is absent; this measure needs the shared leaf scans")
    exemplars = [_leaf(s) for s in DEFAULT]
    model = leaves.analyze(exemplars, args.scribbles, seed=0)
    t = model.training
    train = model.aligned[t]
    leaf = train[..., 3] > 0.5
    refs = [main_veins(a) for a in model.aligned]
    names = {0: "veins", 1: "trails"}
    for k in range(len(model.order) - 1):
        user = model.masks[t][k]
        prec, rec = on_veins(user, refs[t])
        print(
            f"{names.get(k, k)}: expanded share {user.sum() / leaf.sum():.3f} ({int(user.sum())} px), "
            f"on main veins {prec:.3f}, main-vein recall {rec:.3f}"
        )
        print(f"  lambda {model.lam[k]:.3f} delta {model.delta[k]:.3f} objective {model.objective[k]:.3f}")
        for i in range(model.n_exemplars):
            if i != t:
                p_i, _ = on_veins(model.masks[i][k], refs[i])
                print(
                    f"  exemplar {i}: IoU with training layer {iou(model.masks[i][k], user):.3f}, on its main veins {p_i:.3f}"
                )
    # The midrib alone, induced on the leaves as analysis induces the vein layer (first layer).
    from phloem.leaves.scribbles import read_scribbles

    labels, _ = read_scribbles(args.scribbles, exemplars[0].shape)
    canvas = np.zeros(leaf.shape, bool)
    ys, xs = np.nonzero(model.leaves[t][..., 3] > 0.5)
    rows, cols = np.nonzero(exemplars[0][..., 3] > 0.5)
    dy, dx = int(ys.min() - rows.min()), int(xs.min() - cols.min())
    canvas[dy : dy + labels.shape[0], dx : dx + labels.shape[1]] = labels == model.order[0]
    rib = midrib(model.masks[t][0], canvas & leaf, leaf)
    ind = leaves.induce(train, rib, model.aligned, epsilon=40.0, kappa=model.kappa, seed=0)
    print(
        f"midrib alone: {int(rib.sum())} px, lambda {ind.lam:.3f} delta {ind.delta:.3f} objective {ind.objective:.3f}"
    )
    for i in range(model.n_exemplars):
        if i != t:
            print(f"  exemplar {i}: IoU with training midrib {iou(ind.masks[i], rib):.3f}")


if __name__ == "__main__":
    main()
