"""Tree exemplar preprocessing (Argudo et al. 2017 §4): normalisation, atlas splitting, contours,
crown/trunk segmentation, pin points, resampling and the simplified contour."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

import phloem
from phloem import trees


def _tree(
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


def _chords(cr: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.diff(np.vstack([cr, cr[:1]]), axis=0), axis=1)


# --- normalize -------------------------------------------------------------------------------


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


# --- split_atlas -----------------------------------------------------------------------------


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


# --- contour ---------------------------------------------------------------------------------


def test_contour_longest_exterior_ccw_on_boundary():
    m = np.zeros((120, 160), np.uint8)
    cv2.circle(m, (50, 60), 40, 1, -1)  # big blob...
    # ...with a star-shaped hole whose outline (an interior contour) is longer than the disk's
    star = [
        (50 + r * np.cos(a), 60 + r * np.sin(a))
        for a, r in zip(np.linspace(0, 2 * np.pi, 24, endpoint=False), [34, 6] * 12, strict=True)
    ]
    cv2.fillPoly(m, [np.round(star).astype(np.int32)], 0)
    cv2.rectangle(m, (110, 20), (150, 100), 1, -1)  # second, smaller blob (perimeter 160)
    mask = m > 0
    c = trees.contour(mask)
    assert trees.signed_area(c) > 0
    # It is the big disk's outline: centred on it and about 2*pi*40 long.
    assert np.allclose(c.mean(axis=0), (50, 60), atol=1.0)
    per = np.linalg.norm(np.diff(np.vstack([c, c[:1]]), axis=0), axis=1).sum()
    assert 220 < per < 270
    # Every point is an opaque pixel with a transparent 4-neighbour.
    xi, yi = c[:, 0].astype(int), c[:, 1].astype(int)
    assert mask[yi, xi].all()
    padded = np.pad(mask, 1)
    interior = padded[yi, xi + 1] & padded[yi + 2, xi + 1] & padded[yi + 1, xi] & padded[yi + 1, xi + 2]
    assert not interior.any()


def test_contour_ccw_is_screen_ccw():
    # Screen-CCW from the bottom point goes right first: x grows just after the lowest point.
    img, _ = _tree()
    c = trees.contour(img)
    b = int(np.argmax(c[:, 1]))
    assert c[(b + 3) % len(c), 0] > c[b, 0] or c[(b + 3) % len(c), 1] < c[b, 1]
    assert trees.signed_area(c) > 0
    assert trees.signed_area(c[::-1]) < 0


def test_contour_accepts_rgba_and_threshold_and_errors():
    img = np.zeros((20, 20, 4), np.float32)
    img[5:15, 5:15, 3] = 0.4
    with pytest.raises(ValueError, match=r"^alpha: .*empty"):
        trees.contour(img)
    assert len(trees.contour(img, alpha_threshold=0.3)) == 36
    with pytest.raises(ValueError, match=r"^alpha"):
        trees.contour(np.ones((5, 5, 3), np.float32))


# --- segment ---------------------------------------------------------------------------------


@pytest.mark.parametrize(("crown_r", "trunk_w", "trunk_h"), [(70, 16, 110), (50, 10, 150), (80, 24, 60), (60, 6, 120)])
def test_segment_recovers_synthetic_trunk(crown_r, trunk_w, trunk_h):
    img, truth = _tree(crown_r=crown_r, trunk_w=trunk_w, trunk_h=trunk_h)
    norm = trees.normalize(img, size=256)
    # The true trunk in normalised coordinates: normalise its mask as an alpha channel.
    t = np.zeros(img.shape, np.float32)
    t[truth] = 1.0
    m = img[..., 3] >= 0.5
    # Same crop / pad / resize as the image: put the truth in the alpha of a copy of the image.
    both = img.copy()
    both[..., :3] = t[..., :1]
    ref = trees.normalize(both, size=256)[..., 0] >= 0.5
    seg = trees.segment(norm)
    iou = (seg & ref).sum() / (seg | ref).sum()
    assert iou > 0.8, iou  # the wide-trunk case (80, 24, 60) measures 0.83: the disk's underside tapers
    assert m.any()


def test_segment_no_trunk_for_a_shrub():
    img = np.zeros((100, 100, 4), np.float32)
    cv2.ellipse(img, (50, 70), (45, 29), 0, 0, 360, (0.2, 0.6, 0.2, 1.0), -1)
    img[99, :] = 0
    assert not trees.segment(img).any()


def test_segment_ignores_flared_foot():
    img, truth = _tree(crown_r=70, trunk_w=14, trunk_h=120)
    bottom = np.flatnonzero(truth.any(axis=1))[-1]
    for k in range(8):  # roots widening over the last 8 rows
        img[bottom - k, 100 - 7 - (8 - k) * 2 : 100 + 7 + (8 - k) * 2] = (0.4, 0.25, 0.1, 1.0)
    seg = trees.segment(img)
    assert seg[bottom - 60, 100] and seg[bottom, 100]
    assert not seg[: np.flatnonzero(truth.any(axis=1))[0] - 2].any()


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


@pytest.mark.shared
def test_segment_against_hand_labels():
    from phloem.testing import shared_file

    ious = []
    for name, i, baseline in LABELS:
        atlas = phloem.io.read_image(shared_file("trees", f"flightgear_atlas_{name}.png"))
        img = trees.normalize(trees.split_atlas(atlas)[i])
        ref = _labelled_trunk(img, baseline)
        seg = trees.segment(img)
        ious.append((seg & ref).sum() / (seg | ref).sum())
    ious_arr = np.array(ious)
    print("trunk IoU per labelled tree:", np.round(ious_arr, 3).tolist())
    # Measured 0.99 1.00 1.00 0.76 0.92 0.99 0.87 0.43 (mean 0.87): the palm's drooping fronds
    # and the caatinga's thin hanging foliage fool the width profile.
    assert ious_arr.mean() > 0.8
    assert np.median(ious_arr) > 0.9


# --- pin points, resampling ------------------------------------------------------------------


def _prepared():
    img, _ = _tree()
    norm = trees.normalize(img, size=512)
    c = trees.contour(norm)
    trunk = trees.segment(norm)
    return norm, c, trunk, trees.pin_points(c, trunk)


def test_pin_points_position_and_order():
    _, c, trunk, (b, l_, r) = _prepared()
    n = len(c)
    # B is the lowest point, in the middle of the trunk's foot.
    assert c[b, 1] == c[:, 1].max()
    xs = c[c[:, 1] == c[:, 1].max(), 0]
    assert abs(c[b, 0] - np.median(xs)) <= 1
    # L on the left, R on the right, both at the crown baseline just above the trunk.
    top = np.flatnonzero(trunk.any(axis=1))[0]
    assert c[l_, 0] < c[b, 0] < c[r, 0]
    assert abs(c[l_, 1] - (top - 1)) <= 1 and abs(c[r, 1] - (top - 1)) <= 1
    # Counter-clockwise from B: R comes first, then L.
    assert (r - b) % n < (l_ - b) % n


def test_pin_points_without_trunk():
    _, c, trunk, _ = _prepared()
    b, l_, r = trees.pin_points(c, np.zeros_like(trunk))
    assert b == l_ == r


def test_resample_counts_pins_and_uniform_chords():
    _, c, _, (b, l_, r) = _prepared()
    cr = trees.resample(c, (b, l_, r))
    assert cr.shape == (2000, 2)
    assert np.array_equal(cr[0], c[r]) and np.array_equal(cr[1600], c[l_]) and np.array_equal(cr[1800], c[b])
    d = _chords(cr)
    for lo, hi in ((0, 1600), (1600, 1800), (1800, 2000)):
        seg = d[lo:hi]
        # Equal chords within the segment, the last gap (to the next pin) included.
        assert seg.max() / seg.min() < 1.5, (lo, seg.min(), seg.max())
        assert np.median(seg) > 0
    assert trees.signed_area(cr) > 0


def test_resample_jagged_contour_exact_count_no_repeats():
    # A disk with thin spokes: the equal-chord walk skips a spoke and comes one point short at
    # n=50; the missing point must still be a new point on the contour.
    rng = np.random.default_rng(1)
    m = np.zeros((200, 200), np.uint8)
    cv2.circle(m, (100, 100), 60, 1, -1)
    for a in rng.uniform(0, 2 * np.pi, 40):
        cv2.line(m, (100, 100), (int(100 + 90 * np.cos(a)), int(100 + 90 * np.sin(a))), 1, 1)
    c = trees.contour(m > 0)
    for n in (50, 100, 300):
        cr = trees.resample(c, (0, 0, 0), split=(n, 1, 1))
        d = _chords(cr[:n])[:-1]
        assert cr.shape == (n + 2, 2) and d.min() > 0.5
        assert np.percentile(d, 95) / np.percentile(d, 5) < 1.01


def test_resample_split_and_errors():
    _, c, _, pins = _prepared()
    cr = trees.resample(c, pins, split=(50, 7, 9))
    assert cr.shape == (66, 2)
    with pytest.raises(ValueError, match=r"^pins"):
        trees.resample(c, (0, 1, len(c)))
    with pytest.raises(ValueError, match=r"^split"):
        trees.resample(c, pins, split=(10, 0, 5))
    with pytest.raises(TypeError, match=r"^pins"):
        trees.resample(c, 3)  # type: ignore[arg-type]


def test_resample_no_trunk_gives_whole_loop_to_crown():
    _, c, _, (b, _, _) = _prepared()
    cr = trees.resample(c, (b, b, b))
    assert np.all(cr[1600:] == c[b])
    per = np.linalg.norm(np.diff(np.vstack([c, c[:1]]), axis=0), axis=1).sum()
    d = _chords(cr)[:1599]
    assert abs(d.sum() - per) / per < 0.05


# --- simplify, prepare -----------------------------------------------------------------------


def test_simplify_dilates_and_has_m_points():
    mask = np.zeros((100, 100), bool)
    cv2.circle(mask.view(np.uint8), (50, 50), 30, 1, -1)
    cs = trees.simplify(mask, m=100, dilation=8)
    assert cs.shape == (100, 2)
    r = np.linalg.norm(cs - 50, axis=1)
    assert np.all(r > 37) and np.all(r < 30 + 8 * np.sqrt(2) + 0.5)  # 8 dilations by a 3x3 square
    d = _chords(cs)
    assert d.max() / d.min() < 1.5
    assert trees.signed_area(cs) > 0
    with pytest.raises(ValueError, match=r"^mask"):
        trees.simplify(np.zeros((5, 5), bool))


def test_prepare_end_to_end_and_user_trunk():
    img, _ = _tree()
    tree = trees.prepare(img, size=256)
    assert tree.image.shape == (256, 256, 4)
    assert tree.resampled.shape == (2000, 2) and tree.simplified.shape == (100, 2)
    assert tree.vector.shape == (4000,) and abs(tree.vector.reshape(-1, 2).mean(axis=0)).max() < 1e-9
    # The simplified contour encloses every opaque pixel of the tree.
    ys, xs = np.nonzero(tree.image[..., 3] >= 0.5)
    poly = tree.simplified.astype(np.float32).reshape(-1, 1, 2)
    inside = [
        cv2.pointPolygonTest(poly, (float(x), float(y)), False) >= 0 for x, y in zip(xs[::50], ys[::50], strict=True)
    ]
    assert all(inside)
    # A user mask with no trunk: all pins at the bottom.
    tree2 = trees.prepare(tree.image, trunk=np.zeros((256, 256), bool), normalized=True)
    assert len(set(tree2.pins)) == 1
    with pytest.raises(ValueError, match=r"^trunk"):
        trees.prepare(img, size=256, trunk=np.zeros((10, 10), bool))


def test_contour_synthesis_convex_combination_is_a_tree():
    # §5.1: a convex combination of two resampled contours keeps B, L, R in place.
    a = trees.prepare(_tree(crown_r=70)[0], size=256)
    b = trees.prepare(_tree(crown_r=50, trunk_h=150)[0], size=256)
    mix = 0.5 * a.resampled + 0.5 * b.resampled
    assert trees.signed_area(mix) > 0
    assert mix[1800, 1] == pytest.approx(255.0)  # both B rows are the bottom edge


# --- the trainable segmenter -----------------------------------------------------------------


def _cone_tree(seed: int, trunk_h: int) -> tuple[np.ndarray, np.ndarray]:
    """A crown that narrows smoothly into the trunk: no width jump for segment() to find."""
    rng = np.random.default_rng(seed)
    img = np.zeros((256, 256, 4), np.float32)
    cx, top_trunk = 128, 255 - trunk_h
    tw = int(rng.integers(5, 8))
    img[top_trunk:, cx - tw : cx + tw] = (0.45, 0.3, 0.15, 1.0)
    crown = np.zeros((256, 256), np.uint8)
    cv2.fillPoly(
        crown, [np.array([[cx - tw, top_trunk], [cx + tw, top_trunk], [cx + 80, 40], [cx - 80, 40]], np.int32)], 1
    )
    for _ in range(30):
        cv2.circle(
            crown, (int(rng.integers(cx - 80, cx + 80)), int(rng.integers(30, 60))), int(rng.integers(6, 14)), 1, -1
        )
    on = crown > 0
    leaf = rng.uniform(0.35, 0.8, (256, 256)).astype(np.float32)
    img[on] = np.stack([0.1 * leaf[on], leaf[on], 0.15 * leaf[on], np.ones(int(on.sum()), np.float32)], axis=1)
    truth = np.zeros((256, 256), bool)
    truth[top_trunk:, cx - tw : cx + tw] = True
    return img, truth & ~on


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


def test_trunk_classifier_learns_what_the_width_profile_misses():
    train = [_cone_tree(0, 60), _cone_tree(1, 90)]
    clf = trees.TrunkClassifier.fit([t[0] for t in train], [t[1] for t in train])
    for seed, h in [(5, 75), (6, 50), (7, 100)]:
        img, truth = _cone_tree(seed, h)
        # Measured: segment() 0.52-0.77 (the taper hides the baseline); the classifier 1.0.
        assert _iou(trees.segment(img), truth) < 0.8
        assert _iou(clf.predict(img), truth) > 0.95
    # Saved and loaded, it predicts the same; prepare() and Library use it.
    again = trees.TrunkClassifier.from_dict(json.loads(json.dumps(clf.to_dict())))
    img, truth = _cone_tree(5, 75)
    assert np.array_equal(again.predict(img), clf.predict(img))
    tree = trees.prepare(img, size=256, classifier=clf)
    assert np.array_equal(tree.trunk, clf.predict(tree.image))


def test_trunk_classifier_errors():
    img, truth = _cone_tree(0, 60)
    with pytest.raises(ValueError, match=r"^trunks: expected one trunk mask per image"):
        trees.TrunkClassifier.fit([img], [truth, truth])
    with pytest.raises(ValueError, match=r"^trunks\[0\]: expected shape"):
        trees.TrunkClassifier.fit([img], [truth[:10]])
    with pytest.raises(ValueError, match=r"^images\[0\]: every pixel is transparent"):
        trees.TrunkClassifier.fit([np.zeros((8, 8, 4), np.float32)], [np.zeros((8, 8), bool)])
    with pytest.raises(ValueError, match=r"^data: not a phloem.trees.TrunkClassifier"):
        trees.TrunkClassifier.from_dict({"coef": []})


@pytest.mark.shared
def test_trunk_classifier_leave_one_out_on_hand_labels():
    from phloem.testing import shared_file

    data = []
    for name, i, baseline in LABELS:
        atlas = phloem.io.read_image(shared_file("trees", f"flightgear_atlas_{name}.png"))
        img = trees.normalize(trees.split_atlas(atlas)[i])
        data.append((img, _labelled_trunk(img, baseline)))
    ious = []
    for k, (img, ref) in enumerate(data):
        rest = [d for j, d in enumerate(data) if j != k]
        clf = trees.TrunkClassifier.fit([d[0] for d in rest], [d[1] for d in rest])
        ious.append(_iou(clf.predict(img), ref))
    print("leave-one-out trunk IoU:", np.round(ious, 3).tolist())
    # At 1024 it measured 0.99 1.00 1.00 0.76 0.93 0.90 0.92 0.43 (mean 0.86, the training-free
    # segmenter 0.87): seven varied trees teach it about as much as the width profile knows
    # (at 512 px it drops to a mean of 0.79: the features are size-relative but the texture is not).
    assert np.mean(ious) > 0.82 and np.median(ious) > 0.9
