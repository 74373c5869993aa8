"""``phloem.strokes.edit``: identity and rotation against the object itself, the dynamic programme
against brute force and the uniform mapping, the composition's labels against the pieces'
supports, determinism across thread counts, and clear errors for bad input."""

from __future__ import annotations

import itertools
import math

import cv2
import numpy as np
import pytest
from scipy import ndimage

import phloem
from phloem import strokes
from phloem.strokes import StrokeSet
from phloem.strokes import compose as _compose
from phloem.strokes import fetch as _fetch
from phloem.strokes import sampling as _sampling


def _textured_bar(h: int = 60, w: int = 160, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """An RGBA bar along y = h/2 (rows h/2 ± 10, columns 10..w-10) with a smooth random texture
    that varies along and across it, and its mask."""
    rng = np.random.default_rng(seed)
    noise = cv2.GaussianBlur(rng.random((h, w, 3)).astype(np.float32), (0, 0), 2.0)
    yy, xx = np.mgrid[0:h, 0:w]
    stripes = 0.5 + 0.4 * np.sin(xx / 5.0)[..., None] * np.array([1.0, 0.6, 0.2], np.float32)
    rgb = np.clip(0.5 * stripes + 0.5 * (noise - noise.mean()) * 4 + 0.25, 0, 1).astype(np.float32)
    mask = (np.abs(yy - h // 2) <= 10) & (xx >= 10) & (xx < w - 10)
    img = np.concatenate([rgb, mask[..., None].astype(np.float32)], axis=2)
    return np.ascontiguousarray(img), mask


def test_identity_strokes_reproduce_the_object_inside_its_mask() -> None:
    img, mask = _textured_bar()
    line = [[12.0, 30.0], [147.0, 30.0]]
    r = strokes.edit(img, [line], [line], full_output=True)
    out = r.image
    covered = out[..., 3] > 0.5
    assert (covered & mask).sum() >= 0.97 * mask.sum()
    assert not (covered & ~mask).any()
    inside = covered & mask
    assert np.abs(out[..., :3][inside] - img[..., :3][inside]).max() < 1e-5
    # Every sample takes its piece where the uniform mapping would (nothing cheaper than 0).
    s = r.samplings[0]
    assert np.allclose(s.source_arc, s.target_arc)
    assert s.energy == 0.0


def test_a_straight_object_along_a_rotated_stroke_is_the_rotated_object() -> None:
    img, _mask = _textured_bar()
    line = np.array([[12.0, 30.0], [147.0, 30.0]])
    angle = 30.0
    centre = (80.0, 80.0)
    rot = cv2.getRotationMatrix2D(centre, angle, 1.0)  # counter-clockwise on screen
    moved = np.c_[line + (0.0, 50.0), np.ones(2)] @ rot.T
    size = (160, 160)
    out = strokes.edit(img, [line], [moved], size=size)
    shifted = np.zeros((160, 160, 4), np.float32)
    shifted[50:110] = img
    expected = cv2.warpAffine(shifted, rot, (160, 160), flags=cv2.INTER_LINEAR)
    inside = cv2.erode((expected[..., 3] > 0.999).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    got = out[..., 3] > 0.5
    assert (got & inside).sum() >= 0.97 * inside.sum()
    err = np.abs(out[..., :3] - expected[..., :3])[inside & got]
    assert np.median(err) < 0.02 and np.quantile(err, 0.99) < 0.1
    # Nothing strays: the result's pixels lie on the rotated bar (dilated by the soft edge).
    near = cv2.dilate((expected[..., 3] > 0).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    assert not (got & ~near).any()


def _brute(energies: list[np.ndarray]) -> float:
    best = math.inf
    for path in itertools.product(*[range(e.shape[0]) for e in energies], range(energies[-1].shape[1])):
        total = sum(e[path[i], path[i + 1]] for i, e in enumerate(energies))
        best = min(best, total)
    return best


@pytest.mark.parametrize("seed", range(6))
def test_best_path_equals_brute_force(seed: int) -> None:
    rng = np.random.default_rng(seed)
    sizes = [1, *rng.integers(1, 5, size=rng.integers(1, 5)).tolist(), 1]
    energies = []
    for a, b in itertools.pairwise(sizes):
        e = rng.random((a, b)) * 10
        e[rng.random((a, b)) < 0.3] = np.inf
        energies.append(e)
    path, energy = _sampling.best_path(energies)
    assert energy == pytest.approx(_brute(energies)) if math.isfinite(_brute(energies)) else energy == math.inf
    if math.isfinite(energy):
        assert sum(e[path[i], path[i + 1]] for i, e in enumerate(energies)) == pytest.approx(energy)


def test_the_programme_on_real_pieces_equals_brute_force_and_never_costs_more_than_uniform() -> None:
    img, _ = _textured_bar(seed=3)
    pair = StrokeSet.from_lists([[[12, 30], [147, 30]]], [[[20, 40], [70, 20], [130, 50]]]).pairs[0]
    part = _fetch.stroke_sources(img, [pair.source])[0]
    # Few samples, so every monotone, bounded mapping over the candidates can be listed.
    s = _sampling.sample(pair, part, spacing=40.0, stretch=2.0, threads=1)
    seg = _sampling._segments(pair, 40.0, 2.0)[0]
    m, sl = len(seg.target_arc) - 1, pair.source.length()
    lo, hi = seg.step / 2 - 1e-9, seg.step * 2 + 1e-9
    # Every candidate the programme could be offered, before it drops the unreachable ones.
    grid = [np.array([0.0])]
    for i in range(1, m):
        c = i * seg.step + np.arange(-_sampling.BAND, _sampling.BAND + 1) * seg.step / 2
        grid.append(c[(c >= 0) & (c <= sl)])
    grid.append(np.array([sl]))
    assert all(set(c) <= set(g) for c, g in zip(seg.candidates, grid, strict=True))
    best = math.inf
    rows = [
        _fetch.specs(pair, np.full(len(c), seg.target_arc[i]), c, part, np.full(len(c), seg.half_length))
        for i, c in enumerate(grid)
    ]
    for choice in itertools.product(*[range(len(c)) for c in grid]):
        src = [grid[i][k] for i, k in enumerate(choice)]
        if not all(lo <= b - a <= hi for a, b in itertools.pairwise(src)):
            continue
        spec = np.concatenate([rows[i][k : k + 1] for i, k in enumerate(choice)])
        pairs = np.array([[i, i + 1] for i in range(len(choice) - 1)], np.int64)
        best = min(best, float(_fetch.pair_energies(part, spec, pairs, threads=1).sum()))
    assert s.energy == pytest.approx(best, rel=1e-9)
    assert s.energy <= s.uniform_energy
    assert s.energy < s.uniform_energy  # on a bend the uniform pieces are not the best fit
    u = _sampling.sample(pair, part, spacing=40.0, stretch=2.0, uniform=True, threads=1)
    assert u.energy == pytest.approx(s.uniform_energy)
    assert np.all(np.diff(s.source_arc) > 0)
    steps = np.diff(s.source_arc) / seg.step
    assert steps.min() >= 0.5 - 1e-9 and steps.max() <= 2 + 1e-9


def test_composition_labels_lie_on_their_pieces() -> None:
    rng = np.random.default_rng(1)
    pieces = []
    for _k in range(6):
        h, w = rng.integers(8, 20, size=2)
        sup = rng.random((h, w)) < 0.8
        rgba = np.zeros((h, w, 4), np.float32)
        rgba[..., :3] = rng.random((h, w, 3))
        rgba[..., 3] = sup
        pieces.append(_fetch.Piece((int(rng.integers(-5, 30)), int(rng.integers(-5, 30))), rgba, sup, (1.0, 1.0)))
    comp = _compose.compose(pieces, (40, 40), threads=1)
    for y, x in zip(*np.nonzero(comp.labels >= 0), strict=True):
        p = pieces[comp.labels[y, x]]
        x0, y0 = p.offset
        assert p.support[y - y0, x - x0]
        assert np.array_equal(comp.rgba[y, x], p.rgba[y - y0, x - x0])
    union = np.zeros((40, 40), bool)
    for p in pieces:
        x0, y0 = p.offset
        for r, c in zip(*np.nonzero(p.support), strict=True):
            if 0 <= y0 + r < 40 and 0 <= x0 + c < 40:
                union[y0 + r, x0 + c] = True
    assert np.array_equal(comp.labels >= 0, union)


def _tee() -> np.ndarray:
    """An RGBA T: a textured bar (rows 20..40) with a leg down from its middle (columns 70..90)."""
    bar, _ = _textured_bar(h=120, seed=5)
    img = np.zeros_like(bar)
    img[20:41, 10:150] = bar[50:71, 10:150]
    img[41:110, 70:91, :3] = np.transpose(bar[50:71, 10:79, :3], (1, 0, 2))
    img[41:110, 70:91, 3] = 1.0
    return img


def test_branching_targets_compose_into_one_object_at_any_thread_count() -> None:
    img = _tee()
    src = [[[12, 30], [147, 30]], [[80, 30], [80, 107]]]
    tgt = [[[20, 100], [180, 100]], [[100, 100], [150, 20]]]
    one = strokes.edit(img, src, tgt, size=(140, 200), threads=1, full_output=True)
    two = strokes.edit(img, src, tgt, size=(140, 200), threads=2, full_output=True)
    assert np.array_equal(one.image, two.image) and np.array_equal(one.pieces, two.pieces)
    _, n = ndimage.label(one.image[..., 3] > 0, structure=np.ones((3, 3)))
    assert n == 1
    assert set(np.unique(one.stroke_of_piece[one.pieces[one.pieces >= 0]])) == {0, 1}


def test_strokes_drawn_over_one_another_share_the_object() -> None:
    img, mask = _textured_bar()
    whole, left = [[12, 30], [147, 30]], [[12, 30], [80, 30]]
    own = _fetch.shares(img[..., 3], [_fetch.Stroke(whole), _fetch.Stroke(left)])
    assert np.array_equal(own[0], mask)
    assert own[1][:, :80].sum() == mask[:, :80].sum() and not own[1][:, 85:].any()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"target": [[[0, 0], [10, 0]], [[0, 5], [10, 5]]]}, "one target stroke per source stroke"),
        ({"target": [[[5, 5], [5, 5]]]}, "target"),
        ({"target": [[[5, 5], [500, 5]]]}, r"pairs\[0\]\.target\[1\].*outside"),
        ({"source": [[[5, 5], [900, 5]]]}, r"pairs\[0\]\.source\[1\].*outside"),
        ({"source": [[[1, 1], [40, 1]]]}, "does not run over the object"),
        ({"mask": np.zeros((60, 160), bool)}, "mask: is empty"),
        ({"mask": np.ones((6, 16), bool)}, "mask"),
        ({"stretch": 0.5}, "stretch"),
        ({"sampling": "greedy"}, "sampling"),
        ({"size": (0, 10)}, "size"),
        ({"spacing": float("nan")}, "spacing"),
    ],
)
def test_bad_input_gives_one_line_errors(kwargs: dict, match: str) -> None:
    img, _ = _textured_bar()
    args = {"source": [[[12, 30], [147, 30]]], "target": [[[12, 30], [147, 30]]]}
    args.update(kwargs)
    src, tgt = args.pop("source"), args.pop("target")
    with pytest.raises(ValueError, match=match) as info:
        strokes.edit(img, src, tgt, **args)
    assert "\n" not in str(info.value)


def test_a_stroke_set_carries_targets_controls_and_size() -> None:
    img, _ = _textured_bar()
    sset = StrokeSet.from_lists(
        [[[12, 30], [147, 30]]], [[[10, 20], [90, 20]]], controls=[[[0, 0], [0.5, 0.25], [1, 1]]], target_size=(40, 100)
    )
    r = strokes.edit(img, sset, full_output=True)
    assert r.image.shape == (40, 100, 4)
    s = r.samplings[0]
    # The control pins the source's middle to a quarter of the target.
    i = int(np.argmin(np.abs(s.target_arc - 20.0)))
    assert s.target_arc[i] == pytest.approx(20.0) and s.source_arc[i] == pytest.approx(67.5)
    with pytest.raises(ValueError, match="target: expected None"):
        strokes.edit(img, sset, [[[0, 0], [5, 5]]])


def test_without_mask_or_alpha_the_object_is_found_on_a_plain_background() -> None:
    img, mask = _textured_bar()
    scan = img[..., :3] * img[..., 3:] + 0.95 * (1 - img[..., 3:])  # the bar on white paper
    line = [[12.0, 30.0], [147.0, 30.0]]
    r = strokes.edit(scan, [line], [line], full_output=True)
    assert (r.mask != mask).sum() <= 0.02 * mask.sum()
    noise = np.random.default_rng(0).random((60, 160, 3))
    with pytest.raises(ValueError, match="mask: none given, the image has no alpha"):
        strokes.edit(noise, [line], [line])


def test_a_background_takes_the_object_by_poisson_editing() -> None:
    img, _ = _textured_bar()
    line = [[12.0, 30.0], [147.0, 30.0]]
    scene = np.zeros((80, 200, 3), np.float32)
    scene[:] = [0.2, 0.5, 0.9]
    moved = [[30.0, 40.0], [165.0, 40.0]]
    plain = strokes.edit(img, [line], [moved], size=(80, 200))
    out = strokes.edit(img, [line], [moved], background=scene)
    assert out.shape == (80, 200, 4) and np.all(out[..., 3] == 1.0)
    inside = plain[..., 3] >= 0.5
    assert np.allclose(out[~(plain[..., 3] > 0), :3], scene[~(plain[..., 3] > 0)])
    # The object's gradients are kept inside, and its border takes the scene's colours.
    gx = np.diff(out[..., :3], axis=1)[inside[:, 1:] & inside[:, :-1]]
    gp = np.diff(plain[..., :3], axis=1)[inside[:, 1:] & inside[:, :-1]]
    assert np.abs(gx - gp).mean() < 0.02
    rim = inside & ~ndimage.binary_erosion(inside)
    assert np.abs(out[rim, :3] - scene[rim]).mean() < 0.5 * np.abs(plain[rim, :3] - scene[rim]).mean()
    with pytest.raises(ValueError, match="background: expected the output size"):
        strokes.edit(img, [line], [moved], size=(90, 200), background=scene)


def test_an_edit_too_big_for_memory_is_refused_before_it_starts() -> None:
    img, _ = _textured_bar()
    line = [[12.0, 30.0], [147.0, 30.0]]
    with pytest.raises(phloem.MemoryLimitError, match=r"size: 100000×100000 .* over the memory limit"):
        strokes.edit(img, [line], [line], size=(100000, 100000))
    seen: list[tuple[int, int]] = []
    strokes.edit(img, [line], [line], progress=lambda d, t: seen.append((d, t)))
    assert seen[0] == (0, 2) and seen[-1] == (2, 2) and all(a <= b for (a, _), (b, _) in itertools.pairwise(seen))


def test_a_wanted_width_scales_the_object_and_its_texture() -> None:
    # A bar 21 px across (rows 20..40) whose colour changes across it only, row by row.
    rows = np.random.default_rng(3).random((60, 1, 3)).astype(np.float32)
    img = np.zeros((60, 160, 4), np.float32)
    img[20:41, 10:150, :3] = np.broadcast_to(rows[20:41], (21, 140, 3))
    img[20:41, 10:150, 3] = 1.0
    line, wide = [[12.0, 30.0], [147.0, 30.0]], [[12.0, 60.0], [147.0, 60.0]]
    out = strokes.edit(img, [line], [wide], widths=[42], size=(120, 160))
    # Twice as wide across the stroke: about rows 60 ± 21 instead of ± 10.5.
    opaque = np.nonzero((out[:, 40:120, 3] > 0.5).all(axis=1))[0]
    assert 38 <= opaque.min() <= 40 and 80 <= opaque.max() <= 82
    # Scaled about the stroke: target row 60 + 2 d shows source row 30 + d.
    for d in range(-9, 10):
        assert np.abs(out[60 + 2 * d, 40:120, :3] - rows[30 + d, 0]).max() < 1e-4, d
    sset = StrokeSet.from_lists([line], [wide], widths=[42], target_size=(120, 160))
    assert np.array_equal(strokes.edit(img, sset), out)
    with pytest.raises(ValueError, match="expected None when source is a StrokeSet"):
        strokes.edit(img, sset, widths=[10])


def test_a_tapering_width_gives_a_smooth_outline_that_follows_it() -> None:
    img, _ = _textured_bar()  # 21 px across
    line, target = [[12.0, 30.0], [147.0, 30.0]], [[10.0, 60.0], [290.0, 60.0]]
    out = strokes.edit(img, [line], [target], widths=[[[0, 40], [1, 10]]], size=(120, 300))
    across = (out[..., 3] > 0.5).sum(axis=0).astype(float)[20:281]
    wanted = 40 - 30 * (np.arange(20, 281) - 10) / 280
    # Within 2 px of the wanted width (and its 2 x 2 px margin) everywhere: no column left
    # open where a piece scaled down reads past the object's end, and no step over 2 px a side.
    assert np.abs(across - wanted).max() <= 4.5, np.abs(across - wanted).max()
    assert np.abs(np.diff(across)).max() <= 4
