"""The stroke model and the ``phloem.strokes`` JSON format: geometry against closed forms,
validation with one-line errors that name what is wrong, lossless round trips."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from phloem.strokes import Stroke, StrokeError, StrokePair, StrokeSet


def _circle(n: int = 400, r: float = 30.0) -> np.ndarray:
    t = np.linspace(0, 2 * math.pi, n)
    return np.c_[50 + r * np.cos(t), 40 + r * np.sin(t)]


def test_geometry_of_a_circle_matches_the_closed_forms() -> None:
    s = Stroke(_circle())
    assert s.length() == pytest.approx(2 * math.pi * 30, rel=1e-4)
    t = np.linspace(0, 2 * math.pi, 400)
    analytic = np.c_[-np.sin(t), np.cos(t)]
    assert np.abs(s.tangents()[1:-1] - analytic[1:-1]).max() < 1e-3
    assert np.allclose(np.hypot(*s.tangents().T), 1.0)
    assert s.at(0.25) == pytest.approx([50.0, 70.0], abs=0.05)  # a quarter turn from (80, 40)
    u = np.linspace(0, 1, 17)
    assert np.allclose([s.project(p) for p in s.at(u[1:-1])], u[1:-1], atol=1e-6)


def test_repeated_points_are_dropped_and_a_stroke_turning_back_keeps_its_tangents() -> None:
    s = Stroke([[0, 0], [0, 0], [5, 0], [5, 0], [0, 0]])
    assert s.points.tolist() == [[0, 0], [5, 0], [0, 0]]
    assert s.tangents().tolist() == [[1, 0], [1, 0], [-1, 0]]
    assert s.length() == 10


@pytest.mark.parametrize(
    ("points", "message"),
    [
        ([[0, 0]], "2 to"),
        ([[1, 1], [1, 1]], "zero length"),
        ([[0, 0], [math.nan, 1]], r"points\[1\].*finite"),
        ([[0, 0], [1e300, 1]], r"points\[1\]"),
        ([[0, 0, 0], [1, 1, 1]], "shape"),
        ("ab", "array"),
    ],
)
def test_bad_strokes_give_one_line_errors(points: object, message: str) -> None:
    with pytest.raises(StrokeError, match=message) as info:
        Stroke(points)  # type: ignore[arg-type]
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("controls", "message"),
    [
        ([[0, 0], [0.5, 0.5]], "last"),
        ([[0.1, 0], [1, 1]], "first"),
        ([[0, 0], [0.5, 0.2], [0.4, 0.6], [1, 1]], r"controls\[2\].*increase"),
        ([[0, 0], [0.5, 0.5], [0.5, 0.6], [1, 1]], r"controls\[2\].*increase"),
        ([[0, 0], [1.5, 0.5], [1, 1]], r"\[0, 1\]"),
        ([[0, 0], [math.nan, 0.5], [1, 1]], "NaN"),
        ([0, 1], "shape"),
    ],
)
def test_bad_controls_give_one_line_errors(controls: object, message: str) -> None:
    with pytest.raises(StrokeError, match=message):
        StrokePair([[0, 0], [10, 0]], [[0, 0], [0, 10]], controls)


def test_controls_pinned_at_points_project_onto_both_strokes_in_order() -> None:
    p = StrokePair([[0, 0], [100, 0]], [[0, 0], [0, 50]])
    q = p.with_controls([((70, 3), (0, 40)), ((20, -2), (0, 5))])
    assert q.controls.tolist() == [[0, 0], [0.2, 0.1], [0.7, 0.8], [1, 1]]
    assert StrokePair(p.source, p.target).controls.tolist() == [[0, 0], [1, 1]]  # the end points


def test_from_lists_checks_counts_and_the_images() -> None:
    src = [[[0, 0], [10, 0]], [[0, 5], [10, 5]]]
    with pytest.raises(StrokeError, match=r"target: expected one target stroke per source stroke \(2\), got 1"):
        StrokeSet.from_lists(src, src[:1])
    with pytest.raises(StrokeError, match=r"controls: expected one entry per stroke pair \(2\), got 1"):
        StrokeSet.from_lists(src, src, controls=[None])
    with pytest.raises(StrokeError, match=r"pairs\[1\]\.target\[1\]: point \[40.0, 5.0\] lies outside the 32×16 image"):
        StrokeSet.from_lists(src, [src[0], [[0, 5], [40, 5]]], target_size=(16, 32))
    with pytest.raises(StrokeError, match=r"pairs\[0\]\.source\[0\]"):
        StrokeSet.from_lists([[[-1, 0], [5, 0]]], src[:1], source_shape=(8, 8))
    with pytest.raises(StrokeError, match=r"pairs\[1\]\.target: the stroke has zero length"):
        StrokeSet.from_lists(src, [src[0], [[3, 3], [3, 3]]])
    with pytest.raises(StrokeError, match="source: expected a list of strokes"):
        StrokeSet.from_lists(np.zeros((2, 2)), src)  # type: ignore[arg-type]
    ok = StrokeSet.from_lists(src, src, source_shape=(6, 11), target_size=(6, 11))  # on the last pixel: inside
    assert ok.bounds("target") == (0.0, 0.0, 10.0, 5.0)


_point = st.tuples(st.floats(-1e4, 1e4), st.floats(-1e4, 1e4))


@given(
    st.lists(
        st.tuples(st.lists(_point, min_size=2, max_size=6), st.lists(_point, min_size=2, max_size=6)),
        min_size=1,
        max_size=4,
    )
)
def test_json_round_trip_is_lossless(pairs: list[tuple[list[tuple[float, float]], list[tuple[float, float]]]]) -> None:
    try:
        s = StrokeSet.from_lists([p for p, _ in pairs], [q for _, q in pairs])
    except StrokeError:
        return  # a zero-length stroke: refused, as tested above
    back = StrokeSet.from_json(s.to_json())
    assert back == s
    assert back.to_json() == s.to_json()


def _doc(**over: object) -> dict[str, object]:
    doc: dict[str, object] = {
        "format": "phloem.strokes",
        "version": 1,
        "target_size": [64, 64],
        "pairs": [
            {"source": [[0, 0], [10, 0]], "target": [[5, 5], [20, 30]], "controls": [[0, 0], [0.5, 0.4], [1, 1]]}
        ],
    }
    doc.update(over)
    return doc


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ([], "must be a JSON object"),
        (_doc(format="phloem.skeleton"), "format must be 'phloem.strokes'"),
        (_doc(version=2), "unsupported stroke set version 2"),
        (_doc(version=True), "unsupported stroke set version True"),
        (_doc(pairs=[]), "'pairs' must be a non-empty list"),
        (_doc(pairs=[{"source": [[0, 0], [1, 1]]}]), r"pairs\[0\] must be an object with 'source' and 'target'"),
        (_doc(pairs=[{"source": [[0, 0], ["1", 1]], "target": [[0, 0], [1, 1]]}]), r"pairs\[0\]\.source\[1\] must be a pair"),
        (_doc(pairs=[{"source": [[0, 0], [True, 1]], "target": [[0, 0], [1, 1]]}]), r"pairs\[0\]\.source\[1\]"),
        (_doc(pairs=[{"source": [[0, 0], [1, 1]], "target": [[0, 0], [1, 1]], "controls": [[0, 0], [1, 0.5]]}]), r"pairs\[0\]\.controls"),
        (_doc(pairs=[{"source": [[0, 0], [1, 1]], "target": [[0, 0], [99, 1]]}]), r"pairs\[0\]\.target\[1\].*outside"),
        (_doc(pairs=[{"source": [[0, 0], [1, 1]], "target": [[0, 0], [1, 1]], "width": 0}]), r"pairs\[0\]\.width: widths must be positive"),
        (_doc(pairs=[{"source": [[0, 0], [1, 1]], "target": [[0, 0], [1, 1]], "width": "wide"}]), r"pairs\[0\]\.width must be a list"),
        (_doc(pairs=[{"source": [[0, 0], [1, 1]], "target": [[0, 0], [1, 1]], "width": [[0.5, 4], [0.2, 6]]}]), r"pairs\[0\]\.width: arc-length fractions u must increase"),
        (_doc(pairs=[{"source": [[0, 0], [1, 1]], "target": [[0, 0], [1, 1]], "width": [[0, 4], [1.5, 6]]}]), r"pairs\[0\]\.width: arc-length fractions u must lie in \[0, 1\]"),
        (_doc(target_size=[64]), r"target_size: expected \[H, W\]"),
        (_doc(target_size=[64, 0]), r"target_size"),
    ],
)  # fmt: skip
def test_malformed_files_give_one_line_errors_naming_the_place(tmp_path: Path, doc: object, message: str) -> None:
    with pytest.raises(StrokeError, match=message) as info:
        StrokeSet.from_json(json.dumps(doc))
    assert "\n" not in str(info.value)
    path = tmp_path / "s.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(StrokeError, match=f"path: {path}: .*{message}"):
        StrokeSet.load(path)


def test_broken_json_and_files_name_the_file(tmp_path: Path) -> None:
    path = tmp_path / "s.json"
    path.write_text('{"pairs": [NaN]}')
    with pytest.raises(StrokeError, match="NaN is not a JSON number"):
        StrokeSet.load(path)
    path.write_bytes(b"\xff\xfe")
    with pytest.raises(StrokeError, match=str(path)):
        StrokeSet.load(path)
    with pytest.raises(StrokeError, match="absent.json does not exist"):
        StrokeSet.load(tmp_path / "absent.json")


def test_save_and_load_and_no_silent_overwrite(tmp_path: Path) -> None:
    s = StrokeSet.from_dict(_doc())
    path = tmp_path / "s.json"
    s.save(path)
    assert StrokeSet.load(path) == s
    assert s.pairs[0].controls.tolist() == [[0, 0], [0.5, 0.4], [1, 1]]
    with pytest.raises(FileExistsError):
        s.save(path)
    s.save(path, overwrite=True)


def test_a_pairs_width_is_a_number_or_pairs_interpolated_along_the_target_and_round_trips() -> None:
    line, target = [[0, 0], [10, 0]], [[0, 0], [0, 40]]
    const = StrokeSet.from_lists([line], [target], widths=[12])
    assert const.pairs[0].width_at([0.0, 0.3, 1.0]).tolist() == [12.0, 12.0, 12.0]
    taper = StrokeSet.from_lists([line], [target], widths=[[[0.25, 20], [0.75, 10]]])
    assert taper.pairs[0].width_at([0.0, 0.5, 1.0]).tolist() == [20.0, 15.0, 10.0]
    plain = StrokeSet.from_lists([line], [target])
    assert plain.pairs[0].width is None and plain.pairs[0].width_at(0.5) is None
    assert "width" not in plain.to_dict()["pairs"][0]
    for s in (const, taper):
        assert StrokeSet.from_json(s.to_json()) == s
    assert const != plain and const != taper
    assert taper.pairs[0].with_controls([((5, 0), (0, 10))]).width is taper.pairs[0].width
    with pytest.raises(StrokeError, match=r"widths: expected one entry per stroke pair \(1\), got 2"):
        StrokeSet.from_lists([line], [target], widths=[1, 2])
    with pytest.raises(StrokeError, match=r"pairs\[0\]\.width: expected a width in px"):
        StrokeSet.from_lists([line], [target], widths=[True])
