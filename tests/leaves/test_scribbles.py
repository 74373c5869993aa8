"""The user's layers from scribbles: reading the strokes, and their lazy-snapping expansion."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

import phloem
from phloem.leaves import layers_from_scribbles, read_scribbles
from phloem.testing import shared_file

DATA = Path(__file__).resolve().parents[1] / "data" / "leaves"

VEIN, SPOT, BLADE = (0.75, 0.85, 0.45), (0.55, 0.30, 0.15), (0.15, 0.40, 0.12)


def _leaf(
    h: int = 160, w: int = 240, *, veins: bool = True, spots: bool = True, noise: float = 0.05, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """An elliptic RGBA leaf: a blade (label 3) with a midrib and side veins 3–4 px wide (1) and
    round spots (2), plus Gaussian colour noise; returns the leaf and its planted labels."""
    yy, xx = np.mgrid[:h, :w]
    alpha = ((xx - w / 2) / (0.45 * w)) ** 2 + ((yy - h / 2) / (0.42 * h)) ** 2 <= 1
    truth = np.where(alpha, 3, 0).astype(np.int32)
    if spots:
        disc = np.zeros((h, w), np.uint8)
        for y, x in [(0.3, 0.3), (0.7, 0.42), (0.28, 0.62), (0.68, 0.75), (0.62, 0.22)]:
            cv2.circle(disc, (int(x * w), int(y * h)), int(0.05 * h), 1, -1)
        truth[alpha & (disc > 0)] = 2
    if veins:
        line = np.zeros((h, w), np.uint8)
        cy = h // 2
        cv2.line(line, (int(0.08 * w), cy), (int(0.92 * w), cy), 1, 4)
        for x0 in np.linspace(0.2 * w, 0.8 * w, 5):
            for s in (-1, 1):
                cv2.line(line, (int(x0), cy), (int(x0 + 0.12 * w), int(cy + s * 0.33 * h)), 1, 3)
        truth[alpha & (line > 0)] = 1
    img = np.zeros((h, w, 4), np.float32)
    for k, c in ((1, VEIN), (2, SPOT), (3, BLADE)):
        img[truth == k, :3] = c
    rng = np.random.default_rng(seed)
    img[..., :3] = np.clip(img[..., :3] + rng.normal(0, noise, (h, w, 3)), 0, 1)
    img[..., 3] = alpha
    return img, truth


def _strokes(truth: np.ndarray, per_layer: int = 6, length: int = 6, seed: int = 0) -> np.ndarray:
    """A few short horizontal strokes inside each planted layer, as a user would draw them."""
    rng = np.random.default_rng(seed)
    out = np.zeros_like(truth)
    for k in np.unique(truth[truth > 0]):
        inner = cv2.erode((truth == k).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        ys, xs = np.nonzero(inner)
        for i in rng.choice(len(ys), per_layer, replace=False):
            run = slice(xs[i], min(xs[i] + length, truth.shape[1]))
            out[ys[i], run] = np.where(truth[ys[i], run] == k, k, out[ys[i], run])
    return out


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / (a | b).sum())


# -- expansion ---------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1])
def test_three_layers_come_back(seed: int) -> None:
    img, truth = _leaf(seed=seed)
    scribbles = _strokes(truth, seed=seed)
    got = layers_from_scribbles(img, scribbles, seed=seed)
    assert got.dtype == np.int32 and got.shape == truth.shape
    assert (got[truth == 0] == 0).all() and (got[truth > 0] > 0).all()
    for k in (1, 2, 3):
        assert _iou(got == k, truth == k) >= 0.9, k
    marked = scribbles > 0
    assert (got[marked] == scribbles[marked]).all()


def test_smoothness_holds_a_noisy_leaf_together() -> None:
    """At colour noise 0.2 the cut still returns every layer (IoU >= 0.8); without the E2 term
    the spots fall apart (IoU 0.58, docs/pipelines/leaves/scribbles.md)."""
    img, truth = _leaf(noise=0.2, seed=1)
    got = layers_from_scribbles(img, _strokes(truth, seed=1))
    for k in (1, 2, 3):
        assert _iou(got == k, truth == k) >= 0.8, k


def _thin_vein_and_blotches() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A leaf whose 3 px veins are a darker shade of the blade, with broad blotches of exactly the
    veins' colour (as relief bands or shadows share a vein's colour); strokes on two veins and on
    the blade, none on a blotch. Returns the leaf, the strokes, the veins and the blotches."""
    h, w = 160, 240
    yy, xx = np.mgrid[:h, :w]
    alpha = ((xx - w / 2) / (0.45 * w)) ** 2 + ((yy - h / 2) / (0.42 * h)) ** 2 <= 1
    line, blot = np.zeros((h, w), np.uint8), np.zeros((h, w), np.uint8)
    cv2.line(line, (int(0.08 * w), h // 2), (int(0.92 * w), h // 2), 1, 3)
    for x0 in np.linspace(0.25 * w, 0.75 * w, 3):
        cv2.line(line, (int(x0), h // 2), (int(x0 + 0.1 * w), int(h // 2 - 0.3 * h)), 1, 3)
    for y, x in [(0.72, 0.3), (0.7, 0.6), (0.3, 0.45)]:
        cv2.ellipse(blot, (int(x * w), int(y * h)), (18, 7), 20, 0, 360, 1, -1)
    img = np.zeros((h, w, 4), np.float32)
    img[..., :3] = (0.20, 0.40, 0.14)
    img[(blot > 0) | (line > 0), :3] = (0.15, 0.30, 0.10)
    img[..., :3] = np.clip(img[..., :3] + np.random.default_rng(0).normal(0, 0.02, (h, w, 3)), 0, 1)
    img[..., 3] = alpha
    strokes = np.zeros((h, w), np.int32)
    strokes[h // 2, 30:60] = strokes[h // 2, 150:180] = 1
    strokes[40, 60:80] = strokes[120, 100:120] = strokes[100, 180:195] = strokes[60, 150:170] = 2
    return img, strokes, alpha & (line > 0), alpha & (blot > 0)


def test_thin_layer_is_its_lines_not_its_colour(monkeypatch: pytest.MonkeyPatch) -> None:
    """A layer scribbled on thin lines takes the lines and leaves broad areas of their colour to
    the blade (the line feature beside colour); by colour alone it takes the blotches too."""
    img, strokes, veins, blotches = _thin_vein_and_blotches()
    got = layers_from_scribbles(img, strokes) == 1
    assert _iou(got, veins) >= 0.9
    assert (got & blotches).sum() <= 0.05 * blotches.sum()
    monkeypatch.setattr("phloem.leaves.scribbles._LINE_WEIGHT", 0.0)
    by_colour = layers_from_scribbles(img, strokes) == 1
    assert (by_colour & blotches).sum() >= 0.5 * blotches.sum()
    assert _iou(by_colour, veins) < 0.7


def test_same_result_for_any_thread_count() -> None:
    img, truth = _leaf(200, 300, noise=0.15)  # over 2^13 pixels: the cuts split across threads
    scribbles = _strokes(truth)
    one = layers_from_scribbles(img, scribbles, threads=1)
    assert (layers_from_scribbles(img, scribbles, threads=2) == one).all()


def test_two_colour_leaf_comes_back() -> None:
    img, planted = _leaf(veins=False, noise=0.08, seed=3)
    labels = np.select([planted == 2, planted == 3], [1, 2], 0).astype(np.int32)
    got = layers_from_scribbles(img, _strokes(labels, seed=3))
    assert _iou(got == 1, labels == 1) >= 0.9 and _iou(got == 2, labels == 2) >= 0.9


def test_order_is_the_removal_sequence() -> None:
    """Removing 3, 1, 2 equals removing 1, 2, 3 of the same strokes relabelled that way, and on
    a noisy leaf (colour models that overlap) it differs from removing 1, 2, 3."""
    img, truth = _leaf(noise=0.1)
    scribbles = _strokes(truth)
    got = layers_from_scribbles(img, scribbles, order=[3, 1, 2])
    relabel = np.array([0, 2, 3, 1], np.int32)  # old label -> its place in the order
    back = np.array([0, 3, 1, 2], np.int32)
    assert (got == back[layers_from_scribbles(img, relabel[scribbles])]).all()
    assert (got != layers_from_scribbles(img, scribbles)).any()
    assert _iou(got == 1, truth == 1) >= 0.9


def test_scribbles_alone() -> None:
    """A fully scribbled leaf comes back as drawn; scribbles win against their colour."""
    img, truth = _leaf(noise=0.02)
    assert (layers_from_scribbles(img, truth) == truth).all()
    scribbles = _strokes(truth)
    ys, xs = np.nonzero(truth == 3)
    wrong = (ys[::97], xs[::97])  # blade pixels marked as spots
    scribbles[wrong] = 2
    got = layers_from_scribbles(img, scribbles)
    assert (got[wrong] == 2).all()
    marked = scribbles > 0
    assert (got[marked] == scribbles[marked]).all()


def test_png_colour_form(tmp_path: Path) -> None:
    img, truth = _leaf()
    scribbles = _strokes(truth)
    # Colours numbered by first appearance: draw the first-met layer in the first colour.
    first = [int(k) for k in dict.fromkeys(scribbles[scribbles > 0].tolist())]
    colours = {first[0]: (255, 0, 0), first[1]: (0, 0, 255), first[2]: (255, 255, 0)}
    rgba = np.zeros((*truth.shape, 4), np.uint8)
    for k, c in colours.items():
        rgba[scribbles == k] = (*c, 255)
    rgba[0, 0] = (0, 255, 0, 128)  # half-transparent: an anti-aliased edge, not a layer
    path = tmp_path / "s.png"
    Image.fromarray(rgba).save(path)
    labels, n = read_scribbles(path, img.shape)
    rank = np.zeros(4, np.int32)
    rank[first] = [1, 2, 3]
    assert n == 3 and (labels == rank[scribbles]).all()
    assert (layers_from_scribbles(img, path) == rank[layers_from_scribbles(img, scribbles)]).all()


def test_read_scribbles_forms(tmp_path: Path) -> None:
    ints = np.array([[0, 2, 2], [1, 0, 0]], np.uint8)
    labels, n = read_scribbles(ints, (2, 3))
    assert n == 2 and labels.dtype == np.int32 and (labels == ints).all()
    gray = tmp_path / "g.png"
    Image.fromarray(ints).save(gray)  # a gray PNG holds the labels themselves
    assert (read_scribbles(gray, (2, 3, 4))[0] == ints).all()
    rgb = np.zeros((2, 3, 3), np.float32)  # RGB: black unmarked, colours by first appearance
    rgb[0, 2] = (1, 0, 0)
    rgb[1, 0] = (0, 1, 0)
    rgb[1, 2] = (1, 0, 0)
    labels, n = read_scribbles(rgb, (2, 3))
    assert n == 2 and labels.tolist() == [[0, 0, 1], [2, 0, 1]]
    Image.fromarray((rgb * 255).astype(np.uint8)).save(tmp_path / "rgb.png")  # an RGB PNG reads alike
    assert read_scribbles(tmp_path / "rgb.png", (2, 3))[0].tolist() == [[0, 0, 1], [2, 0, 1]]
    rgba = np.zeros((2, 3, 4), np.float32)
    rgba[0, 0] = (0.2, 0.4, 0.6, 1.0)
    rgba[0, 1] = (0.2, 0.4, 0.6, 0.99)  # not opaque: unmarked
    rgba[1, 1] = (0.0, 0.0, 0.0, 1.0)  # opaque black is a colour in RGBA
    labels, n = read_scribbles(rgba, (2, 3))
    assert n == 2 and labels.tolist() == [[1, 0, 0], [0, 2, 0]]


# -- errors ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("scribbles", "match"),
    [
        (np.zeros((4, 5), np.int32), "no layer"),
        (np.ones((4, 5), np.int32), "only one layer"),
        (np.array([[0, 1, 3, 3, 0]] * 4), "layer 2 has no pixel"),
        (np.array([[0, 1, 2, -1, 0]] * 4), "0..n"),
        (np.zeros((4, 6), np.int32), "size"),
        (np.zeros((4, 5, 2), np.float32), "colour image"),
        (np.full((4, 5), 1.5), "whole numbers"),
        (np.arange(20 * 3).reshape(4, 5, 3) / 60.0 + 0.01, None),
    ],
)
def test_read_scribbles_errors(scribbles: np.ndarray, match: str | None) -> None:
    if match is None:  # 20 colours is fine; 65 is not
        assert read_scribbles(scribbles, (4, 5))[1] == 20
        many = np.arange(65 * 3).reshape(5, 13, 3) / 200.0 + 0.01
        with pytest.raises(ValueError, match="^scribbles: 65 distinct"):
            read_scribbles(many, (5, 13))
        return
    with pytest.raises(ValueError, match=f"^scribbles: .*{match}"):
        read_scribbles(scribbles, (4, 5))


def test_read_scribbles_bad_arguments(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="^shape:"):
        read_scribbles(np.zeros((2, 2)), (2, 0))
    with pytest.raises(TypeError, match="^shape:"):
        read_scribbles(np.zeros((2, 2)), 5)
    with pytest.raises(FileNotFoundError, match="^scribbles: no such file"):
        read_scribbles(tmp_path / "missing.png", (2, 2))
    (tmp_path / "bad.png").write_bytes(b"not a png")
    with pytest.raises(ValueError, match="^scribbles: cannot read"):
        read_scribbles(tmp_path / "bad.png", (2, 2))
    with pytest.raises(TypeError, match="^scribbles:"):
        read_scribbles(np.array(["a", "b"]).reshape(1, 2), (1, 2))


def test_layers_from_scribbles_errors() -> None:
    img, truth = _leaf(h=80, w=120)
    scribbles = _strokes(truth, per_layer=2)
    with pytest.raises(ValueError, match=r"^order: expected a permutation of the labels 1\.\.3"):
        layers_from_scribbles(img, scribbles, order=[1, 2])
    with pytest.raises(ValueError, match="^order:"):
        layers_from_scribbles(img, scribbles, order=[1, 1, 3])
    with pytest.raises(TypeError, match="^order:"):
        layers_from_scribbles(img, scribbles, order=[1.0, 2, 3])
    with pytest.raises(TypeError, match="^order:"):
        layers_from_scribbles(img, scribbles, order="123")
    with pytest.raises(ValueError, match="^scribbles: expected the training leaf's size"):
        layers_from_scribbles(img, scribbles[:, :-1])
    off = scribbles.copy()
    off[off == 2] = 0
    off[0, 0] = 2  # a corner: off the elliptic leaf
    with pytest.raises(ValueError, match="^scribbles: layer 2 has no mark on the leaf"):
        layers_from_scribbles(img, off)
    with pytest.raises(ValueError, match="^training: expected an RGB or RGBA"):
        layers_from_scribbles(img[..., :2], scribbles)
    with pytest.raises(ValueError, match="^training: no leaf pixel"):
        layers_from_scribbles(np.zeros_like(img), scribbles)
    with pytest.raises(ValueError, match="^seed:"):
        layers_from_scribbles(img, scribbles, seed=-1)
    with pytest.raises(ValueError, match="^threads:"):
        layers_from_scribbles(img, scribbles, threads=0)


# -- the shared scans --------------------------------------------------------------------------


def test_committed_scribbles_on_the_training_scan() -> None:
    """tests/data/leaves/leafarea_A300-1_scribbles.png fits leaf 0 of its scan and expands to
    thin veins (under 10 % of the leaf: the pale relief bands beside them made 12–17 %), small
    spots and a large blade."""
    path = shared_file("leaves", "leafarea_A300-1.jpeg")  # skips without the shared data
    leaf = phloem.leaves.extract(phloem.io.read_image(path))[0]
    scribbles = DATA / "leafarea_A300-1_scribbles.png"
    assert read_scribbles(scribbles, leaf.shape)[1] == 3
    got = layers_from_scribbles(leaf, scribbles)
    on = leaf[..., 3] > 0.5
    share = [float((got == k).sum() / on.sum()) for k in (1, 2, 3)]
    assert 0.02 < share[0] < 0.10 and 0.01 < share[1] < 0.1 and share[2] > 0.75, share
