"""The stroke measures: widths against analytic shapes, coverage and width agreement of edits."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from phloem import metrics, strokes
from phloem.strokes import Stroke, StrokeSet
from phloem.strokes.measures import stroke_widths


@pytest.mark.parametrize("angle", [0.0, 17.0, 45.0, 90.0])
def test_widths_of_a_turned_band_are_its_width(angle: float) -> None:
    a = math.radians(angle)
    t, n = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    yy, xx = np.mgrid[0:200, 0:200].astype(np.float64)
    d = np.stack([xx - 100, yy - 100], axis=-1)
    band = ((np.abs(d @ n) <= 8) & (np.abs(d @ t) <= 80)).astype(np.float32)
    s = Stroke([100 - 60 * t, 100 + 60 * t])
    w = stroke_widths(band, s, np.linspace(0, 1, 9))
    # 2 × 8 px, give or take the pixel grid (the last set pixel's centre up to half a pixel in).
    assert np.abs(w - 16.5).max() <= 1.5


def test_widths_of_a_disc_follow_its_chords() -> None:
    r = 30.0
    mask = np.zeros((100, 100), np.float32)
    cv2.circle(mask, (50, 50), int(r), 1.0, -1)
    s = Stroke([[50, 20], [50, 80]])
    u = np.linspace(0.1, 0.9, 9)
    y = 20 + 60 * u - 50
    chord = 2 * np.sqrt(r**2 - y**2)
    assert np.abs(stroke_widths(mask, s, u) - chord).max() < 2.0
    assert stroke_widths(mask, Stroke([[0, 0], [10, 0]]), [0.5]).tolist() == [0.0]


def test_an_edit_covers_its_strokes_with_the_object_width() -> None:
    img = np.zeros((60, 160, 4), np.float32)
    img[20:41, 10:150] = [0.5, 0.4, 0.3, 1.0]
    img[20:41, 10:150:6, :3] = 0.2
    sset = StrokeSet.from_lists(
        [[[12, 30], [147, 30]]],
        [[[130 + 100 * math.cos(a), 150 - 100 * math.sin(a)] for a in np.linspace(2.8, 0.35, 40)]],
        target_size=(180, 260),
    )
    out = strokes.edit(img, sset)
    assert metrics.stroke_coverage(out, sset) >= 0.98
    assert metrics.width_agreement(out, sset, img) < 0.1
    # An empty result covers nothing and disagrees fully.
    empty = np.zeros_like(out)
    assert metrics.stroke_coverage(empty, sset) == 0.0
    assert metrics.width_agreement(empty, sset, img) == pytest.approx(1.0)


def test_width_agreement_reads_a_wanted_width_where_a_pair_has_one() -> None:
    src = np.zeros((40, 60))
    src[15:25, 5:55] = 1  # 10 px wide
    out = np.zeros((60, 40))
    out[5:55, 15:35] = 1  # 20 px wide, upright
    line, upright = [[[5, 20], [54, 20]]], [[[25, 5], [25, 54]]]
    assert metrics.width_agreement(out, StrokeSet.from_lists(line, upright), src) == pytest.approx(1.0)
    assert metrics.width_agreement(out, StrokeSet.from_lists(line, upright, widths=[20]), src) == pytest.approx(0.0)
    assert metrics.width_agreement(out, StrokeSet.from_lists(line, upright, widths=[25]), src) == pytest.approx(0.2)


def test_measures_name_bad_arguments() -> None:
    sset = StrokeSet.from_lists([[[0, 0], [9, 0]]], [[[0, 0], [9, 0]]])
    with pytest.raises(TypeError, match="strokes: expected a phloem.strokes.StrokeSet"):
        metrics.stroke_coverage(np.ones((5, 10)), [[0, 0]])
    with pytest.raises(ValueError, match="image: expected an alpha channel"):
        metrics.stroke_coverage(np.ones((5, 10, 3)), sset)
    with pytest.raises(ValueError, match="source: no source stroke runs over"):
        metrics.width_agreement(np.ones((5, 10)), sset, np.zeros((5, 10)))
