"""phloem.trees.atlas: normalisation (Argudo et al. 2017 §4.1) and atlas splitting."""

from __future__ import annotations

import numpy as np
import pytest

import phloem
from phloem import trees


@pytest.mark.parametrize(("h", "w"), [(300, 120), (120, 300), (200, 200)])
def test_normalize_square_size_and_placement(h, w):
    img = np.zeros((h + 40, w + 60, 4), np.float32)
    img[25 : 25 + h, 33 : 33 + w] = (0.2, 0.7, 0.3, 1.0)
    out = trees.normalize(img, size=128)
    assert out.shape == (128, 128, 4) and out.dtype == np.float32
    ys, xs = np.nonzero(out[..., 3] >= 0.5)
    # The tree stands on the bottom edge and fills the longer side; centred horizontally.
    assert ys.max() == 127
    if h >= w:
        assert ys.min() == 0
        assert abs((xs.min() + xs.max()) / 2 - 63.5) <= 1.0
    else:
        assert xs.min() == 0 and xs.max() == 127
        assert ys.min() > 60  # padding went on top


def test_normalize_transparent_pixels_are_black():
    rng = np.random.default_rng(0)
    img = rng.random((80, 60, 4)).astype(np.float32)  # colour everywhere, random alpha
    out = trees.normalize(img, size=64, alpha_threshold=0.5)
    clear = out[..., 3] < 0.5
    assert clear.any()
    assert np.all(out[clear] == 0.0)


def test_normalize_does_not_bleed_transparent_colour():
    img = np.zeros((20, 20, 4), np.float32)
    img[..., 0] = 1.0  # red, but transparent
    img[5:15, 8:12] = (0.0, 1.0, 0.0, 1.0)  # a cross: its bounding box holds transparent corners
    img[8:11, 4:16] = (0.0, 1.0, 0.0, 1.0)
    out = trees.normalize(img, size=200)
    assert out[..., 0].max() == 0.0


def test_normalize_accepts_uint8():
    img = np.zeros((30, 30, 4), np.uint8)
    img[5:25, 10:20] = 255
    out = trees.normalize(img, size=32)
    assert out.max() == pytest.approx(1.0)


def test_normalize_errors():
    with pytest.raises(ValueError, match=r"^rgba: .*4 channels"):
        trees.normalize(np.ones((10, 10, 3), np.float32))
    with pytest.raises(ValueError, match=r"^rgba: .*fully transparent"):
        trees.normalize(np.zeros((10, 10, 4), np.float32))
    with pytest.raises(ValueError, match=r"^size"):
        trees.normalize(np.ones((10, 10, 4), np.float32), size=1)
    with pytest.raises(ValueError, match=r"^alpha_threshold"):
        trees.normalize(np.ones((10, 10, 4), np.float32), alpha_threshold=1.5)


def test_split_atlas_grid_of_six_in_reading_order():
    atlas = np.zeros((200, 300, 4), np.float32)
    k = 0
    for r in range(2):
        for c in range(3):
            k += 1
            y0, x0 = 10 + 100 * r, 10 + 100 * c
            atlas[y0 + 20 : y0 + 80, x0 + 30 : x0 + 50] = (k / 10, 0, 0, 1)  # trunk + crown
            atlas[y0 : y0 + 40, x0 + 10 : x0 + 70] = (k / 10, 0, 0, 1)
            atlas[y0 + 2 : y0 + 4, x0 + 75 : x0 + 79] = (k / 10, 0, 0, 1)  # a detached twig
    out = trees.split_atlas(atlas, min_area=50)
    assert len(out) == 6
    assert [round(float(t[0, 40, 0]) * 10) for t in out] == [1, 2, 3, 4, 5, 6]
    assert all(t.shape[:2] == (80, 69) for t in out)  # the twig stays with its tree


def test_split_atlas_drops_specks_and_errors():
    atlas = np.zeros((50, 50, 4), np.float32)
    atlas[5:30, 5:20] = 1.0
    atlas[40:42, 40:42] = 1.0  # speck
    assert len(trees.split_atlas(atlas, min_area=20)) == 1
    with pytest.raises(ValueError, match=r"^rgba: found no tree"):
        trees.split_atlas(atlas, min_area=10_000)


# FlightGear atlases: the count of billboards seen by eye (4 rows of 4 or 8 columns; grass is
# 3 strips). Atlases where neighbours touch come out with fewer pieces: a range.
ATLAS_COUNTS = {
    "caatinga-trees": (16, 16),
    "cerrado-trees": (16, 16),
    "coniferous-alt": (32, 32),
    "coniferous": (32, 32),
    "deciduous-alt": (32, 32),
    "deciduous": (32, 32),
    "evergreen-mediterranean": (32, 32),
    "grass_blades": (3, 3),
    "hawaii-shrub": (16, 16),
    "mediterranean-shrub": (16, 16),
    "mixed-alt": (32, 32),
    "mixed-shrub": (24, 32),
    "mixed": (32, 32),
    "mojave-shrub": (32, 32),
    "savanna-trees": (16, 16),
    "tropical-alt": (32, 32),
    "tropical-alt2": (24, 32),
    "tropical": (24, 32),
}


@pytest.mark.shared
@pytest.mark.parametrize("name", sorted(ATLAS_COUNTS))
def test_split_flightgear_atlas_counts(name):
    from phloem.testing import shared_file

    atlas = phloem.io.read_image(shared_file("trees", f"flightgear_atlas_{name}.png"))
    lo, hi = ATLAS_COUNTS[name]
    assert lo <= len(trees.split_atlas(atlas)) <= hi
