"""Junctions of ``phloem.strokes.edit``: a branch takes its parent's rim where it leaves it and
keeps its parent's core, strokes that merely cross are cut as the paper cuts them, and the
branch's tone is matched to its parent's near the junction only, smoothly."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

import phloem
from phloem import strokes
from phloem.strokes import compose as _compose
from phloem.strokes import synthesis as _synthesis
from phloem.strokes import tone as _tone


def _bark_strip() -> np.ndarray:
    """The embedded bark as an RGBA strip 40 px wide (columns 10..50, rows 10..250), its
    fissures running along it."""
    bark = phloem.data.bark()[..., :3].astype(np.float32)
    img = np.zeros((260, 60, 4), np.float32)
    img[10:250, 10:50, :3] = cv2.resize(bark, (40, 240), interpolation=cv2.INTER_AREA)
    img[10:250, 10:50, 3] = 1.0
    return img


SRC = [[[30, 12], [30, 247]]] * 2  # one strip feeds both target strokes
MAIN, BRANCH = [[20, 100], [280, 100]], [[150, 100], [150, 10]]


def _stroke_map(r: strokes.EditResult) -> np.ndarray:
    return np.where(r.pieces >= 0, r.stroke_of_piece[np.maximum(r.pieces, 0)], -1)


def test_a_branch_takes_its_parents_rim_where_it_leaves_and_keeps_out_of_its_core(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    img = _bark_strip()
    r = strokes.edit(img, SRC, [MAIN, BRANCH], size=(140, 300), full_output=True)
    owner = _stroke_map(r)
    # The main branch covers rows 81..120; the branch leaves it upwards around column 150. The
    # rim is 0.35 x 22 px deep (the half width with its 2 px margin), the core deeper than 0.65 x 22.
    rim, core, below = owner[81:88, 140:161], owner[96:106, 120:181], owner[106:121, 120:181]
    assert (rim == 1).mean() > 0.9
    assert (core == 0).all() and not (below == 1).any()
    # The plain cut of the paper follows the parent's edge (the object's edge is a cheap
    # seam) and leaves it to the parent: the branch seems to pass behind it.
    monkeypatch.setattr(_compose, "RIM", 0.0)
    plain = _stroke_map(strokes.edit(img, SRC, [MAIN, BRANCH], size=(140, 300), full_output=True))
    assert (plain[81:88, 140:161] == 0).mean() > 0.7


def test_strokes_that_only_cross_are_cut_as_the_paper_cuts_them(monkeypatch: pytest.MonkeyPatch) -> None:
    img = _bark_strip()
    cross = [[[20, 100], [280, 100]], [[150, 190], [150, 10]]]
    r = strokes.edit(img, SRC, cross, size=(200, 300))
    monkeypatch.setattr(_compose, "RIM", 0.0)
    monkeypatch.setattr(_synthesis, "match_seams", lambda rgba, *a, **k: rgba)
    plain = strokes.edit(img, SRC, cross, size=(200, 300))
    assert np.array_equal(r, plain)


def _two_tones(seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """A composite: a light bar (stroke 0, rows 40..60) and a dark branch leaving it upwards
    (stroke 1, rows 0..40, columns 70..90), both textured."""
    rng = np.random.default_rng(seed)
    h, w = 100, 160
    of = np.full((h, w), -1, np.int64)
    of[40:61, :] = 0
    of[0:40, 70:91] = 1
    texture = 0.08 * rng.standard_normal((h, w, 3)).astype(np.float32)
    base = np.where(of[..., None] == 0, 0.7, 0.3).astype(np.float32)
    rgba = np.zeros((h, w, 4), np.float32)
    rgba[..., :3] = np.clip(base + texture, 0, 1)
    rgba[..., 3] = of >= 0
    rgba[of < 0] = 0
    return rgba, of


def test_the_branch_tone_meets_the_parent_at_the_junction_only() -> None:
    rgba, of = _two_tones()
    ends = np.array([[[0, 50], [159, 50]], [[80, 50], [80, 0]]], np.float64)
    out = _tone.match_seams(rgba, of, np.array([10.0, 10.0]), ends, threads=1)
    branch_edge = (of == 1) & (np.arange(100)[:, None] >= 37)
    parent_edge = (of == 0) & (np.arange(100)[:, None] <= 42)
    step_before = rgba[..., :3][parent_edge].mean() - rgba[..., :3][branch_edge].mean()
    step_after = out[..., :3][parent_edge].mean() - out[..., :3][branch_edge].mean()
    assert step_before > 0.35
    assert abs(step_after) < 0.1 * step_before
    # The parent, the background, alpha and the branch beyond the reach (20 px) are untouched.
    far = (of == 1) & (np.arange(100)[:, None] < 40 - 21)
    assert np.array_equal(out[of != 1], rgba[of != 1])
    assert np.array_equal(out[far], rgba[far])
    assert np.array_equal(out[..., 3], rgba[..., 3])
    # Only the low frequencies move: the correction is smooth where the texture is not.
    corr = (out - rgba)[..., 0][0:40, 72:89]
    assert np.abs(np.diff(corr, 2, axis=0)).max() < 0.02
    assert np.abs(np.diff(rgba[..., 0][0:40, 72:89], 2, axis=0)).max() > 0.2


def test_a_stroke_whose_ends_lie_off_other_strokes_keeps_its_tone() -> None:
    rgba, of = _two_tones()
    ends = np.array([[[0, 50], [159, 50]], [[80, 38], [80, 0]]], np.float64)  # ends on itself
    out = _tone.match_seams(rgba, of, np.array([10.0, 10.0]), ends, threads=1)
    assert np.array_equal(out, rgba)
