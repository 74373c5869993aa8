"""leaves.analyze: a model from synthetic leaves with known layers; determinism; bad input."""

from __future__ import annotations

import os
import signal
import threading
import time

import cv2
import numpy as np
import pytest

from phloem import leaves
from phloem.leaves import _fill
from phloem.testing import layered_leaf, scribbles_from

# small leaves and few keypoints keep these fast; epsilon is about the registration error here
_KW = {"points": 40, "epsilon": 10.0}


@pytest.fixture(scope="module")
def leaf_set() -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray]:
    made = [layered_leaf(variant=v, seed=v) for v in range(3)]
    imgs = [m[0] for m in made]
    labels = [m[1] for m in made]
    # the second exemplar lies on its side, as scans do: pose must undo it
    imgs[2] = np.ascontiguousarray(np.rot90(imgs[2]))
    labels[2] = np.ascontiguousarray(np.rot90(labels[2]))
    return imgs, labels, scribbles_from(labels[0], seed=3)


@pytest.fixture(scope="module")
def model(leaf_set) -> leaves.LeafModel:
    imgs, _, sc = leaf_set
    return leaves.analyze(imgs, sc, seed=1, **_KW)


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum()) / max(1.0, float((a | b).sum()))


def test_the_model_has_every_field_on_one_canvas(model: leaves.LeafModel) -> None:
    h, w = model.size
    assert model.n_exemplars == 3 and model.n_layers == 3 and model.order == [1, 2, 3]
    assert len(model.lam) == len(model.delta) == len(model.objective) == 2
    for i in range(3):
        assert model.leaves[i].shape == model.aligned[i].shape == model.background[i].shape == (h, w, 4)
        assert model.forward[i].shape == model.inverse[i].shape == (h, w, 2)
        assert len(model.masks[i]) == len(model.layers[i]) == len(model.dissimilarity[i]) == 2
    assert model.residual[0] == 0.0 and not model.forward[0].any()
    assert model.scale[0] == 1.0


def test_every_exemplar_is_aligned_to_the_training_leaf(model: leaves.LeafModel) -> None:
    # the keypoints lie on the outline and the veins, and the variants' side veins differ in
    # angle, so aligning veins costs some outline overlap: the bound is on both together
    train = model.leaves[model.training][..., 3] > 0.5
    for i in (1, 2):
        assert _iou(model.aligned[i][..., 3] > 0.5, train) > 0.88
        assert 0.0 < model.residual[i] < 2.0
        assert _iou(model.masks[i][0], model.masks[model.training][0]) > 0.5  # the veins meet


def test_the_training_layers_are_the_users_expanded_layers(leaf_set, model: leaves.LeafModel) -> None:
    _, labels, _ = leaf_set
    t = model.training
    lab = np.zeros(model.size, np.int32)
    ys, xs = np.nonzero(model.leaves[t][..., 3] > 0.5)
    y0, x0 = ys.min() - np.nonzero(labels[0])[0].min(), xs.min() - np.nonzero(labels[0])[1].min()
    lab[y0 : y0 + labels[0].shape[0], x0 : x0 + labels[0].shape[1]] = labels[0]
    for k, label in enumerate(model.order[:-1]):
        assert _iou(model.masks[t][k], lab == label) > 0.8


def test_veins_are_induced_on_the_exemplars_and_peeled(model: leaves.LeafModel) -> None:
    t = model.training
    veins_t = model.masks[t][0]
    for i in (1, 2):
        assert _iou(model.masks[i][0], veins_t) > 0.5  # aligned veins overlap the training's
    # peeling: the veins' pale colour is gone from the background layer of every exemplar
    pale = np.array([0.72, 0.78, 0.38], np.float32)
    for i in range(3):
        leaf = model.background[i][..., 3] > 0.5
        d = np.linalg.norm(model.background[i][..., :3] - pale, axis=2)
        assert (d[leaf] < 0.12).mean() < 0.02
        m = model.layers[i][0]
        assert np.array_equal(m[..., 3] > 0, model.masks[i][0] & (model.aligned[i][..., 3] > 0))


def test_veins_are_more_structural_than_spots(model: leaves.LeafModel) -> None:
    assert model.lam[0] > model.lam[1]


def test_the_model_does_not_depend_on_threads(leaf_set) -> None:
    imgs, _, sc = leaf_set
    a = leaves.analyze(imgs[:2], sc, seed=2, threads=1, **_KW)
    b = leaves.analyze(imgs[:2], sc, seed=2, threads=2, **_KW)
    for x, y in zip(a.background + a.forward + a.inverse, b.background + b.forward + b.inverse, strict=True):
        assert np.array_equal(x, y)
    assert a.lam == b.lam and a.delta == b.delta


def test_order_changes_which_layer_is_peeled_first(leaf_set) -> None:
    imgs, _, sc = leaf_set
    m = leaves.analyze(imgs[:2], sc, order=[2, 1, 3], seed=1, **_KW)
    assert m.order == [2, 1, 3]
    # layer 2 (spots, ~200 px) is now removed first, the veins (~1800 px) second
    assert m.masks[0][0].sum() < m.masks[0][1].sum()


def test_progress_is_reported_to_the_end(leaf_set) -> None:
    imgs, _, sc = leaf_set
    seen: list[tuple[int, int]] = []
    leaves.analyze(imgs[:2], sc, progress=lambda d, t: seen.append((d, t)), **_KW)
    assert seen[-1][0] == seen[-1][1] and [d for d, _ in seen] == list(range(1, len(seen) + 1))


def test_saved_models_synthesize_as_the_original(tmp_path, model: leaves.LeafModel) -> None:
    model.save(tmp_path / "m")
    back = leaves.LeafModel.load(tmp_path / "m")
    a = leaves.synthesize(model, count=1, seed=5)[0]
    b = leaves.synthesize(back, count=1, seed=5)[0]
    assert np.array_equal(a, b)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ("one", "at least 2 leaves"),
        ("rgb", "expected an RGBA leaf"),
        ("empty", "alpha channel is empty"),
        ("size", "scribbles"),
        ("nolayer", "scribbles"),
        ("order", "order: expected a permutation"),
        ("order_short", "order: expected a permutation"),
        ("order_long", "order: expected a permutation"),
        ("training", "training: expected an index below"),
        ("array", "leaves: expected a list"),
    ],
)
def test_bad_input_is_a_one_line_error(leaf_set, change: str, message: str) -> None:
    imgs, _, sc = leaf_set
    imgs = list(imgs[:2])
    kw: dict = dict(_KW)
    if change == "one":
        imgs = imgs[:1]
    elif change == "rgb":
        imgs[1] = imgs[1][..., :3]
    elif change == "empty":
        imgs[1] = np.zeros_like(imgs[1])
    elif change == "size":
        sc = cv2.resize(sc.astype(np.uint8), (40, 40), interpolation=cv2.INTER_NEAREST).astype(np.int32)
    elif change == "nolayer":
        sc = np.zeros_like(sc)
    elif change == "order":
        kw["order"] = [1, 1, 3]
    elif change == "order_short":  # fewer layers than the scribbles have
        kw["order"] = [2, 1]
    elif change == "order_long":  # a layer the scribbles do not have
        kw["order"] = [1, 2, 3, 4]
    elif change == "training":
        kw["training"] = 5
    elif change == "array":
        imgs = np.stack(imgs)
    with pytest.raises((ValueError, TypeError), match=message) as info:
        leaves.analyze(imgs, sc, **kw)
    assert "\n" not in str(info.value)


def test_the_stages_side_by_side_make_the_serial_model(leaf_set) -> None:
    # threads=1 runs every task in turn; 2 and 3 run the exemplars' registrations and peels side by side
    imgs, _, sc = leaf_set
    a, b, c = (leaves.analyze(imgs, sc, seed=4, threads=n, **_KW) for n in (1, 2, 3))
    for m in (b, c):
        fields = ("aligned", "background", "forward", "inverse", "masks", "layers", "dissimilarity")
        for name in fields:
            for x, y in zip(getattr(a, name), getattr(m, name), strict=True):
                assert np.array_equal(np.asarray(x), np.asarray(y)), name
        assert a.residual == m.residual and a.lam == m.lam and a.objective == m.objective


def test_progress_comes_in_order_from_stages_side_by_side(leaf_set) -> None:
    imgs, _, sc = leaf_set
    seen: list[tuple[int, int]] = []
    leaves.analyze(imgs, sc, threads=3, progress=lambda d, t: seen.append((d, t)), **_KW)
    # 2 per registered exemplar, 1 for the scribbles, per peeled layer 1 induction + 3 peels,
    # then 1 per leaf for its holes
    total = 2 * 2 + 1 + 2 * 4 + 3
    assert seen == [(d, total) for d in range(1, total + 1)]


def test_ctrl_c_stops_the_peels_running_beside_each_other(leaf_set, monkeypatch) -> None:
    # Python delivers SIGINT to the main thread only: it must stop the workers' completions at
    # their next iteration, drop the peel not started, and raise once every worker has ended
    imgs, _, sc = leaf_set
    started, stopped, finished = [], [], []
    running = threading.Event()

    def slow_complete(image, mask, *, progress, **kw):
        started.append(1)
        if len(started) == 2:  # both workers are busy: now the user presses Ctrl-C
            running.set()
        try:
            for k in range(2000):  # ~20 s unless stopped
                time.sleep(0.01)
                progress(k + 1, 2000)
        except BaseException:
            stopped.append(1)
            raise
        finished.append(1)
        return image

    monkeypatch.setattr(_fill, "complete", slow_complete)
    timer = threading.Thread(target=lambda: running.wait(30) and os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        leaves.analyze(imgs, sc, threads=2, **_KW)
    timer.join()
    assert len(started) == 2 and len(stopped) == 2 and not finished  # the third peel never began
    assert not [th for th in threading.enumerate() if th.name.startswith("phloem-leaves")]
