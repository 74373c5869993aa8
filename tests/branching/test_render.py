"""Fragment-based image synthesis (Sibbing et al. 2010, §5.2-§5.3): choice, deformation, seams, pastes, scheduling."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.ndimage import map_coordinates

import phloem
from phloem import _core
from phloem.blend import interpolate_field
from phloem.branching import Branch, Skeleton, render
from phloem.branching._pixels import two_level
from phloem.branching.measures import structure_contrast
from phloem.branching.render import (
    _branch_map,
    _channel_range,
    _drop_foreign,
    _fit_range,
    _in_order,
    _keep_contrast,
    _pt,
)
from phloem.testing import channel_scene, longest_path, shared_file, wavy_branch


def test_identity_target_reproduces_the_source_along_the_structure() -> None:
    img, sk = channel_scene()
    out = render(img, sk, sk, seed=0, complete=False, full_output=True)
    near = cv2.dilate(sk.mask().astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool) & (out.labels >= 0)
    err = np.abs(out.image - img)[near]  # a 2-D input gives a 2-D image
    assert near.sum() > 0.8 * sk.mask().sum()
    # Fragments holding a junction are kept for the furcation fragments only, so pixels near
    # the junction come from elsewhere; everywhere else the copy is exact.
    assert float(err.mean()) < 0.04, float(err.mean())
    assert float(np.mean(err < 0.01)) > 0.7, float(np.mean(err < 0.01))
    # Each target fragment took the source fragment at its own place.
    src = np.stack([out.sources[i].center for i in out.choice])
    tgt = np.stack([g.center for g in out.targets])
    assert float(np.median(np.linalg.norm(src - tgt, axis=1))) < 1.0


def test_structure_pixels_come_from_the_source_structure() -> None:
    img, sk = channel_scene()
    # A different target: rotated, bent main branch with one sub-branch elsewhere.
    main = wavy_branch((20, 20), 0.5, 200, (4.0, 3.0), phase=3.0, amp=0.4)
    child = wavy_branch(tuple(main.points[40]), -0.6, 50, (3.0, 2.0), parent=(0, 40))
    tgt = Skeleton([main, child], (160, 200))
    out = render(img, sk, tgt, seed=3)
    m = tgt.mask()
    core = cv2.erode(m.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    far = ~cv2.dilate(m.astype(np.uint8), np.ones((15, 15), np.uint8)).astype(bool)
    assert out.shape == (160, 200)
    assert float(np.median(out[core])) < 0.3  # the dark channel stays dark
    assert float(np.mean(out[core] < 0.4)) > 0.85
    assert float(np.median(out[far])) > 0.6  # and the land stays light
    assert float(np.mean(out[far] < 0.4)) < 0.02  # no pseudo-branches in the gaps


def test_render_is_deterministic_for_a_seed() -> None:
    img, sk = channel_scene()
    main = wavy_branch((20, 30), 0.2, 170, (4.0, 3.0), phase=2.0)
    tgt = Skeleton([main], (96, 200))
    a = render(img, sk, tgt, seed=7, full_output=True)
    b = render(img, sk, tgt, seed=7, full_output=True)
    assert np.array_equal(a.image, b.image) and np.array_equal(a.choice, b.choice)
    one = render(img, sk, tgt, seed=7, threads=1)
    assert np.array_equal(one, a.image)  # whatever the number of threads
    others = [render(img, sk, tgt, seed=s, n_best=4, complete=False, full_output=True).choice for s in range(4)]
    assert any(not np.array_equal(others[0], o) for o in others[1:])


def test_concurrent_painting_equals_painting_in_order() -> None:
    """Fragments that do not overlap are painted at the same time; the image, the choices and
    the fragment map must still be those of painting them one by one. Three separate trees
    and two sub-branches give the scheduler real concurrency, and c = 4 makes every pick a
    random draw."""
    img, sk = channel_scene()
    branches = []
    for k, (y, ang) in enumerate(((30.0, 0.1), (110.0, -0.1), (190.0, 0.05))):
        main = wavy_branch((10, y), ang, 230, (4.0, 3.0), phase=k)
        branches.append(main)
        if k != 1:
            turn = 0.9 - 1.8 * (k == 2)
            parent = (len(branches) - 1, 35)
            branches.append(wavy_branch(tuple(main.points[35]), turn, 40, (3.0, 2.0), amp=0.1, parent=parent))
    tgt = Skeleton(branches, (220, 260))
    runs = [render(img, sk, tgt, seed=3, n_best=4, complete=False, full_output=True, threads=t) for t in (1, 2, 3)]
    for r in runs[1:]:
        assert np.array_equal(r.image, runs[0].image)
        assert np.array_equal(r.choice, runs[0].choice) and np.array_equal(r.labels, runs[0].labels)


@pytest.mark.parametrize("n_best", [1, 2])
def test_fragment_choice_does_not_depend_on_the_input_contrast(n_best: int) -> None:
    # issue 19: the colour term is measured in units of the input's range; on a terrain that
    # spans 1 % of [0, 1] it used to be 10^4 times weaker, so the choice was by shape alone.
    img, sk = channel_scene()
    tgt = Skeleton([wavy_branch((20, 30), 0.2, 150, (4.0, 3.0), phase=2.0)], (80, 180))
    kw = {"seed": 1, "n_best": n_best, "complete": False, "full_output": True}
    full = render(img, sk, tgt, **kw)
    faint = render(0.01 * img + 0.3, sk, tgt, **kw)
    assert np.array_equal(full.choice, faint.choice)
    assert not np.array_equal(full.choice, render(img, sk, tgt, omega_c=0.0, **kw).choice)  # C matters here


def _framed_scene(first: int) -> tuple[np.ndarray, Skeleton, np.ndarray]:
    """The channel scene with a frame of value 5 from column ``first`` on, and its ``valid``."""
    img, sk = channel_scene()
    img = img.copy()
    img[:, first:] = 5.0
    valid = np.zeros(img.shape[:2], bool)
    valid[:, :first] = True
    return img, sk, valid


def test_fragments_reaching_outside_valid_are_not_used() -> None:
    # The right half of the input is "frame" (value 5, outside `valid`); the source branch
    # runs through it. No pixel of it may reach the output, and a `valid` that leaves no
    # fragment whole is an error naming it. (Half the fragments lie in it, so without `valid`
    # they are not outliers of the fragments' surroundings either.)
    img, sk, valid = _framed_scene(90)
    tgt = Skeleton([wavy_branch((20, 30), 0.2, 150, (4.0, 3.0), phase=2.0)], (80, 180))
    assert float(render(img, sk, tgt, seed=1, complete=False).max()) > 4.0  # without `valid` it does
    out = render(img, sk, tgt, seed=1, valid=valid, keep_frame=False)
    assert float(out.max()) < 1.5
    with pytest.raises(ValueError, match="valid"):
        render(img, sk, tgt, valid=np.zeros(img.shape[:2], bool))
    # by default the new image keeps the input's frame (stretched to the target's 180 of the
    # input's 224 columns, nearest pixel), faded in over its first 4 px, and only the frame
    kept = render(img, sk, tgt, seed=1, valid=valid)
    frame = np.floor(np.arange(180) * 224 / 180) >= 90
    first = int(np.argmax(frame))
    assert np.all(kept[:, first + 5 :] == 5.0) and float(kept[:, ~frame].max()) < 1.5
    assert np.all(np.diff(kept[:, first : first + 5].mean(axis=0)) > 0.5)  # the fade
    assert np.array_equal(kept[:, ~frame], out[:, ~frame])


def test_the_frame_is_kept_in_place_at_the_input_s_size() -> None:
    img, sk, valid = _framed_scene(190)
    tgt = Skeleton([wavy_branch((20, 40), 0.2, 160, (4.0, 3.0), phase=2.0)], img.shape[:2])
    out = render(img, sk, tgt, seed=1, valid=valid)
    assert np.array_equal(out[:, 195:], img[:, 195:]) and float(out[:, :190].max()) < 1.5


def test_paste_structure_default_is_off_for_masks_only() -> None:
    img, sk = channel_scene()
    tgt = Skeleton([wavy_branch((20, 30), 0.2, 150, (4.0, 3.0), phase=2.0)], (80, 180))
    grey = [render(img, sk, tgt, seed=2, paste_structure=m) for m in (None, True, False)]
    assert np.array_equal(grey[0], grey[1]) and not np.array_equal(grey[0], grey[2])
    # match_borders follows: off under the structure paste, on without it
    assert np.array_equal(grey[0], render(img, sk, tgt, seed=2, match_borders=False))
    assert np.array_equal(grey[2], render(img, sk, tgt, seed=2, paste_structure=False, match_borders=True))
    mask = np.where(sk.mask(), 1.0, 0.0).astype(np.float32)
    masks = [
        render(mask, sk, tgt, seed=2, paste_structure=m, match_borders=b) for m, b in ((None, None), (False, False))
    ]
    assert np.array_equal(masks[0], masks[1])
    with pytest.raises(ValueError, match="^paste_structure"):
        render(img, sk, tgt, paste_structure=True, complete=False)


def _steps(out: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Absolute 4-neighbour differences across the structure's border and between gap pixels."""
    f = labels >= 0
    d = (np.abs(np.diff(out, axis=1)), np.abs(np.diff(out, axis=0)))
    border = np.concatenate([d[0][f[:, 1:] != f[:, :-1]], d[1][f[1:] != f[:-1]]])
    gap = np.concatenate([d[0][~f[:, 1:] & ~f[:, :-1]], d[1][~f[1:] & ~f[:-1]]])
    return border, gap


@pytest.mark.parametrize("seed", [0, 1])
def test_paste_structure_leaves_no_disk_rims_under_uneven_light(seed: int) -> None:
    # issue 19: the input is lit from one side (a ramp of half its range), so fragments from
    # its two ends differ in level by up to 0.5; pasted into the completed gaps as a whole,
    # their rims are no steeper than the gaps themselves, and the channel stays dark.
    img, sk = channel_scene()
    lit = np.clip(img + np.linspace(-0.25, 0.25, img.shape[1], dtype=np.float32)[None, :], 0, 1)
    tgt = Skeleton([wavy_branch((20, 30), 0.2, 150, (4.0, 3.0), phase=2.0)], (80, 180))
    core = tgt.mask()
    res = {ps: render(lit, sk, tgt, seed=seed, paste_structure=ps, full_output=True) for ps in (True, False)}
    border, gap = _steps(res[True].image, res[True].labels)
    assert float(border.mean()) < 1.2 * float(gap.mean()), (border.mean(), gap.mean())
    assert float(np.percentile(border, 99)) < 0.15
    # the channel keeps its depth (0.53 in the input) against the gaps beside it
    ring = (cv2.dilate(core.astype(np.uint8), np.ones((9, 9), np.uint8)) > 0) & ~core
    out = res[True].image
    depth = [out[ring[:, x], x].mean() - out[core[:, x], x].mean() for x in range(10, 170, 10) if core[:, x].any()]
    assert min(depth) > 0.3, depth
    # the same without it: the rims show (the test sees the difference)
    rims, _ = _steps(res[False].image, res[False].labels)
    assert float(rims.mean()) > 2 * float(border.mean()) and float(np.percentile(rims, 99)) > 0.3


def _bolt(rng: np.random.Generator, x0: float, y0: float, n: int) -> np.ndarray:
    """A downward random walk of ``n`` 3-px steps, heading within 45 degrees of straight down."""
    pts, a = [(x0, y0)], np.pi / 2
    for _ in range(n):
        a = float(np.clip(a + rng.normal(0, 0.5), np.pi / 4, 3 * np.pi / 4))
        pts.append((pts[-1][0] + 3 * np.cos(a), pts[-1][1] + 3 * np.sin(a)))
    return np.array(pts)


def _night_sky() -> tuple[np.ndarray, Skeleton]:
    """Three thin bright bolts on a glowing sky over a dark, jagged horizon."""
    rng = np.random.default_rng(0)
    H, W = 160, 220
    yy, xx = np.mgrid[:H, :W].astype(np.float32)
    glow = np.exp(-((yy - 50) ** 2 / 50**2 + (xx - 110) ** 2 / 70**2))
    sky = 0.3 + 0.35 * glow + rng.normal(0, 0.015, (H, W))
    horizon = 130 + 6 * np.sin(xx[0] / 7.0) + rng.normal(0, 2, W)
    img = np.where(yy > horizon[None, :], 0.03, sky).astype(np.float32)
    bolts = []
    for x0 in (40, 110, 175):
        p = _bolt(rng, x0 + rng.uniform(-10, 10), 5, 30)
        bolts.append(Branch(p, 1.2))
        cv2.polylines(img, [np.round(p * 16).astype(np.int32)], False, 0.95, thickness=2, lineType=cv2.LINE_AA, shift=4)
    return img, Skeleton(bolts, (H, W))


@pytest.mark.parametrize("seed", [0, 1])
def test_the_gaps_beside_pasted_structure_are_plain_background(seed: int) -> None:
    # issue 19: with the structure pasted afterwards, the gaps were completed around it, and
    # partly known patches holding a bolt copied the sky's brightest (or, on a photo, its
    # darkest) places beside it: a halo 0.10 brighter than the sky 8-20 px away. Completed
    # without seeing the structure, the gaps beside it are the sky's own level.
    img, sk = _night_sky()
    rng = np.random.default_rng(100 + seed)
    tgt = Skeleton([Branch(_bolt(rng, x0, 15, 25), 1.2) for x0 in (70, 150)], img.shape)
    res = render(img, sk, tgt, seed=seed, full_output=True)
    d = cv2.distanceTransform((res.labels < 0).astype(np.uint8), cv2.DIST_L2, 5)
    sky = np.arange(img.shape[0])[:, None] < 120
    near = float(res.image[(d > 0) & (d <= 3) & sky].mean())
    far = float(res.image[(d >= 8) & (d <= 20) & sky].mean())
    assert abs(near - far) < 0.05, (near, far)
    # and the bolts still stand out from that sky
    core = tgt.mask() & (res.labels >= 0)
    assert float(res.image[core].mean()) > near + 0.3


def _glowing_bolt(x0: float) -> tuple[np.ndarray, Branch]:
    """A bright bolt 1.5 px in radius down a 160 x 220 dark sky at about ``x0``, in a glow that
    fades over 6 px (a Gaussian), as a lightning photo's bolts are traced."""
    rng = np.random.default_rng(3)
    H, W = 160, 220
    p = _bolt(rng, x0, 5, 50)
    core = np.ones((H, W), np.uint8)
    cv2.polylines(core, [np.round(p * 16).astype(np.int32)], False, 0, thickness=1, lineType=cv2.LINE_8, shift=4)
    d = cv2.distanceTransform(core, cv2.DIST_L2, 5)
    img = 0.08 + 0.45 * np.exp(-(d**2) / (2 * 6.0**2)) + 0.45 * (d <= 1.5) + rng.normal(0, 0.01, (H, W))
    return np.clip(img, 0, 1).astype(np.float32), Branch(p, 1.5)


def test_a_glow_follows_the_new_structure_not_the_old() -> None:
    # issue 19: the gaps took the input's large-scale brightness where it was in the input, so
    # a lightning photo's output carried its bolt's glow as a bright band where the input's bolt
    # had been, and its own bolts sat unlit in a dark sky. The brightness that surrounds the
    # whole structure now follows the new structure.
    img, bolt = _glowing_bolt(50)
    far_right = _glowing_bolt(170)[1]
    res = render(img, Skeleton([bolt], img.shape), Skeleton([far_right], img.shape), seed=0, full_output=True)
    gaps = res.labels < 0
    d_new = cv2.distanceTransform(Skeleton([far_right], img.shape).mask().astype(np.uint8) ^ 1, cv2.DIST_L2, 5)
    d_old = cv2.distanceTransform(Skeleton([bolt], img.shape).mask().astype(np.uint8) ^ 1, cv2.DIST_L2, 5)
    beside_new = float(res.image[gaps & (d_new >= 4) & (d_new <= 10)].mean())
    where_old_was = float(res.image[gaps & (d_old <= 14) & (d_new > 60)].mean())
    open_sky = float(res.image[gaps & (d_old > 40) & (d_new > 40)].mean())
    assert beside_new > open_sky + 0.1, (beside_new, open_sky)
    assert where_old_was < open_sky + 0.05, (where_old_was, open_sky)


def test_the_structure_stands_out_from_the_gaps_as_much_as_the_input() -> None:
    # issue 19: the whole-structure paste moved each fragment to the gaps' level at its rim,
    # and the gaps do not continue a bolt's glow, so bolts came out grey (a third of the
    # contrast lost on a lightning photo); vessels pale likewise
    img, bolt = _glowing_bolt(50)
    tgt = Skeleton([_glowing_bolt(150)[1]], img.shape)
    src = Skeleton([bolt], img.shape)
    for picture in (img, 1.0 - img):
        want = structure_contrast(picture, src)
        res = render(picture, src, tgt, seed=0, full_output=True)
        assert structure_contrast(res.image, tgt) == pytest.approx(want, abs=0.02)


@pytest.mark.parametrize("angle", [0.3, 0.5])
def test_a_line_one_pixel_wide_stays_sharp_in_rotated_fragments(angle: float) -> None:
    # issue 19: bilinear sampling of a rotated fragment spread a vessel or crack a pixel wide over its neighbours
    rng = np.random.default_rng(0)
    img = np.full((120, 200), 0.8, np.float32) + rng.normal(0, 0.01, (120, 200)).astype(np.float32)
    img[60, 10:190] = 0.2
    src = Skeleton([Branch([[10, 60], [189, 60]], 1.0)], img.shape)
    d = 70 * np.array([np.cos(angle), np.sin(angle)])
    tgt = Skeleton([Branch(np.linspace([100, 60] - d, [100, 60] + d, 50), 1.0)], img.shape)

    def curvature(picture: np.ndarray, sk: Skeleton) -> float:
        return float(np.median(np.abs(cv2.Laplacian(picture.astype(np.float32), cv2.CV_32F, ksize=1))[sk.mask()]))

    out = render(img, src, tgt, seed=0)
    assert curvature(out, tgt) > 0.75 * curvature(img, src)
    assert out.min() >= img.min() - 1e-6 and out.max() <= img.max() + 1e-6  # no overshoot beyond the input's range


def test_keep_contrast_lifts_the_structure_and_fades_out_at_the_fragments_rims() -> None:
    # a bolt 0.7 over its sky in the input, pasted 0.3 over it: the lift is 0.4 on the bolt,
    # nothing beyond the fragments (inside the ring that measures it), falling off between
    sk = Skeleton([Branch([[10, 30], [109, 30]], 2.0)], (60, 120))
    yy, xx = np.mgrid[:60, :120]
    on = (np.abs(yy - 30) <= 2) & (xx >= 10) & (xx <= 109)
    image = np.where(on, 0.9, 0.2).astype(np.float32)[..., None]
    canvas = np.where(on, 0.5, 0.2).astype(np.float32)[..., None]
    filled = (np.abs(yy - 30) <= 5) & (xx >= 5) & (xx <= 114)
    out = _keep_contrast(canvas, filled, image, sk, sk, threads=1)
    assert np.array_equal(out[~filled], canvas[~filled])
    assert structure_contrast(out, sk) == pytest.approx(structure_contrast(image, sk), abs=1e-3)
    column = out[30:40, 60, 0] - canvas[30:40, 60, 0]
    assert column[0] == pytest.approx(0.4, abs=1e-6) and (np.diff(column) <= 1e-6).all() and column[-1] == 0.0


def _valley_on_low_ground() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A terrain in [0.1, 0.9] whose gaps slope from 0.8 down to 0.2, and a valley 0.4 deep
    (its fragments' relief) along them: on the low side its floor falls below 0.1."""
    yy, xx = np.mgrid[:60, :120].astype(np.float32)
    gaps = (0.8 - 0.6 * xx / 119.0)[..., None]
    filled = (np.abs(yy - 30) <= 8) & (xx >= 10) & (xx <= 110)
    ends = np.clip(np.minimum(xx - 10, 110 - xx) / 10.0, 0.0, 1.0)
    depth = np.where(filled, 0.4 * np.clip(1.0 - np.abs(yy - 30) / 8.0, 0.0, 1.0) * ends, 0.0)
    canvas = (gaps[..., 0] - depth).astype(np.float32)[..., None]
    image = np.full((60, 120, 1), 0.5, np.float32)
    image[0, :2, 0] = (0.1, 0.9)  # the input's range, reached by one pixel each: no saturation
    return canvas, gaps.astype(np.float32), filled, image


def test_fit_range_scales_a_valley_into_the_range_instead_of_clipping_it_flat() -> None:
    # issue 19: deep valley fragments landing on the elevation model's low ground were clipped
    # into black blots (1.7 % of the output at the input's minimum)
    canvas, gaps, filled, image = _valley_on_low_ground()
    lo, hi = np.float32([0.1]), np.float32([0.9])
    clipped = np.clip(canvas, lo, hi)
    assert (clipped[filled] <= lo + 1e-6).mean() > 0.1  # what a clip flattens
    out = _fit_range(canvas, gaps, filled, image, lo, hi, reach=4.0, threads=1)
    assert np.array_equal(out[~filled], canvas[~filled])  # the gaps are untouched
    # (what is left at the bottom: where the blot starts it is narrower than BLOT_WIDTH)
    assert (out[filled] <= lo + 1e-6).mean() < 0.02
    # across the valley on the low ground its floor is a V again, where the clip left it flat
    for picture, v_shaped in ((clipped, False), (out, True)):
        down, up = np.diff(picture[22:31, 100, 0]), np.diff(picture[30:39, 100, 0])
        assert bool((down < 0).all() and (up > 0).all()) == v_shaped
    # on the high ground, farther than the reach from any blot, the relief is as painted
    np.testing.assert_allclose(out[22:39, 15:40], canvas[22:39, 15:40], atol=1e-3)


def test_fit_range_scales_every_channel_by_the_same_factor() -> None:
    # only the red channel leaves the range; green and blue are scaled with it, so the
    # structure keeps its hue instead of shifting towards the channels with room
    canvas, gaps, filled, image = _valley_on_low_ground()
    rgb = np.concatenate([canvas, 0.5 + 0.5 * (canvas - gaps), 0.6 + 0.25 * (canvas - gaps)], axis=2)
    base = np.concatenate([gaps, np.full_like(gaps, 0.5), np.full_like(gaps, 0.6)], axis=2)
    lo, hi = np.float32([0.1, 0.1, 0.1]), np.float32([0.9, 0.9, 0.9])
    out = _fit_range(rgb, base, filled, np.repeat(image, 3, axis=2), lo, hi, reach=4.0, threads=1)
    deep = filled & (rgb[..., 1] < 0.45) & (out[..., 0] > lo[0] + 1e-6)
    ratio = (out - base)[deep] / (rgb - base)[deep]
    assert float(ratio[:, 0].min()) < 0.9  # the valley was scaled
    np.testing.assert_allclose(ratio[:, 1], ratio[:, 0], atol=5e-3)
    np.testing.assert_allclose(ratio[:, 2], ratio[:, 0], atol=5e-3)


def test_fit_range_clips_where_the_input_saturates_or_the_excess_is_a_thin_line() -> None:
    canvas, gaps, filled, image = _valley_on_low_ground()
    lo, hi = np.float32([0.1]), np.float32([0.9])
    saturated = image.copy()
    saturated[:5] = lo  # 7 % of the input at its minimum: the output may sit there too
    fit = _fit_range(canvas, gaps, filled, saturated, lo, hi, reach=4.0, threads=1)
    assert np.array_equal(fit, np.clip(canvas, lo, hi))
    line = np.maximum(canvas, np.float32(0.12))
    line[29:31, 30:100, 0] = 0.0  # a core 2 px wide below the range: a line, not a blot
    fit = _fit_range(line, gaps, filled, image, lo, hi, reach=4.0, threads=1)
    assert np.array_equal(fit, np.clip(line, lo, hi))


def test_a_mask_renders_as_a_mask() -> None:
    # issue 19: bilinear warps, Poisson pastes and the completion's votes gave grey ramps
    _, sk = channel_scene()
    tgt = Skeleton([wavy_branch((20, 30), 0.2, 150, (4.0, 3.0), phase=2.0)], (80, 180))
    for lo, hi in ((0.0, 1.0), (0.2, 0.6)):
        mask = np.where(sk.mask(), hi, lo).astype(np.float32)
        out = render(mask, sk, tgt, seed=2)
        assert set(np.unique(out).tolist()) <= {np.float32(lo), np.float32(hi)}
        # the structure is there, as wide as the target's (thickness 4 to 3: about 2 r = 7 px)
        assert 4 <= (out[:, 90] == np.float32(hi)).sum() <= 12


def test_a_mask_output_holds_no_pieces_the_target_does_not_touch() -> None:
    # issue 19: a second channel runs 11 px beside the main one, within the fragments' reach
    # (3 x thickness): their disks carry pieces of it, which used to stand as islands.
    _, sk = channel_scene()
    main = sk.branches[0]
    side = np.zeros(sk.shape, np.uint8)
    cv2.polylines(side, [np.round(main.points[60:150] + [0, 11]).astype(np.int32)], False, 1, thickness=3)
    mask = np.where(sk.mask() | (side > 0), 1.0, 0.0).astype(np.float32)
    tgt = Skeleton([wavy_branch((20, 30), 0.2, 150, (4.0, 3.0), phase=2.0)], (80, 180))
    touch = tgt.mask()
    islands = 0
    for seed in range(3):
        res = render(mask, sk, tgt, seed=seed, full_output=True)
        n, comp = cv2.connectedComponents((res.image > 0.5).astype(np.uint8), connectivity=8)
        assert set(np.unique(comp[touch & (res.image > 0.5)]).tolist()) == set(range(1, n))
        # the painted structure before the snap did hold pieces apart from the target's
        n0, comp0 = cv2.connectedComponents((res.structure > 0.5).astype(np.uint8), connectivity=8)
        islands += n0 - 1 - len(set(np.unique(comp0[touch & (res.structure > 0.5)]).tolist()))
    assert islands > 0


def test_drop_foreign_keeps_the_targets_channel_of_either_polarity() -> None:
    tgt = Skeleton([Branch([[5, 20], [35, 20]], 2.0)], (40, 60))
    for struct, bg in ((1.0, 0.0), (0.1, 0.9)):
        canvas = np.full((40, 60, 1), bg, np.float32)
        canvas[17:24, 2:50] = struct  # along the target, and running 15 px past its end
        canvas[17:24, 20:22] = bg  # a break between two fragments
        canvas[30:34, 45:55] = struct  # an island
        canvas[2:5, 2:5] = struct  # another
        source = Skeleton([Branch([[5, 20], [35, 20]], 2.0)], (40, 60))
        lo, hi = np.float32([min(struct, bg)]), np.float32([max(struct, bg)])
        out = _drop_foreign(canvas, canvas, source, tgt, lo, hi)[..., 0]
        assert set(np.unique(out).tolist()) == {np.float32(struct), np.float32(bg)}
        assert (out[30:34, 45:55] == bg).all() and (out[2:5, 2:5] == bg).all()  # islands dropped
        assert (out[17:24, 42:50] == bg).all()  # beyond 1.25 radii + 1 px of the target's end
        assert (out[17:24, 8:18] == struct).all()  # the channel's banks within the band stay
        assert (out[19:22, 20:22] == struct).all()  # the break is closed by the target's tube
        assert (out[:15] == bg).all() and (out[26:30] == bg).all()


def test_fragments_leaving_the_image_are_not_pasted() -> None:
    # the channel starts 8 px from the left border: its first disks reach beyond the image,
    # whose reflected border would be pasted (at a target branch end: a blob)
    img, sk = channel_scene()
    H, W = img.shape[:2]
    tgt = Skeleton([wavy_branch((40, 30), 0.2, 120, (4.0, 3.0), phase=2.0)], (80, 180))
    res = render(img, sk, tgt, seed=0, full_output=True)
    clipped = {
        i
        for i, f in enumerate(res.sources)
        if min(f.center[0], f.center[1]) - f.radius < -1 or f.center[0] + f.radius > W or f.center[1] + f.radius > H
    }
    assert clipped, "the scene should have fragments at the border"
    assert not clipped & set(res.choice.tolist())


def test_in_order_waits_only_for_overlapping_fragments() -> None:
    import threading

    # 0 and 1 overlap; 2 overlaps neither and must run while 1 waits for 0 (a barrier of two
    # that 0 and 2 must reach together, or it times out); 3 overlaps 1 and 2.
    boxes = np.array([[0, 10, 0, 10], [5, 15, 5, 15], [20, 30, 20, 30], [12, 25, 12, 25]])
    barrier = threading.Barrier(2, timeout=10)
    events: list[tuple[str, int]] = []
    lock = threading.Lock()

    def work(j: int) -> None:
        with lock:
            events.append(("start", j))
        if j in (0, 2):
            barrier.wait()
        with lock:
            events.append(("end", j))

    calls: list[tuple[int, int]] = []
    _in_order(boxes, work, workers=2, progress=lambda d, t: calls.append((d, t)))
    pos = {e: i for i, e in enumerate(events)}
    for i, j in ((0, 1), (1, 3), (2, 3)):
        assert pos[("end", i)] < pos[("start", j)], events
    assert calls == [(1, 5), (2, 5), (3, 5), (4, 5)]

    def fail(j: int) -> None:
        if j == 2:
            raise ValueError("fragment 2")

    with pytest.raises(ValueError, match="fragment 2"):
        _in_order(boxes, fail, workers=2, progress=None)


def test_progress_reports_every_fragment() -> None:
    img, sk = channel_scene()
    calls: list[tuple[int, int]] = []
    res = render(img, sk, sk, seed=0, complete=False, full_output=True, progress=lambda d, t: calls.append((d, t)))
    total = len(res.targets) + 1
    assert calls[-1] == (total, total) and all(t == total for _, t in calls)
    assert [d for d, _ in calls] == sorted(d for d, _ in calls) and len(calls) == total


def test_stages_can_be_switched_off() -> None:
    img, sk = channel_scene()
    plain = render(img, sk, sk, seed=0, deform=False, photometric=False, seams=False, complete=False)
    assert plain.shape == (128, 224)
    assert np.isfinite(plain).all()


def test_two_level_is_95_percent_of_pixels_at_a_channel_extreme_in_every_channel() -> None:
    rng = np.random.default_rng(0)
    for c in (1, 3, 5):
        for off in (0.0, 0.03, 0.049, 0.051, 0.2):
            # Two blocks: the off-level pixels fall mostly inside them, not on the edge between
            # them, where a soft mask (below) would have its in-between values.
            img = np.zeros((60, 50, c), np.float32)
            img[:, 25:] = 1.0
            # Off-level pixels in the last channel only: the channel-by-channel exit must reach it.
            k = round(off * 60 * 50)
            img.reshape(-1, c)[rng.permutation(60 * 50)[:k], c - 1] = 0.5
            lo, hi = _channel_range(img)
            direct = float(((img == lo) | (img == hi)).all(axis=2).mean()) >= 0.95
            assert two_level(img, lo, hi) == direct == (off < 0.05), (c, off)


def test_a_soft_mask_is_two_level_and_renders_as_one() -> None:
    # issue 19: a venation mask scaled and saved as a JPEG has grey edges and noisy levels; it
    # was taken for a photo, and its output had grey fringes and a grey haze.
    rng = np.random.default_rng(1)
    _, sk = channel_scene()
    sharp = sk.mask().astype(np.float32)
    soft = cv2.GaussianBlur(sharp, (0, 0), 1.0)
    soft = np.clip(soft + rng.normal(0, 0.02, soft.shape) * (np.abs(soft - 0.5) > 0.45), 0, 1).astype(np.float32)
    lo, hi = _channel_range(soft[..., None])
    assert not float(((soft == lo) | (soft == hi)).mean()) >= 0.95  # not by the exact rule
    assert two_level(soft[..., None], lo, hi)
    tgt = Skeleton([wavy_branch((20, 30), 0.2, 150, (4.0, 3.0), phase=2.0)], (80, 180))
    out = render(soft, sk, tgt, seed=0)
    assert set(np.unique(out).tolist()) <= {float(lo[0]), float(hi[0])}
    # a thin bright line in a wide glow on a black sky is a photo: its glow is not an edge
    sky = np.zeros((100, 140), np.float32)
    cv2.line(sky, (10, 50), (130, 40), 1.0, 2)
    glow = np.clip(sky + 0.6 * cv2.GaussianBlur(sky, (0, 0), 6.0) / cv2.GaussianBlur(sky, (0, 0), 6.0).max(), 0, 1)
    lo, hi = _channel_range(glow[..., None])
    assert not two_level(glow[..., None].astype(np.float32), lo, hi)


def test_a_mask_with_channels_thinner_than_a_pixel_is_two_level_and_synthesizes_as_one() -> None:
    # A delta's mask scaled down (a screenshot of one, held out): its fine distributaries become
    # grey lines with no pixel at the water's level, and a sixth of its pixels lie between the
    # levels. It was taken for a photo, and its output was a grey haze.
    from phloem.branching import synthesize

    rng = np.random.default_rng(3)
    big = np.zeros((480, 640), np.uint8)
    cv2.line(big, (0, 400), (640, 80), 255, 40)
    for _ in range(70):
        x0, y0, a = int(rng.integers(0, 640)), int(rng.integers(0, 480)), rng.uniform(0, np.pi)
        end = (int(x0 + 200 * np.cos(a)), int(y0 + 200 * np.sin(a)))
        cv2.line(big, (x0, y0), end, 255, int(rng.integers(1, 4)))
    small = cv2.resize(big.astype(np.float32) / 255, (160, 120), interpolation=cv2.INTER_AREA)
    lo, hi = _channel_range(small[..., None])
    assert float(((small > 0.1) & (small < 0.9)).mean()) > 0.15
    assert two_level(small[..., None], lo, hi)
    out = synthesize(small, seed=0).image
    assert set(np.unique(out).tolist()) <= {float(lo[0]), float(hi[0])}


def test_branch_map_is_each_branch_drawn_over_the_earlier_ones() -> None:
    """The map drawn in each branch's box equals drawing every branch on the whole image."""
    main = wavy_branch((3, 40), 0.1, 150, (9.0, 4.0), amp=0.5)
    child = wavy_branch(tuple(main.points[30]), 1.2, 50, (4.0, 2.0), parent=(0, 30))
    edge = Branch([[-0.4, -0.4], [80, 0.3], [159.4, 99.4]], [7.0, 2.0, 12.0], parent=(0, 5))
    sk = Skeleton([main, child, edge], (100, 160))
    want = np.full((100, 160), -1, np.int32)
    for i, b in enumerate(sk.branches):
        m = np.zeros((100, 160), np.uint8)
        for a, bb, r0, r1 in zip(b.points[:-1], b.points[1:], b.thickness[:-1], b.thickness[1:], strict=True):
            t = round(2 * (max(0.5 * (r0 + r1), 0.5) + 2.0))
            cv2.line(m, _pt(a), _pt(bb), 1, thickness=t, lineType=cv2.LINE_8, shift=4)
        want[m > 0] = i
    got = _branch_map(sk, (100, 160))
    assert (got >= 0).sum() > 3000
    np.testing.assert_array_equal(got, want)


def _field(shape: tuple[int, int], q: np.ndarray, d: np.ndarray, radius: float) -> tuple[np.ndarray, float]:
    """The deformation alone: ``fragment_maps`` with no rigid motion, less each pixel's own position."""
    mx, my, alpha = _core.fragment_maps(np.ones(shape, bool), (0, 0), (0.0, 0.0), q, d, radius, np.eye(2), (0.0, 0.0))
    gy, gx = np.mgrid[: shape[0], : shape[1]]
    return np.stack([mx - gx, my - gy], axis=-1) / max(alpha, 1e-12), alpha


def test_displacement_field_hits_its_constraints() -> None:
    """The §5.3 field over a fragment's crop: at full resolution (radius ≤ 8) it takes the
    given displacements at the skeleton samples and is smooth between them; on the coarsened
    grid of a large fragment a constant displacement stays exactly constant."""
    rng = np.random.default_rng(1)
    q = np.stack([np.linspace(2, 14, 7), 8 + 2 * np.sin(np.linspace(0, 3, 7))], axis=1)  # (x, y)
    d = rng.normal(size=(7, 2)) * 0.3
    field, alpha = _field((17, 17), q, d, 8.0)
    assert alpha == 1.0
    r, c = np.round(q[:, 1]).astype(int), np.round(q[:, 0]).astype(int)
    assert np.allclose(field[r, c], d, atol=1e-4)
    assert np.abs(np.diff(field, axis=0)).max() < 2 * np.abs(d).max()
    const, alpha = _field((135, 135), q * 8, np.tile([[3.0, -1.5]], (7, 1)), 67.0)
    assert alpha == 1.0
    assert np.allclose(const, [3.0, -1.5], atol=1e-4)


def _reference_maps(
    disk: np.ndarray, y0: int, x0: int, centre: tuple[float, float], q_abs: np.ndarray, d: np.ndarray, r: float,
    rigid: np.ndarray, source_centre: tuple[float, float],
) -> tuple[np.ndarray, np.ndarray, float]:  # fmt: skip
    """NumPy and OpenCV version of ``fragment_maps`` (the render's own before the core did it)."""
    h, w = disk.shape
    f = max(1, int(np.ceil(r / 8)))
    ch, cw = max(2, -(-h // f)), max(2, -(-w // f))
    rows = np.clip(np.round((q_abs[:, 1] - y0) / f).astype(np.int64), 0, ch - 1)
    cols = np.clip(np.round((q_abs[:, 0] - x0) / f).astype(np.int64), 0, cw - 1)
    uniq, inv = np.unique(rows * cw + cols, return_inverse=True)
    vals = np.zeros((len(uniq), 2))
    np.add.at(vals, inv, d)
    vals /= np.bincount(inv, minlength=len(uniq))[:, None]
    coarse = interpolate_field(np.ones((ch, cw), bool), np.stack([uniq // cw, uniq % cw], axis=1), vals, threads=1)
    if f == 1:
        field = coarse[:h, :w]
    else:
        # exact bilinear weights (OpenCV's remap rounds positions to 1/32 of a cell), held beyond the last cell
        at = np.mgrid[:h, :w].astype(np.float64) / f
        field = np.stack([map_coordinates(coarse[..., k], at, order=1, mode="nearest") for k in (0, 1)], axis=-1)
    ux, uy = np.gradient(field[..., 0], axis=1), np.gradient(field[..., 0], axis=0)
    vx, vy = np.gradient(field[..., 1], axis=1), np.gradient(field[..., 1], axis=0)
    a1, a2 = (ux + vy)[disk], (ux * vy - uy * vx)[disk]
    alpha = next((a for a in (1.0, 0.75, 0.5, 0.25) if float((1 + a * a1 + a * a * a2).min()) >= 0.5), 0.0)
    gy, gx = np.mgrid[y0 : y0 + h, x0 : x0 + w].astype(np.float64)
    px = gx - centre[0] + alpha * field[..., 0]
    py = gy - centre[1] + alpha * field[..., 1]
    mapx = rigid[0, 0] * px + rigid[0, 1] * py + source_centre[0]
    mapy = rigid[1, 0] * px + rigid[1, 1] * py + source_centre[1]
    return mapx, mapy, alpha


@pytest.mark.parametrize("radius", [6.0, 23.0, 67.0])
def test_fragment_maps_agree_with_a_numpy_reference(radius: float) -> None:
    """The core's maps against the NumPy reference over fragments whose skeletons are bent by
    small fields and by fields that fold (scaled down), rotated and moved: the same scale and
    the same source positions, and a map that never folds over the disk."""
    rng = np.random.default_rng(int(radius))
    n = int(2 * radius) + 1
    yy, xx = np.mgrid[:n, :n]
    disk = (xx - radius) ** 2 + (yy - radius) ** 2 <= radius**2
    y0, x0 = 40, 70
    centre = (x0 + radius, y0 + radius)
    for trial in range(8):
        t = np.linspace(-0.9, 0.9, 12) * radius
        q = np.stack([centre[0] + t, centre[1] + 0.2 * radius * np.sin(t / radius * 3 + trial)], axis=1)
        scale = (0.05, 0.3, 1.0, 2.0)[trial % 4] * radius
        d = rng.normal(size=q.shape) * scale / 4
        a = rng.uniform(-np.pi, np.pi)
        rigid = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        src = (rng.uniform(0, 300), rng.uniform(0, 300))
        mx, my, alpha = _core.fragment_maps(disk, (y0, x0), centre, q, d, radius, rigid, src)
        rx, ry, ralpha = _reference_maps(disk, y0, x0, centre, q, d, radius, rigid, src)
        assert alpha == ralpha
        assert np.abs(mx - rx).max() < 1e-3 and np.abs(my - ry).max() < 1e-3, (trial, np.abs(mx - rx).max())
        # The rigid part is a rotation, so the map's Jacobian determinant is the scaled field's:
        # at least the guard's 1/2 everywhere on the disk, which the largest fields only keep scaled down.
        det = np.gradient(mx, axis=1) * np.gradient(my, axis=0) - np.gradient(mx, axis=0) * np.gradient(my, axis=1)
        assert float(det[disk].min()) > 0.5 - 1e-3, (trial, alpha, float(det[disk].min()))
        if trial % 4 == 3:
            assert alpha < 1.0, (trial, alpha)


def test_fragment_maps_refuse_bad_input() -> None:
    disk = np.ones((9, 9), bool)
    q = np.array([[4.0, 4.0], [5.0, 4.0]])
    with pytest.raises(ValueError, match="^displacement:"):
        _core.fragment_maps(disk, (0, 0), (4.0, 4.0), q, q[:1], 4.0, np.eye(2), (4.0, 4.0))
    with pytest.raises(ValueError, match="^points:"):
        _core.fragment_maps(disk, (0, 0), (4.0, 4.0), q, np.full((2, 2), np.nan), 4.0, np.eye(2), (4.0, 4.0))
    with pytest.raises(ValueError, match="^rigid:"):
        _core.fragment_maps(disk, (0, 0), (4.0, 4.0), q, q, 4.0, np.eye(3), (4.0, 4.0))


def test_bad_inputs_name_the_argument() -> None:
    img, sk = channel_scene()
    with pytest.raises(ValueError, match="source_skeleton.*outside"):
        render(img[:50], sk, sk)
    with pytest.raises(ValueError, match="source_skeleton: the skeleton has no branches"):
        render(img, Skeleton([], (128, 224)), sk)
    with pytest.raises(ValueError, match="target_skeleton: its shape"):
        render(img, sk, Skeleton(sk.branches))
    bad = Skeleton([Branch([[1, 1], [5, 5]], 1.0)], (10, 10))
    bad.branches[0].points[1, 0] = np.nan
    with pytest.raises(ValueError, match="target_skeleton: branches\\[0\\] has NaN"):
        render(img, sk, bad)
    with pytest.raises(ValueError, match="image"):
        render(np.zeros((2, 3, 4, 5)), sk, sk)
    with pytest.raises(ValueError, match="image: expected finite"):
        render(np.full((128, 224), np.nan), sk, sk)
    with pytest.raises(TypeError, match="target_skeleton"):
        render(img, sk, [[0, 0], [1, 1]])  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="n_best:"):
        render(img, sk, sk, n_best=0)
    with pytest.raises(ValueError, match="^gap_diversity: expected a finite value >= 0"):
        render(img, sk, sk, gap_diversity=-1.0)


def test_sub_branches_connect_to_their_parent() -> None:
    """Fig. 6: a sub-branch must run into its parent, not stop short at the banks the parent's
    fragments painted (before the fix, two of these four stopped short: 0.72 and 0.68)."""
    rng = np.random.default_rng(0)
    main = wavy_branch((8, 90), 0.05, 300, (7.0, 5.0), phase=1.0)
    kids = [wavy_branch(tuple(main.points[50]), 0.8, 90, (4.0, 3.0), amp=0.2, parent=(0, 50))]
    kids.append(wavy_branch(tuple(main.points[75]), -0.9, 70, (4.0, 3.0), amp=0.2, parent=(0, 75)))
    sk = Skeleton([main, *kids], (180, 320))
    tex = cv2.GaussianBlur(rng.normal(size=sk.shape).astype(np.float32), (0, 0), 1.0)
    img = np.clip(np.where(sk.mask(), 0.15 + 0.05 * tex, 0.7 + 0.1 * tex), 0, 1).astype(np.float32)
    main2 = wavy_branch((10, 90), -0.05, 280, (7.0, 5.0), phase=2.0, amp=0.2)
    for v, ang in ((25, -1.0), (40, 1.2), (30, -0.5), (50, 0.6)):
        child = wavy_branch(tuple(main2.points[v]), ang, 70, (4.0, 3.0), amp=0.1, parent=(0, v))
        out = render(img, sk, Skeleton([main2, child], (180, 320)), seed=1, complete=False)
        # The child's first three fragment radii, from the furcation outwards, must be dark.
        s = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(child.points, axis=0), axis=1))])
        pts = child.points[s < 3 * 3 * child.thickness[0]]
        vals = out[np.round(pts[:, 1]).astype(int), np.round(pts[:, 0]).astype(int)]
        assert float(vals.max()) < 0.35, (v, ang, vals.round(2))


@pytest.mark.shared
def test_real_river_channel_along_a_rotated_skeleton() -> None:
    """Colville delta water mask (RivGraph): one channel, traced automatically, painted along
    the same channel turned by 180°: the channel must stay water along its whole length."""
    m = phloem.io.read_image(shared_file("branching", "rivgraph_colville_delta_mask.png"))
    water = (m[..., 0] if m.ndim == 3 else m) > 0.5
    y0, y1, x0, x1 = 540, 1000, 280, 420
    _, lab, stats, _ = cv2.connectedComponentsWithStats(water[y0:y1, x0:x1].astype(np.uint8), connectivity=8)
    big = lab == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    path = longest_path(big)[::6]
    thick = cv2.distanceTransform(big.astype(np.uint8), cv2.DIST_L2, 5)[path[:, 0].astype(int), path[:, 1].astype(int)]
    xy = path[:, ::-1] + [x0, y0]
    assert len(xy) > 50
    src = Skeleton([Branch(xy, thick)], water.shape)
    tgt = Skeleton([Branch(2 * xy.mean(axis=0) - xy, thick)], water.shape)
    out = render(m, src, tgt, seed=0, complete=False)
    out = out[..., 0] if out.ndim == 3 else out
    tm = tgt.mask()
    core = tm & (cv2.distanceTransform(tm.astype(np.uint8), cv2.DIST_L2, 3) > 2)
    assert core.sum() > 3000
    assert float(np.mean(out[core] > 0.5)) > 0.95


def test_fragments_in_unusual_surroundings_are_left_out() -> None:
    # A dark vessel across a grey photo, through a bright disc (an optic disc) and a band lit
    # from one side (a fundus rim's shading): only the fragments there are outliers.
    from phloem.branching.fragments import cover
    from phloem.branching.render import _unusual_surroundings

    rng = np.random.default_rng(0)
    img = 0.5 + 0.01 * rng.standard_normal((120, 600)).astype(np.float32)
    yy, xx = np.mgrid[:120, :600]
    disc = (xx - 480) ** 2 + (yy - 60) ** 2 <= 40**2
    img[disc] = 0.9
    lit = (xx >= 200) & (xx < 280)
    img[lit] += (0.004 * (yy - 60))[lit]  # 0.2 of brightness across the band's fragments
    img[57:64] = 0.2
    sk = Skeleton([Branch([[5, 60], [595, 60]], 3.0)], (120, 600))
    frs = cover(sk, 0.75, 3.0, 16, order=False)
    img = img[..., None]
    span = _channel_range(img)
    out = _unusual_surroundings(img, span, sk, frs, np.zeros(len(frs), bool), keep=3)
    x = np.array([f.center[0] for f in frs])
    r = np.array([f.radius for f in frs])
    touches = ((x + r > 440) & (x - r < 520)) | ((x + r > 200) & (x - r < 280))
    inside = ((x - r >= 440) & (x + r <= 520)) | ((x - r >= 200) & (x + r <= 280))
    assert out[inside].all() and inside.sum() >= 8
    assert not out[~touches].any()
    # never all of them: with too few left, none is left out
    assert not _unusual_surroundings(img, span, sk, frs, ~inside, keep=3).any()


def _blur_scene() -> tuple[np.ndarray, Skeleton]:
    """Two crisp dark lines that wave, and a straight one out of focus (a dish's blurred rim
    beside the vessels, blurred little enough that its surroundings stay usual), all traced
    2.5 px thick."""
    rng = np.random.default_rng(0)
    img = 0.5 + 0.01 * rng.standard_normal((220, 400)).astype(np.float32)
    x = np.arange(10.0, 391.0, 2.0)
    branches = []
    for y0 in (40.0, 100.0):
        pts = np.stack([x, y0 + 8.0 * np.sin(x / 8.0)], axis=1)
        cv2.polylines(img, [np.rint(pts * 16).astype(np.int32)], False, 0.2, 5, cv2.LINE_AA, shift=4)
        branches.append(Branch(pts, 2.5))
    band = img[140:200].copy()
    cv2.line(band, (10, 30), (390, 30), 0.2, 5, cv2.LINE_AA)
    img[140:200] = cv2.GaussianBlur(band, (0, 0), 1.5)
    branches.append(Branch([[10.0, 170.0], [390.0, 170.0]], 2.5))
    return img, Skeleton(branches, img.shape)


def test_fragments_of_blurred_structure_are_left_out() -> None:
    from phloem.branching.fragments import cover
    from phloem.branching.render import _blurred_structure

    img, sk = _blur_scene()
    frs = cover(sk, 0.75, 3.0, 9, order=False)
    blurred = np.array([f.branch == 2 for f in frs])
    out = _blurred_structure(img[..., None], frs, np.zeros(len(frs), bool), keep=3)
    assert blurred.sum() >= 8
    np.testing.assert_array_equal(out, blurred)
    # never all of them: with too few left, none is left out
    assert not _blurred_structure(img[..., None], frs, ~blurred, keep=3).any()


def test_a_straight_target_is_not_painted_from_blurred_structure() -> None:
    # The blurred line is the best shape for a straight target, as the brain's dish rim was for
    # its grown trunk, which it painted as smears (docs/pipelines/branching/quality.md).
    img, sk = _blur_scene()
    tgt = Skeleton([Branch([[20.0, 60.0], [380.0, 60.0]], 2.5)], img.shape)
    res = render(img, sk, tgt, seed=0, full_output=True, complete=False)
    used = {res.sources[c].branch for c in res.choice}
    assert used and 2 not in used


def _rim_scene(start_thickness: float) -> tuple[np.ndarray, Skeleton, Skeleton, np.ndarray]:
    """A grey photo with a flat black frame along its left side, a vessel that starts 11 px from
    the frame and one that starts in the middle ``start_thickness`` thick; the target is one
    vessel starting in the middle, 3 px thick as the first."""
    rng = np.random.default_rng(0)
    img = 0.5 + 0.01 * rng.standard_normal((160, 300)).astype(np.float32)
    img[:, :20] = 0.0
    valid = np.ones(img.shape, bool)
    valid[:, :20] = False
    by_frame = Branch([[31, 50], [160, 50]], 3.0)
    inside = Branch([[150, 120], [290, 120]], [start_thickness, 3.0])
    for y, x0, x1 in ((50, 31, 160), (120, 150, 290)):
        img[y - 2 : y + 3, x0:x1] -= 0.3
    tgt = Skeleton([Branch([[150, 40], [280, 40]], 3.0)], img.shape)
    return img, Skeleton([by_frame, inside], img.shape), tgt, valid


def test_a_branch_start_away_from_the_frame_is_not_painted_from_beside_it() -> None:
    # A fundus photo's vessels end at its rim, and a source fragment there carries the rim's
    # shading: pasted at a target branch start in the middle of the disc, it stamped the
    # rim there. The best-shaped start (11 px from the frame, radius 9) is left to targets by
    # their own frame; the start in the middle, a worse shape, paints the target's start.
    img, sk, tgt, valid = _rim_scene(4.0)
    res = render(img, sk, tgt, seed=0, valid=valid, full_output=True)
    assert res.targets[0].arc == 0.0
    np.testing.assert_allclose(res.sources[res.choice[0]].center, [150.0, 120.0])
    # without a frame the same source is the best start (the shape term alone decides)
    free = render(img, sk, tgt, seed=0, full_output=True)
    np.testing.assert_allclose(free.sources[free.choice[0]].center, [31.0, 50.0])
    # a target start by its own frame may take it
    by_frame = Skeleton([Branch([[31, 100], [160, 100]], 3.0)], img.shape)
    res = render(img, sk, by_frame, seed=0, valid=valid, full_output=True)
    np.testing.assert_allclose(res.sources[res.choice[0]].center, [31.0, 50.0])


def test_a_frame_along_less_than_a_sixth_of_the_border_is_not_kept() -> None:
    img, sk = channel_scene()
    img = img.copy()
    img[-30:, :60] = 0.0  # a flat patch in a corner: 90 of the border's 700 px, under a sixth
    valid = np.ones(img.shape[:2], bool)
    valid[-30:, :60] = False
    tgt = Skeleton([wavy_branch((20, 40), 0.2, 160, (4.0, 3.0), phase=2.0)], img.shape[:2])
    out = render(img, sk, tgt, seed=1, valid=valid)
    assert float(out[-30:, :60].min()) > 0.3  # filled from the picture, not kept
    img[-30:, :120] = 0.0  # along 150 px of the border: kept
    valid[-30:, :120] = False
    out = render(img, sk, tgt, seed=1, valid=valid)
    assert np.all(out[-25:, :115] == 0.0)


def _vessel_ending_in_a_tangle() -> tuple[np.ndarray, Skeleton]:
    """A dark vessel 3 px in radius across a light 120 x 160 field, and at each of its ends,
    8-10 px past it, thin dark strokes the skeleton does not hold (finer vessels, as where a
    traced vessel dissolves into a tangle). The field is lit unevenly, as a photo's is: a flat
    one would make the picture a drawing in three tones, which reads as a soft mask."""
    img = np.broadcast_to(np.linspace(0.7, 0.9, 160, dtype=np.float32), (120, 160)).copy()
    cv2.line(img, (20, 60), (110, 60), 0.15, 6)
    for x in (10, 120):  # a bar across each end, and a stroke slanting off it
        cv2.line(img, (x, 50), (x, 70), 0.2, 2)
        cv2.line(img, (x, 60), (x + (6 if x > 60 else -6), 52), 0.2, 1)
    img += np.random.default_rng(0).normal(0.0, 0.01, img.shape).astype(np.float32)
    sk = Skeleton([Branch(np.array([[20.0 + 2 * i, 60.0] for i in range(46)]), 3.0)], img.shape)
    return img, sk


@pytest.mark.parametrize("seed", [0, 1])
def test_a_branch_end_paints_no_structure_past_it(seed: int) -> None:
    # issue 19: an end fragment is taken from a source branch's end, and what lies past that
    # end is whatever stopped the trace (on the mouse brain, a tangle of finer vessels). Pasted
    # whole at a target's tip, where the target has nothing, it stamped a star there.
    img, sk = _vessel_ending_in_a_tangle()
    tgt = Skeleton([Branch(np.array([[40.0 + 2 * i, 40.0] for i in range(31)]), 3.0)], img.shape)
    res = render(img, sk, tgt, seed=seed, full_output=True)
    yy, xx = np.mgrid[: img.shape[0], : img.shape[1]]
    for tip in ((100, 40), (40, 40)):
        d = np.hypot(xx - tip[0], yy - tip[1])
        past = (d > 3.0 * 1.5 + 2.0 + 1.0) & (d <= 9.0) & (np.abs(xx - 70) > 30)
        # the end fragment leaves everything past the branch's tube to the gap completion
        assert not (res.labels[past] >= 0).any()
        # which fills it with the field, not with the strokes past the source's end
        assert float(res.image[past].min()) > 0.55, (tip, float(res.image[past].min()))
    # and the vessel itself is painted to its ends
    assert float(res.image[40, 42:99].max()) < 0.4
