"""Contact sheet of the bark pipeline (thesis Laitoch 2018), to judge by eye.

One row per photo: the photo, phloem's input label map, the synthesised output label map (joint,
the default, and layered), the texture painted from each, the cylinder preview, and a 2×2 tiling of the
``tileable`` texture. With ``../shared/data`` a second block compares phloem with the thesis'
own runs from the *same* inputs (photo ``ai``, labels ``a`` and ``b``): the thesis' result
``bi`` next to phloem's texture-by-numbers, with patch coherence to the photo (lower is better)
and the per-label colour histogram distance (lower is better) under each.

    python -m benches.sheets.sheet_bark out/bark_sheet.png
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

import phloem
from phloem import bark
from phloem.testing import shared_path

from ._sheet import TILE, _fit, _label, write_sheet

SHARED = shared_path("bark")
RUNS = ("bark1", "bark2", "eucalyptus", "eucap5")


def pipeline_row(
    name: str, photo: np.ndarray, k: int, size: tuple[int, int], rotations: str = "half"
) -> list[np.ndarray]:
    opts = {"n_labels": k, "rotations": rotations}
    t0 = time.perf_counter()
    joint = bark.generate(photo, size, seed=1, full_output=True, **opts)
    t_joint = time.perf_counter() - t0
    lay = bark.generate(photo, size, method="layered", seed=1, full_output=True, **opts)
    tile = bark.generate(photo, (size[0] // 2, size[1] // 2), tileable=True, seed=2, **opts)
    tiled = np.tile(tile, (2, 2, 1))
    sim_l = phloem.metrics.shape_similarity(lay.labels_in, lay.labels_out, rotations=rotations)
    sim_j = phloem.metrics.shape_similarity(joint.labels_in, joint.labels_out, rotations=rotations)
    return [
        _label(_fit(photo), f"{name} photo {photo.shape[1]}x{photo.shape[0]}"),
        _label(_fit(bark.encode_labels(joint.labels_in)), f"input labels k={k}"),
        _label(_fit(bark.encode_labels(joint.labels_out)), f"joint labels D={sim_j:.2f}"),
        _label(_fit(joint.texture), f"texture {size[1]}x{size[0]} {t_joint:.1f}s"),
        _label(_fit(bark.encode_labels(lay.labels_out)), f"layered labels D={sim_l:.2f}"),
        _label(_fit(lay.texture), "texture from layered labels"),
        _label(_fit(bark.cylinder_preview(joint.texture)), "on a trunk"),
        _label(_fit(tiled), "tileable, 2x2"),
    ]


def thesis_row(run: str) -> list[np.ndarray]:
    folder = SHARED / "thesis_runs" / run
    photo = phloem.io.read_image(next(folder.glob("ai.*")))[..., :3].copy()
    a_img = phloem.io.read_image(folder / "a.png")
    b_img = phloem.io.read_image(folder / "b.png")
    colours = np.unique(a_img.reshape(-1, 3), axis=0)
    a = np.argmin(np.abs(a_img[:, :, None] - colours[None, None]).sum(3), axis=2).astype(np.int32)
    b = np.argmin(np.abs(b_img[:, :, None] - colours[None, None]).sum(3), axis=2).astype(np.int32)
    bi = phloem.io.read_image(folder / "bi.png")[..., :3]
    t0 = time.perf_counter()
    ours = phloem.texture.by_numbers(photo, a, b, seed=1)
    dt = time.perf_counter() - t0
    m = phloem.metrics

    def scores(img: np.ndarray) -> str:
        return f"coh {m.patch_coherence(img, photo):.4f} hist {m.label_histogram_distance(img, b, photo, a):.3f}"

    return [
        _label(_fit(photo), f"thesis {run}: ai"),
        _label(_fit(bark.encode_labels(a)), "thesis a"),
        _label(_fit(bark.encode_labels(b)), "thesis b"),
        _label(_fit(bi), "thesis bi " + scores(bi)),
        _label(_fit(ours), f"phloem {dt:.2f}s " + scores(ours)),
        _label(_fit(bi[: TILE // 2, : TILE // 2]), "bi 1:1 crop"),
        _label(_fit(ours[: TILE // 2, : TILE // 2]), "phloem 1:1 crop"),
        np.ones((TILE, TILE, 3), np.float32),
    ]


def main(out: Path) -> None:
    rows = [pipeline_row("douglas fir", phloem.data.bark()[..., :3].copy(), 2, (384, 384))]
    rows.append(pipeline_row("douglas fir", phloem.data.bark()[..., :3].copy(), 3, (384, 384)))
    if SHARED.exists():
        for run in RUNS:
            ai = phloem.io.read_image(next((SHARED / "thesis_runs" / run).glob("ai.*")))[..., :3].copy()
            rows.append(pipeline_row(run, ai, 3, (384, 384), rotations="all"))  # plane-tree bark has no grain
        rows.extend(thesis_row(run) for run in RUNS)
    sheet = write_sheet(rows, out)
    print(f"wrote {out} ({sheet.shape[1]}x{sheet.shape[0]}); tile {TILE}px")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/bark_sheet.png"))
