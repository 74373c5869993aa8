"""The gaps between the branches (Sibbing et al. 2010, §5.4): the gradient-domain paste against the structure."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phloem.branching import Branch, Skeleton
from phloem.branching.gaps import (
    _complete_background,
    _layout,
    _match_borders,
    _nearest_structure,
    _proximity_profile,
    _recolour,
    _relight,
    fill_gaps,
)


def _texture(shape: tuple[int, int], seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (0.5 + 0.1 * cv2.GaussianBlur(rng.normal(size=shape).astype(np.float32), (0, 0), 2.0) / 0.15)[..., None]


def test_match_borders_removes_a_lighting_step_and_keeps_the_gaps_gradients() -> None:
    # Structure on the left, 0.1 brighter than the completion that continues its texture on
    # the right: the Poisson solution with the step as Dirichlet data on one side and free
    # borders elsewhere is the texture plus the constant 0.1.
    tex = _texture((80, 90), 0)
    hole = np.zeros((80, 90), bool)
    hole[:, 20:] = True
    canvas = np.where(hole[..., None], tex, tex + 0.1).astype(np.float32)
    out = _match_borders(canvas, hole, np.float32([-1.0]), np.float32([2.0]), radius=10.0, threads=1)
    assert np.array_equal(out[~hole], canvas[~hole])
    corr = (out - canvas)[..., 0][hole]
    assert abs(float(corr.mean()) - 0.1) < 0.005 and float(np.abs(corr - 0.1).max()) < 0.01


def test_match_borders_leaves_content_steps_alone() -> None:
    # A white branch cut off at the structure's edge (rows 35-44) is content, not lighting:
    # away from it the dark completion must not be brightened. A border that is all large
    # steps (a white structure) gets no correction at all.
    hole = np.zeros((80, 90), bool)
    hole[:, 20:] = True
    canvas = np.zeros((80, 90, 1), np.float32)
    canvas[35:45, :20] = 1.0
    lo, hi = np.float32([0.0]), np.float32([1.0])
    out = _match_borders(canvas, hole, lo, hi, radius=10.0, threads=1)
    far = hole.copy()
    far[25:55, :40] = False
    assert float(np.abs(out[far]).max()) < 0.02
    white = np.where(hole[..., None], 0.0, 1.0).astype(np.float32)
    assert np.array_equal(_match_borders(white, hole, lo, hi, radius=10.0, threads=1), white)


def test_gaps_of_a_field_keep_its_large_scale_layout() -> None:
    # A field rising from 0.2 to 0.8 across, faint texture on it, one dark valley along the
    # middle; only a strip of the canvas is painted. The completed gaps rise as the field
    # does (§5.4's patches alone settle on one level across such large gaps).
    rng = np.random.default_rng(1)
    H, W = 120, 240
    tex = cv2.GaussianBlur(rng.normal(size=(H, W)).astype(np.float32), (0, 0), 1.5)
    ramp = np.linspace(0.2, 0.8, W, dtype=np.float32)[None, :]
    image = (ramp + 0.03 * tex)[..., None].astype(np.float32)
    image[55:66] -= 0.15
    valley = Skeleton([Branch([[0, 60], [239, 60]], 3.0)], (H, W))
    filled = np.zeros((H, W), bool)
    filled[:, 110:130] = True
    canvas = np.where(filled[..., None], image, 0.0).astype(np.float32)
    lo, hi = image.reshape(-1, 1).min(0), image.reshape(-1, 1).max(0)
    out = fill_gaps(
        canvas, filled, image, valley, valid=None, radius_factor=3.0, radius=3.0, lo=lo, hi=hi,
        match_borders=False, photometric=False, patch_size=7, iterations=4, seed=0, threads=1,
    )  # fmt: skip
    assert np.array_equal(out[filled], image[filled])
    rise = float(out[:, -60:].mean() - out[:, :60].mean())
    assert 0.3 < rise < 0.5  # the field's outer quarters differ by 0.45


def test_the_layout_keeps_the_backgrounds_edges_and_not_its_detail() -> None:
    # A background dark on the left and bright on the right (a scarp, a macula's rim) with
    # grain and a thin dark pole on it, and a vessel band the layout must not see. At 10 px
    # from the step the layout keeps most of it, where a Gaussian of the same scale keeps a
    # quarter; the grain and the pole leave no trace.
    rng = np.random.default_rng(2)
    H, W = 160, 240
    step = np.where(np.arange(W) < 120, 0.3, 0.7).astype(np.float32)[None, :] * np.ones((H, 1), np.float32)
    grain = 0.03 * cv2.GaussianBlur(rng.normal(size=(H, W)).astype(np.float32), (0, 0), 1.0) / 0.28
    image = (step + grain)[..., None].astype(np.float32)
    image[:, 60:62] -= 0.3  # the pole
    allowed = np.ones((H, W), bool)
    allowed[75:86] = False  # the structure's band
    image[75:86] = 0.0
    lay = _layout(image, allowed, 40.0, (H, W))[..., 0]
    gauss = cv2.GaussianBlur(step, (0, 0), 40.0)
    assert float(gauss[:, 130].mean() - gauss[:, 109].mean()) < 0.1  # of the 0.4 step
    assert float(lay[:, 130].mean() - lay[:, 109].mean()) > 0.3
    outside = np.ones(H, bool)
    outside[55:106] = False  # (the band and the reach of its smoother layout)
    assert float(np.abs(lay[outside, :90] - 0.3).max()) < 0.02  # no grain, no pole
    assert float(np.abs(lay[outside, 150:] - 0.7).max()) < 0.02
    assert float(np.abs(lay[75:86, :80] - 0.3).max()) < 0.02  # the band from its surroundings


def test_relight_moves_brightness_and_not_hue() -> None:
    # A backdrop red on the left and blue on the right, equally bright, then dark on the left
    # and bright on the right: the gaps of a uniform canvas take the second layout's
    # brightness, the same shift in every channel (keeping their own hue), and nothing of the
    # first one's hue.
    H, W = 60, 200
    hole = np.zeros((H, W), bool)
    hole[2:-2, 2:-2] = True
    canvas = np.ones((H, W, 3), np.float32) * np.float32([0.5, 0.3, 0.2])  # as bright as both layouts' mean
    allowed = np.ones((H, W), bool)
    left = np.arange(W) < W // 2
    hue = np.where(left[None, :, None], [0.6, 0.2, 0.2], [0.2, 0.2, 0.6]).astype(np.float32) * np.ones((H, 1, 1))
    out = _relight(canvas, hole, hue.astype(np.float32), allowed, sigma=8.0)
    assert float(np.abs(out - canvas).max()) < 1e-5
    light = np.where(left[None, :, None], 0.2, 0.6).astype(np.float32) * np.ones((H, 1, 3), np.float32)
    out = _relight(canvas, hole, light, allowed, sigma=8.0)
    assert np.array_equal(out[~hole], canvas[~hole])
    shift = (out - canvas)[hole]
    assert float(np.ptp(shift, axis=1).max()) < 1e-6  # one shift for all channels
    inner = out[10:-10]
    assert abs(float(inner[:, 10:40].mean()) - 0.2) < 0.01 and abs(float(inner[:, -40:-10].mean()) - 0.6) < 0.01


def test_recolour_gives_the_gaps_the_backgrounds_colour_cast_and_keeps_their_brightness() -> None:
    # Soil that is red but for a blue backdrop in a fifth of it, and gaps filled from a grey
    # patch of it (a completion settled on a few patches): the gaps take the soil's colour cast,
    # not the backdrop's, and every pixel keeps its brightness and its grain.
    rng = np.random.default_rng(3)
    H, W = 60, 100
    source = np.empty((H, W, 3), np.float32)
    source[:] = [0.45, 0.28, 0.27]
    source[:, :20] = [0.2, 0.3, 0.6]
    source += 0.03 * rng.normal(size=(H, W, 1)).astype(np.float32)
    allowed = np.ones((H, W), bool)
    hole = np.zeros((H, W), bool)
    hole[5:55, 30:90] = True
    canvas = (np.float32([0.33, 0.33, 0.34]) + 0.03 * rng.normal(size=(H, W, 1))).astype(np.float32)
    out = _recolour(canvas, hole, source, allowed)
    assert np.array_equal(out[~hole], canvas[~hole])
    np.testing.assert_allclose(out[hole].mean(axis=1), canvas[hole].mean(axis=1), atol=1e-6)
    np.testing.assert_allclose(np.ptp(out[hole] - canvas[hole], axis=0), 0.0, atol=1e-6)  # one shift per channel
    cast = np.median(out[hole], axis=0) - np.median(out[hole], axis=0).mean()
    soil = np.float32([0.45, 0.28, 0.27]) - np.float32([0.45, 0.28, 0.27]).mean()
    np.testing.assert_allclose(cast, soil, atol=0.02)  # a mean would be 0.06 off, towards the backdrop
    gray = canvas[..., :1]
    assert np.array_equal(_recolour(gray, hole, source[..., :1], allowed), gray)  # one channel: no colour


def test_gap_diversity_keeps_more_of_the_backgrounds_grain() -> None:
    # A background whose grain grows from nothing (left) to strong (right): the plain fill of
    # the large gaps settles on the smoothest patches, the occurrence penalty keeps more grain.
    rng = np.random.default_rng(0)
    H, W = 96, 192
    grain = cv2.GaussianBlur(rng.normal(size=(H, W)).astype(np.float32), (0, 0), 0.8)
    image = (0.5 + grain * np.linspace(0.0, 0.15, W, dtype=np.float32)[None, :])[..., None].astype(np.float32)
    valley = Skeleton([Branch([[0, 48], [191, 48]], 2.0)], (H, W))
    filled = np.zeros((H, W), bool)
    filled[:, 90:102] = True
    canvas = np.where(filled[..., None], image, 0.0).astype(np.float32)
    lo, hi = image.reshape(-1, 1).min(0), image.reshape(-1, 1).max(0)
    gaps = ~filled
    gaps[:, 80:112] = False  # the gaps' interior, away from the painted strip

    def fine(diversity: float, seed: int) -> float:
        out = fill_gaps(
            canvas, filled, image, valley, valid=None, radius_factor=3.0, radius=3.0, lo=lo, hi=hi,
            match_borders=False, photometric=False, patch_size=7, iterations=4, seed=seed, threads=1,
            diversity=diversity,
        )  # fmt: skip
        return float((out[..., 0] - cv2.GaussianBlur(out[..., 0], (0, 0), 2.0))[gaps].std())

    for seed in range(3):
        assert fine(1.0, seed) > 1.2 * fine(0.0, seed)


def _crack_on_grain(grain_contrast: float) -> tuple[np.ndarray, Skeleton]:
    """A dark wavy crack across asphalt-like grain of ``grain_contrast`` (240x320), and its skeleton."""
    rng = np.random.default_rng(0)
    grain = cv2.GaussianBlur(rng.normal(0, 1, (240, 320)).astype(np.float32), (0, 0), 1.2)
    img = (0.55 + grain_contrast * grain / grain.std()).astype(np.float32)
    x = np.arange(10, 310, dtype=np.float64)
    pts = np.c_[x, 120 + 30 * np.sin(x / 50)]
    cv2.polylines(img, [np.round(pts).astype(np.int32)], False, 0.40, 2)
    return np.clip(img, 0, 1), Skeleton([Branch(pts, 1.0)], (240, 320))


def test_the_gaps_of_a_grainy_surface_get_the_spread_fill_by_default(monkeypatch: pytest.MonkeyPatch) -> None:
    from phloem.branching import gap_diversity_default, pipeline, render, synthesize, threshold_climb

    grainy, sk = _crack_on_grain(0.05)
    smooth, _ = _crack_on_grain(0.002)
    assert threshold_climb(grainy) > 1.0 and threshold_climb(smooth) == 1.0
    assert gap_diversity_default(grainy) == 1.0 and gap_diversity_default(smooth) == 0.0
    assert gap_diversity_default(grainy, gap_diversity=0.25) == 0.25  # the caller's value
    assert gap_diversity_default(grainy, trace_options={"kind": "mask", "gap": 3.0}) == 0.0
    # render's default is the resolved value: on grain the spread fill, elsewhere the plain one
    for img, value, other in ((grainy, 1.0, 0.0), (smooth, 0.0, 1.0)):
        auto = render(img, sk, sk, seed=0, threads=1)
        assert np.array_equal(auto, render(img, sk, sk, seed=0, threads=1, gap_diversity=value))
        assert not np.array_equal(auto, render(img, sk, sk, seed=0, threads=1, gap_diversity=other))
    # and synthesize resolves it with its trace options
    asked: list[dict[str, object]] = []

    def spy(*args: object, **kwargs: object) -> float:
        asked.append(kwargs)
        return gap_diversity_default(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(pipeline, "gap_diversity_default", spy)
    a = synthesize(grainy, seed=0, threads=1, trace_options={"kind": "dark"})
    assert [k["trace_options"] for k in asked] == [{"kind": "dark"}]
    b = synthesize(grainy, seed=0, threads=1, trace_options={"kind": "dark"}, render_options={"gap_diversity": 1.0})
    assert np.array_equal(a.image, b.image)


def test_completed_gaps_are_background_pixels_with_their_grain() -> None:
    # The gaps are filled with pixels of the input's background itself (the finest level
    # copies its field, no vote averages them), so a grainy background stays grainy.
    image = _texture((96, 160), 2)
    allowed = np.ones((96, 160), bool)
    allowed[:, 70:90] = False  # the structure, widened
    canvas = np.zeros((96, 160, 1), np.float32)
    hole = np.ones((96, 160), bool)
    hole[:, 75:85] = False
    canvas[~hole] = image[~hole]
    out = _complete_background(canvas, hole, image, allowed, patch_size=7, iterations=4, seed=0, threads=1)
    assert np.isin(out[hole], np.unique(image[allowed])).all()
    inner = cv2.erode(hole.astype(np.uint8), np.ones((11, 11), np.uint8)).astype(bool)

    def fine(a: np.ndarray, where: np.ndarray) -> float:
        return float((a[..., 0] - cv2.GaussianBlur(a[..., 0], (0, 0), 2.0))[where].std())

    assert fine(out, inner) > 0.7 * fine(image, allowed)


def test_gaps_get_the_grain_of_a_background_left_in_narrow_bands() -> None:
    # Dense structure (10 px of every 24) leaves the background in 14-px bands: too narrow for
    # a 7-px patch at the coarse levels of a large gap. Copying only the upsampled coarse
    # field filled the gap with one flat colour; the finest level's own search finds the bands.
    H, W = 120, 200
    allowed = np.ones((H, W), bool)
    for x in range(0, W, 24):
        allowed[:, x : x + 10] = False
    hole = np.ones((H, W), bool)
    hole[:, 96:104] = False
    for seed in range(3):
        rng = np.random.default_rng(seed)
        grain = cv2.GaussianBlur(rng.normal(size=(H, W)).astype(np.float32), (0, 0), 0.8)
        image = (0.5 + 0.1 * grain / 0.3)[..., None]
        canvas = np.where(hole[..., None], 0.0, image).astype(np.float32)
        out = _complete_background(canvas, hole, image, allowed, patch_size=7, iterations=4, seed=seed, threads=1)
        assert np.isin(out[hole], np.unique(image[allowed])).all()
        assert len(np.unique(out[hole])) > 500

        def fine(a: np.ndarray, where: np.ndarray) -> float:
            return float((a[..., 0] - cv2.GaussianBlur(a[..., 0], (0, 0), 2.0))[where].std())

        assert fine(out, hole) > 0.5 * fine(image, allowed)  # 0.6 here; the flat fill had 0


def test_gaps_with_diversity_copy_the_backgrounds_detail_under_its_layout() -> None:
    # A plateau (left, 0.8) and a lowland (right, 0.2) with the same grain, and a gap over
    # both. Blocks drawn from either side put lowland pieces on the plateau, a patchwork at the
    # scale of the blocks; the completion of the detail under the layout does not.
    H, W = 96, 192
    grain = 0.5 * (_texture((H, W), 4) - 0.5)
    layout = np.where(np.arange(W)[None, :] < W // 2, 0.8, 0.2).astype(np.float32)
    image = (cv2.GaussianBlur(layout, (0, 0), 4.0)[..., None] + grain).astype(np.float32)
    allowed = np.ones((H, W), bool)
    allowed[40:56] = False  # a valley, widened
    hole = allowed.copy()
    canvas = np.where(hole[..., None], 0.0, image).astype(np.float32)
    far = hole.copy()
    far[:, W // 2 - 24 : W // 2 + 24] = False  # away from the step between the two

    def off_layout(out: np.ndarray) -> float:
        # the brightness at the blocks' scale against the input's at the same place
        return float(np.abs(cv2.GaussianBlur(out[..., 0] - image[..., 0], (0, 0), 3.0))[far].mean())

    for seed in range(3):
        blocks = _complete_background(
            canvas, hole, image, allowed, patch_size=7, iterations=4, seed=seed, threads=1, diversity=1.0
        )
        detail = _complete_background(
            canvas, hole, image, allowed, patch_size=7, iterations=4, seed=seed, threads=1, diversity=1.0,
            detail_sigma=16.0,
        )  # fmt: skip
        assert off_layout(detail) < 0.1 < off_layout(blocks)


def test_gaps_with_diversity_leave_out_a_backdrop() -> None:
    # A leaf's green grain with a blue backdrop in one corner (a tenth of the image): a fill
    # spread over the whole background would copy blue pieces into the gaps; none may be there.
    H, W = 120, 160
    grain = 0.5 * (_texture((H, W), 5)[..., 0] - 0.5)
    image = np.stack([0.2 + grain, 0.55 + grain, 0.2 + grain], axis=2).astype(np.float32)
    image[:40, 112:] = np.float32([0.1, 0.2, 0.9]) + 0.5 * grain[:40, 112:, None]
    allowed = np.ones((H, W), bool)
    allowed[56:64] = False  # a vein, widened
    hole = allowed.copy()
    canvas = np.where(hole[..., None], 0.0, image).astype(np.float32)
    for seed in range(3):
        out = _complete_background(
            canvas, hole, image, allowed, patch_size=7, iterations=4, seed=seed, threads=1, diversity=1.0,
            detail_sigma=20.0,
        )  # fmt: skip
        blue = out[..., 2] > out[..., 1]
        assert not blue[hole].any()


def _around_a_line(light) -> tuple[np.ndarray, np.ndarray, tuple]:
    """A 200 x 240 image whose brightness is ``light(d)`` at distance ``d`` from a horizontal
    line across it, the pixels beyond 3 px as background, and the line's nearest-pixel maps."""
    sk = Skeleton([Branch([[0, 100], [239, 100]], 1.0)], (200, 240))
    near = _nearest_structure(sk, (200, 240))
    img = light(near[0].astype(np.float64)).astype(np.float32)[..., None]
    return img, near[0] > 3, near


def test_proximity_profile_falls_off_away_from_the_structure() -> None:
    # a glow that falls off, with a brighter band farther out (a neighbour's light, a ridge)
    img, allowed, near = _around_a_line(lambda d: 0.3 + 0.2 * np.exp(-d / 5) + 0.1 * ((d > 15) & (d < 21)))
    centres, prof = _proximity_profile(img, allowed, near, reach=30.0)
    assert (np.diff(prof) <= 1e-12).all() and (prof >= 0).all()
    # near the line it is the glow over the ring at 30-45 px
    k = int(np.searchsorted(centres, 7.0))
    assert prof[k] == pytest.approx(0.2 * np.exp(-centres[k] / 5), abs=0.02)
    # a terrain: flat by the valley, the next ridge farther out: no glow at all, so no rings
    img, allowed, near = _around_a_line(lambda d: 0.3 + 0.1 * ((d > 12) & (d < 20)))
    _, prof = _proximity_profile(img, allowed, near, reach=30.0)
    assert not prof.any()
    # a shadow keeps its sign; a brighter band beyond it does not flip it
    img, allowed, near = _around_a_line(lambda d: 0.5 - 0.2 * np.exp(-d / 5) + 0.1 * ((d > 15) & (d < 21)))
    _, prof = _proximity_profile(img, allowed, near, reach=30.0)
    assert prof.min() < -0.05 and (prof <= 0).all() and (np.diff(prof) >= -1e-12).all()
