"""phloem nnf: the field as .npz."""

from __future__ import annotations

import numpy as np

from phloem.cli import main


def test_nnf_writes_npz(tmp_path, exemplar_png):
    out = tmp_path / "f.npz"
    assert main(["nnf", str(exemplar_png), str(exemplar_png), "--out", str(out), "--patch-size", "5", "-q"]) == 0
    with np.load(out) as z:
        assert z["field"].shape == (64, 64, 2) and z["distance"].shape == (64, 64)
