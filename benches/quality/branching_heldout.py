"""Rebuild the held-out inputs of issue 19's quality runs from their public sources.

    python benches/quality/branching_heldout.py --out DIR --crackforest REPO --hazards REPO
        --fracdim REPO --singan REPO --minirhizotron REPO [--pysheds REPO] [--shared DIR]

None of these images is in the repository (their licences differ, and nobody may tune on
them here), so each session that scores ``synthesize`` on images nobody tuned on makes them
again. Each ``REPO`` is a clone of the repository named below (a bare clone will do); files
are read at the commits the quality notes name, with ``git show``. ``--shared`` is the shared
real-image collection (default: ``PHLOEM_SHARED_DATA``), for the two stand-ins cut from it.
Writes ``DIR/heldout`` (8 inputs), ``DIR/heldout2`` (2), ``DIR/heldout3`` (4) and
``DIR/heldout4`` (1): the four folders of docs/pipelines/branching/quality.md, twenty-second
session on, scored with ``branching_quality.py --inputs DIR/heldoutN``; with ``--pysheds``
also ``DIR/heldout5`` (1, a second elevation model, thirty-ninth session on) and ``DIR/heldout6``
(14: six more CrackForest photos with their masks, and two river-network figures of pysheds'
examples, forty-fourth session on). File names do not matter to the quality script; a derived image is a lossless PNG, a repository's JPEG is copied
byte for byte.
"""

from __future__ import annotations

import argparse
import io
import os
import subprocess
from pathlib import Path

import numpy as np
from PIL import Image
from scipy.io import loadmat

CRACKFOREST = "ed57c2d"  # github.com/cuilimeng/CrackForest-dataset
HAZARDS = "e335f2e"  # github.com/Emperoremman/Hydrometeorological-Hazards (lightning.jpg's one version)
FRACDIM = "1366db5"  # github.com/stevecrampton/fracdim
SINGAN = "4863640"  # github.com/jonasgrebe/pt-singan-single-image-gan
MINIRHIZOTRON = "9abedb1"  # github.com/loreguerra/minirhizotron
PYSHEDS = "f55659b"  # github.com/mdbartos/pysheds (data/dem.tif's last change)


def _show(repo: Path, commit: str, path: str) -> bytes:
    """The bytes of ``path`` at ``commit`` in the clone ``repo``."""
    return subprocess.run(["git", "-C", str(repo), "show", f"{commit}:{path}"], check=True, capture_output=True).stdout


def _copy(data: bytes, dest: Path) -> None:
    dest.write_bytes(data)


def _crack_mask(mat: bytes) -> Image.Image:
    """CrackForest's ground truth: label 2 of the segmentation is crack, written white on black."""
    seg = loadmat(io.BytesIO(mat))["groundTruth"][0, 0]["Segmentation"]
    return Image.fromarray(np.where(seg == 2, 255, 0).astype(np.uint8), "L")


def build(out: Path, shared: Path, *, crackforest: Path, hazards: Path, fracdim: Path, singan: Path,
          minirhizotron: Path, pysheds: Path | None = None) -> list[Path]:  # fmt: skip
    """Write the four folders under ``out`` (six with ``pysheds``); returns the files written."""
    dirs = [out / n for n in ("heldout", "heldout2", "heldout3", "heldout4")]
    if pysheds is not None:
        dirs.append(out / "heldout5")
    h1, h2, h3, h4 = dirs[:4]
    for d in dirs:
        d.mkdir(parents=True, exist_ok=True)
    # Road cracks, photos and masks (480x320).
    for n in ("001", "042", "087"):
        _copy(_show(crackforest, CRACKFOREST, f"image/{n}.jpg"), h1 / f"crack_photo_{n}.jpg")
        _crack_mask(_show(crackforest, CRACKFOREST, f"groundTruth/{n}.mat")).save(h1 / f"crack_mask_{n}.png")
    # Two stand-ins from the shared collection: a leaf's veins (rows 180-480, columns 230-450)
    # and bark fissures (longest side 400 px).
    leaf = np.asarray(Image.open(shared / "leaves" / "pliman_sev_leaf.jpg").convert("RGB"))
    Image.fromarray(leaf[180:480, 230:450]).save(h1 / "leaf_vein_crop.png")
    bark = Image.open(shared / "bark" / "laitoch_bark1_full.jpg").convert("RGB")
    s = 400 / max(bark.size)
    bark.resize((round(bark.size[0] * s), round(bark.size[1] * s)), Image.LANCZOS).save(h1 / "bark_fissures.png")
    # A small lightning photo (257x180) and the same scaled x2.
    small = _show(hazards, HAZARDS, "lightning.jpg")
    _copy(small, h2 / "lightning.jpg")
    li = Image.open(io.BytesIO(small)).convert("RGB")
    li.resize((li.size[0] * 2, li.size[1] * 2), Image.LANCZOS).save(h2 / "lightning_x2.png")
    # A branching bolt, a frozen dendritic reservoir, a leaf venation (900x671 to 450x336), a
    # row of bolts.
    for name in ("lightning", "river"):
        _copy(_show(fracdim, FRACDIM, f"data/{name}.jpg"), h3 / f"fracdim_{name}.jpg")
    veins = Image.open(io.BytesIO(_show(fracdim, FRACDIM, "data/leaf.jpg")))
    veins.resize((450, 336), Image.LANCZOS).save(h3 / "fracdim_leaf.png")
    _copy(_show(singan, SINGAN, "data/lightning.jpg"), h3 / "singan_lightning.jpg")
    # Roots seen through a minirhizotron tube (600x502).
    _copy(_show(minirhizotron, MINIRHIZOTRON, "images/roots.jpg"), h4 / "minirhizotron_roots.jpg")
    if pysheds is not None:
        # An elevation model (367x359, int16 heights), its range stretched to a 16-bit PNG.
        dem = np.asarray(Image.open(io.BytesIO(_show(pysheds, PYSHEDS, "data/dem.tif"))), np.float64)
        u16 = np.round((dem - dem.min()) / (dem.max() - dem.min()) * 65535).astype(np.uint16)
        Image.fromarray(u16).save(dirs[4] / "pysheds_dem_u16.png")
        # Inputs nobody had tuned on by the forty-fourth session: more road cracks, and two
        # figures of a river network (the plots' insides, without titles and colour bar).
        h6 = out / "heldout6"
        h6.mkdir(parents=True, exist_ok=True)
        dirs.append(h6)
        for n in ("015", "033", "058", "071", "099", "112"):
            _copy(_show(crackforest, CRACKFOREST, f"image/{n}.jpg"), h6 / f"crack_photo_{n}.jpg")
            _crack_mask(_show(crackforest, CRACKFOREST, f"groundTruth/{n}.mat")).save(h6 / f"crack_mask_{n}.png")
        for name, box in (("flow_accumulation", (42, 18, 395, 330)), ("river_network", (58, 20, 415, 365))):
            fig = Image.open(io.BytesIO(_show(pysheds, PYSHEDS, f"examples/img/{name}.png"))).convert("RGB")
            fig.crop(box).save(h6 / f"pysheds_{name}_crop.png")
    return sorted(p for d in dirs for p in d.iterdir())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, required=True, help="folder that receives heldout, heldout2, ...")
    for name in ("crackforest", "hazards", "fracdim", "singan", "minirhizotron"):
        ap.add_argument(f"--{name}", type=Path, required=True, help="a clone of the repository named in the docstring")
    ap.add_argument("--pysheds", type=Path, default=None, help="a clone of pysheds: also write heldout5 and heldout6")
    ap.add_argument("--shared", type=Path, default=None, help="the shared real-image collection")
    args = ap.parse_args()
    shared = args.shared or Path(os.environ.get("PHLOEM_SHARED_DATA", "../shared/data"))
    files = build(
        args.out, shared, crackforest=args.crackforest, hazards=args.hazards, fracdim=args.fracdim,
        singan=args.singan, minirhizotron=args.minirhizotron, pysheds=args.pysheds,
    )  # fmt: skip
    for p in files:
        with Image.open(p) as im:
            print(f"{p}  {im.size[0]}x{im.size[1]} {im.mode}")


if __name__ == "__main__":
    main()
