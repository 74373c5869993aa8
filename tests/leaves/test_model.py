"""LeafModel.save / load: lossless round trip, no silent overwrite, clear errors on bad folders."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from phloem.leaves import LeafModel


def _model(n: int = 2, n_layers: int = 3, size: tuple[int, int] = (24, 20)) -> LeafModel:
    rng = np.random.default_rng(1)
    h, w = size
    k = n_layers - 1

    def rgba() -> np.ndarray:
        return rng.random((h, w, 4), dtype=np.float32)

    return LeafModel(
        training=1,
        order=[2, 1, 3][:n_layers] if n_layers == 3 else list(range(1, n_layers + 1)),
        leaves=[rgba() for _ in range(n)],
        forward=[rng.normal(size=(h, w, 2)).astype(np.float32) for _ in range(n)],
        inverse=[rng.normal(size=(h, w, 2)).astype(np.float32) for _ in range(n)],
        residual=[0.5 * i for i in range(n)],
        aligned=[rgba() for _ in range(n)],
        masks=[[rng.random((h, w)) > 0.5 for _ in range(k)] for _ in range(n)],
        dissimilarity=[[rng.random((h, w), dtype=np.float32) for _ in range(k)] for _ in range(n)],
        layers=[[rgba() for _ in range(k)] for _ in range(n)],
        background=[rgba() for _ in range(n)],
        lam=[1.2, 0.1][:k],
        delta=[0.3, 0.4][:k],
        objective=[0.8, 0.7][:k],
        scale=[1.0 + 0.1 * i for i in range(n)],
    )


def _equal(a: LeafModel, b: LeafModel) -> None:
    assert (a.training, a.order, a.residual, a.scale, a.lam, a.delta, a.objective) == (
        b.training, b.order, b.residual, b.scale, b.lam, b.delta, b.objective,
    )  # fmt: skip
    for name in ("leaves", "forward", "inverse", "aligned", "background"):
        for x, y in zip(getattr(a, name), getattr(b, name), strict=True):
            assert x.dtype == y.dtype and np.array_equal(x, y), name
    for name in ("masks", "dissimilarity", "layers"):
        for xs, ys in zip(getattr(a, name), getattr(b, name), strict=True):
            for x, y in zip(xs, ys, strict=True):
                assert x.dtype == y.dtype and np.array_equal(x, y), name


@pytest.mark.parametrize("n_layers", [2, 3])
def test_round_trip_is_lossless(tmp_path: Path, n_layers: int) -> None:
    m = _model(n=3, n_layers=n_layers)
    m.save(tmp_path / "model")
    assert sorted(p.name for p in (tmp_path / "model").iterdir()) == [
        "exemplar_000.npz", "exemplar_001.npz", "exemplar_002.npz", "model.json",
    ]  # fmt: skip
    back = LeafModel.load(tmp_path / "model")
    _equal(m, back)
    assert back.n_exemplars == 3 and back.n_layers == n_layers and back.size == (24, 20)


def test_save_refuses_to_overwrite(tmp_path: Path) -> None:
    m = _model()
    m.save(tmp_path / "m")
    before = (tmp_path / "m" / "model.json").read_bytes()
    with pytest.raises(FileExistsError, match="already exists"):
        _model(n=2, n_layers=2).save(tmp_path / "m")
    assert (tmp_path / "m" / "model.json").read_bytes() == before
    m2 = _model(n=2, n_layers=2)
    m2.save(tmp_path / "m", overwrite=True)
    _equal(m2, LeafModel.load(tmp_path / "m"))


def test_save_into_a_file_is_refused(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("x")
    with pytest.raises(ValueError, match="not a folder"):
        _model().save(tmp_path / "f")


def _corrupt(folder: Path, what: str) -> None:
    meta = json.loads((folder / "model.json").read_text())
    if what == "format":
        meta["format"] = "something else"
    elif what == "version":
        meta["version"] = 99
    elif what == "order":
        meta["order"] = [1, 1, 3]
    elif what == "lam":
        meta["lam"] = [1.0]
    elif what == "field":
        del meta["residual"]
    (folder / "model.json").write_text(json.dumps(meta))


@pytest.mark.parametrize(
    ("what", "message"),
    [
        ("format", "not a phloem leaf model"),
        ("version", "model version 99"),
        ("order", "inconsistent"),
        ("lam", "wrong length"),
        ("field", "lacks a field"),
    ],
)
def test_load_rejects_a_bad_model_json(tmp_path: Path, what: str, message: str) -> None:
    _model().save(tmp_path / "m")
    _corrupt(tmp_path / "m", what)
    with pytest.raises(ValueError, match=message):
        LeafModel.load(tmp_path / "m")


def test_load_rejects_bad_exemplar_files(tmp_path: Path) -> None:
    _model().save(tmp_path / "m")
    npz = tmp_path / "m" / "exemplar_001.npz"
    npz.write_bytes(npz.read_bytes()[:200])
    with pytest.raises(ValueError, match="exemplar_001.npz cannot be read"):
        LeafModel.load(tmp_path / "m")
    (tmp_path / "m" / "exemplar_001.npz").unlink()
    with pytest.raises(ValueError, match="exemplar_001.npz cannot be read"):
        LeafModel.load(tmp_path / "m")


def test_load_rejects_nan_and_wrong_shapes(tmp_path: Path) -> None:
    m = _model()
    m.forward[0][3, 3, 0] = np.nan
    m.save(tmp_path / "nan")
    with pytest.raises(ValueError, match="forward holds NaN"):
        LeafModel.load(tmp_path / "nan")
    m = _model()
    m2 = LeafModel(**{**m.__dict__, "background": [b[:-1] for b in m.background]})
    m2.save(tmp_path / "shape")
    with pytest.raises(ValueError, match="background has shape"):
        LeafModel.load(tmp_path / "shape")


def test_load_of_a_missing_folder(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="not a folder written by LeafModel.save"):
        LeafModel.load(tmp_path / "nothing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="model.json"):
        LeafModel.load(tmp_path / "empty")
