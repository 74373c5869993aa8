"""Fixtures of the phloem.trees tests: synthetic trees, a small library, hand-labelled FlightGear trunks."""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np
import pytest

import phloem
from phloem import trees


def _disk_tree(
    h: int = 300, w: int = 200, *, crown_r: int = 70, trunk_w: int = 16, trunk_h: int = 110
) -> tuple[np.ndarray, np.ndarray]:
    """A synthetic RGBA tree: a green disk crown on a brown rectangle trunk standing on the bottom.

    Returns the image and its true trunk mask (the trunk below the crown).
    """
    img = np.zeros((h, w, 4), np.float32)
    cx = w // 2
    bottom = h - 10
    top_trunk = bottom - trunk_h
    trunk = np.zeros((h, w), bool)
    trunk[top_trunk:bottom, cx - trunk_w // 2 : cx + trunk_w // 2] = True
    crown = np.zeros((h, w), np.uint8)
    cv2.circle(crown, (cx, top_trunk - crown_r + 12), crown_r, 1, -1)
    crown = crown > 0
    img[trunk] = (0.4, 0.25, 0.1, 1.0)
    img[crown] = (0.1, 0.6, 0.1, 1.0)
    return img, trunk & ~crown


def _ragged_tree(seed: int, *, crown=(70, 60), trunk_w: int = 16, trunk_h: int = 90) -> np.ndarray:
    """A synthetic RGBA tree: a ragged ellipse crown of leafy noise on a brown trunk."""
    rng = np.random.default_rng(seed)
    h, w = 300, 220
    img = np.zeros((h, w, 4), np.float32)
    cx, bottom = w // 2, h - 5
    top = bottom - trunk_h
    img[top:bottom, cx - trunk_w // 2 : cx + trunk_w // 2] = (0.45, 0.3, 0.15, 1.0)
    crown_mask = np.zeros((h, w), np.uint8)
    cv2.ellipse(crown_mask, (cx, top - crown[1] + 15), crown, 0, 0, 360, 1, -1)
    for _ in range(40):  # ragged outline
        a = rng.uniform(0, 2 * np.pi)
        x, y = cx + crown[0] * np.cos(a), top - crown[1] + 15 + crown[1] * np.sin(a)
        cv2.circle(crown_mask, (int(x), int(y)), int(rng.integers(4, 12)), 1, -1)
    leaf = rng.uniform(0.3, 0.8, (h, w)).astype(np.float32)
    on = crown_mask > 0
    img[on, 0] = 0.1 * leaf[on]
    img[on, 1] = leaf[on]
    img[on, 2] = 0.2 * leaf[on]
    img[on, 3] = 1.0
    return img


@pytest.fixture(scope="session")
def disk_tree() -> Callable[..., tuple[np.ndarray, np.ndarray]]:
    """``disk_tree(h, w, *, crown_r, trunk_w, trunk_h)``: a disk crown on a rectangle trunk, and its trunk mask."""
    return _disk_tree


@pytest.fixture(scope="session")
def ragged_tree() -> Callable[..., np.ndarray]:
    """``ragged_tree(seed, *, crown, trunk_w, trunk_h)``: a ragged leafy ellipse crown on a trunk."""
    return _ragged_tree


@pytest.fixture(scope="session")
def library() -> trees.Library:
    """Four ragged trees named a-d, prepared at 256."""
    imgs = [
        _ragged_tree(0),
        _ragged_tree(1, crown=(50, 80), trunk_h=70),
        _ragged_tree(2, crown=(90, 45), trunk_w=24),
        _ragged_tree(3, crown=(60, 60)),
    ]
    return trees.Library.from_images(imgs, names=["a", "b", "c", "d"], size=256)


# Hand labels: for a handful of FlightGear trees (atlas, index in split_atlas order), the crown
# baseline (lowest crown row) at size 1024, read off zoomed renders with a 16 px grid before
# comparing with the segmenter (about +-10 px). The labelled trunk is the opaque part below it
# that touches the bottom, the same notion of trunk the segmenter outputs.
LABELS = [
    ("cerrado-trees", 1, 600),
    ("cerrado-trees", 3, 590),
    ("deciduous-alt", 2, 740),
    ("tropical-alt", 5, 560),
    ("savanna-trees", 0, 790),
    ("evergreen-mediterranean", 7, 615),
    ("coniferous", 0, 860),
    ("caatinga-trees", 2, 920),
]


def _labelled_trunk(img: np.ndarray, baseline: int) -> np.ndarray:
    op = img[..., 3] >= 0.5
    below = op.copy()
    below[: baseline + 1] = False
    _, lab = cv2.connectedComponents(below.astype(np.uint8))
    bottom = np.flatnonzero(op.any(axis=1))[-1]
    keep = np.unique(lab[bottom][below[bottom]])
    return np.isin(lab, keep[keep > 0])


@pytest.fixture(scope="session")
def hand_labelled() -> list[tuple[np.ndarray, np.ndarray]]:
    """The LABELS trees normalised to 1024 with their labelled trunks (skips without the shared data)."""
    from phloem.testing import shared_file

    out = []
    for name, i, baseline in LABELS:
        atlas = phloem.io.read_image(shared_file("trees", f"flightgear_atlas_{name}.png"))
        img = trees.normalize(trees.split_atlas(atlas)[i])
        out.append((img, _labelled_trunk(img, baseline)))
    return out
