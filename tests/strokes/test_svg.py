"""Strokes from SVG: every path command, transform and unit against closed forms; layers; errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from phloem.branching import trace
from phloem.strokes import Stroke, StrokeError, read_svg, read_svg_widths, strokes_from_skeleton

NS = 'xmlns="http://www.w3.org/2000/svg" xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape"'


def _svg(tmp_path: Path, body: str, root: str = "") -> Path:
    p = tmp_path / "d.svg"
    p.write_text(f"<svg {NS} {root}>{body}</svg>")
    return p


def _path(tmp_path: Path, d: str, root: str = "") -> np.ndarray:
    strokes = read_svg(_svg(tmp_path, f'<path d="{d}"/>', root))
    assert len(strokes) == 1
    return strokes[0].points


def _off(points: np.ndarray, p: tuple[float, float]) -> float:
    """Distance from ``p`` to the polyline ``points``."""
    s = Stroke(points)
    return float(np.hypot(*(s.at(s.project(p)) - p)))


def test_lines_in_every_form_agree(tmp_path: Path) -> None:
    ref = [[1, 2], [11, 2], [11, 12], [4, 5]]
    assert _path(tmp_path, "M1 2 L11 2 L11 12 L4 5").tolist() == ref
    assert _path(tmp_path, "m1,2 10,0 0 10 -7-7").tolist() == ref  # implicit relative linetos
    assert _path(tmp_path, "M1 2H11V12L4 5").tolist() == ref
    assert _path(tmp_path, "M1 2h10v10l-7-7").tolist() == ref


def test_cubic_and_quadratic_curves_lie_on_the_bezier(tmp_path: Path) -> None:
    pts = _path(tmp_path, "M0 0 C 0 40 40 40 40 0")
    assert pts[0].tolist() == [0, 0] and pts[-1].tolist() == [40, 0]
    assert np.hypot(*np.diff(pts, axis=0).T).max() <= 1.5  # flattened about 1 px apart
    assert _off(pts, (20, 30)) < 0.05  # B(1/2) = (20, 30)
    q = _path(tmp_path, "M0 0 Q 20 40 40 0")
    assert _off(q, (20, 20)) < 0.05  # B(1/2) = (20, 20)
    # S reflects the previous control point, T the previous quadratic one
    s = _path(tmp_path, "M0 0 C 0 40 40 40 40 0 S 80 -40 80 0")
    assert _off(s, (60, -30)) < 0.05
    t = _path(tmp_path, "M0 0 Q 20 40 40 0 T 80 0")
    assert _off(t, (60, -20)) < 0.05


def test_arcs_are_on_their_circles_with_either_flag(tmp_path: Path) -> None:
    small = _path(tmp_path, "M0 0 A 10 10 0 0 1 20 0")  # a half circle about (10, 0), sweeping up (y down)
    assert np.allclose(np.hypot(small[:, 0] - 10, small[:, 1]), 10, atol=1e-9)
    assert small[len(small) // 2, 1] < -9.9
    other = _path(tmp_path, "M0 0 a10 10 0 0 0 20 0")
    assert other[len(other) // 2, 1] > 9.9
    big = _path(tmp_path, "M0 0 A 10 10 0 1 1 10 10")  # three quarters of the circle about (10, 0)
    assert np.allclose(np.hypot(big[:, 0] - 10, big[:, 1]), 10, atol=1e-9)
    assert big[:, 1].min() < -9.9 and big[:, 0].min() > -1e-9
    compact = _path(tmp_path, "M0 0 a10 10 0 1110 10")  # flags written together
    assert np.allclose(compact, big)
    scaled = _path(tmp_path, "M0 0 A 1 1 0 0 1 20 0")  # radii too small: scaled up to fit
    assert np.allclose(scaled, small)


def test_closepath_returns_to_the_start_and_subpaths_are_strokes(tmp_path: Path) -> None:
    strokes = read_svg(_svg(tmp_path, '<path d="M0 0 L10 0 L10 10 Z M20 20 L30 20"/>'))
    assert [s.points.tolist() for s in strokes] == [[[0, 0], [10, 0], [10, 10], [0, 0]], [[20, 20], [30, 20]]]


def test_transforms_compose_from_the_root_down(tmp_path: Path) -> None:
    body = (
        '<g transform="translate(100 0)"><g transform="rotate(90)"><path d="M0 0 L10 0" transform="scale(2)"/></g></g>'
    )
    (s,) = read_svg(_svg(tmp_path, body))
    assert np.allclose(s.points, [[100, 0], [100, 20]])
    body = '<polyline points="1,1 2,3" transform="matrix(1 0 0 1 5 6) skewX(45)"/>'
    (s,) = read_svg(_svg(tmp_path, body))
    assert np.allclose(s.points, [[7, 7], [10, 9]])
    body = '<path d="M10 0 L20 0" transform="rotate(180 15 0)"/>'
    (s,) = read_svg(_svg(tmp_path, body))
    assert np.allclose(s.points, [[20, 0], [10, 0]])


def test_the_view_box_maps_onto_the_pixel_size(tmp_path: Path) -> None:
    assert _path(tmp_path, "M0 0 L50 25", 'width="200" height="100" viewBox="0 0 100 50"').tolist() == [
        [0, 0],
        [100, 50],
    ]
    # aspect ratios that differ: uniform scale, centred (xMidYMid meet)
    assert _path(tmp_path, "M0 0 L10 10", 'width="200" height="100" viewBox="0 0 10 10"').tolist() == [
        [50, 0],
        [150, 100],
    ]
    mm = _path(tmp_path, "M0 0 L1 0", 'width="25.4mm" height="25.4mm" viewBox="0 0 1 1"')
    assert mm.tolist() == [[0, 0], [96, 0]]
    assert _path(tmp_path, "M1 1 L3 1", 'viewBox="1 1 2 2"').tolist() == [[0, 0], [2, 0]]


def test_layers_are_found_by_inkscape_label_illustrator_name_or_id(tmp_path: Path) -> None:
    body = (
        '<g inkscape:groupmode="layer" inkscape:label="Source"><path d="M0 0 L1 0"/><path d="M0 1 L1 1"/></g>'
        '<g data-name="target"><line x1="0" y1="0" x2="5" y2="5"/></g>'
        '<g id="other"><polygon points="0,0 4,0 4,4"/></g>'
        "<defs><path d='M0 0 L9 9'/></defs>"
    )
    p = _svg(tmp_path, body)
    assert len(read_svg(p, layer="source")) == 2
    assert read_svg(p, layer="TARGET")[0].points.tolist() == [[0, 0], [5, 5]]
    assert read_svg(p, layer="other")[0].points.tolist() == [[0, 0], [4, 0], [4, 4], [0, 0]]
    assert len(read_svg(p)) == 4  # everything but <defs>
    with pytest.raises(StrokeError, match="layer 'absent' holds no stroke"):
        read_svg(p, layer="absent")


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("<svg", "not a well-formed SVG"),
        (f"<svg {NS}></svg>", "holds no stroke"),
        ("<html/>", r"root element is <html>"),
        (f'<svg {NS}><path d="L 1 1"/></svg>', "must start with a moveto"),
        (f'<svg {NS}><path d="M0 0 C 1 1 2"/></svg>', "'C' needs 6 numbers"),
        (f'<svg {NS}><path d="M0 0 A 5 5 0 2 0 1 1"/></svg>', r"flag \(0 or 1\)"),
        (f'<svg {NS}><path d="M0 0 L1 1 Z 4 4"/></svg>', "after a closepath"),
        (f'<svg {NS}><path d="M0 0 L1e999 1"/></svg>', "too large"),
        (f'<svg {NS}><polyline points="0 0 1"/></svg>', "odd count"),
        (f'<svg {NS}><path d="M0 0 L1 1" transform="spin(3)"/></svg>', "cannot read transform"),
        (f'<svg {NS}><path d="M0 0 L1 1" transform="rotate(1 2)"/></svg>', r"rotate\(\) takes 1 or 3"),
        (f'<svg {NS} viewBox="0 0 -1 1"><path d="M0 0 L1 1"/></svg>', "viewBox"),
        (f'<svg {NS} width="3furlongs" viewBox="0 0 1 1"><path d="M0 0 L1 1"/></svg>', "width: expected a length"),
    ],
)
def test_malformed_drawings_give_one_line_errors(tmp_path: Path, content: str, message: str) -> None:
    p = tmp_path / "bad.svg"
    p.write_text(content)
    with pytest.raises(StrokeError, match=message) as info:
        read_svg(p)
    assert "\n" not in str(info.value) and str(p) in str(info.value)


def test_an_entity_expansion_bomb_is_refused(tmp_path: Path) -> None:
    lol = "".join(f'<!ENTITY l{i} "{("&l" + str(i - 1) + ";") * 10}">' for i in range(1, 10))
    p = tmp_path / "bomb.svg"
    p.write_text(f'<?xml version="1.0"?><!DOCTYPE svg [<!ENTITY l0 "lol">{lol}]><svg {NS}><desc>&l9;</desc></svg>')
    with pytest.raises(StrokeError, match="not a well-formed SVG"):
        read_svg(p)


def test_strokes_from_a_traced_skeleton_meet_at_the_junctions() -> None:
    mask = np.zeros((80, 80), np.float32)
    mask[10:70, 37:43] = 1.0  # a trunk
    mask[38:44, 40:75] = 1.0  # and a branch
    skel = trace(mask, kind="mask")
    strokes = strokes_from_skeleton(skel)
    assert len(strokes) == len(skel.branches) >= 2
    for b, s in zip(skel.branches, strokes, strict=True):
        if b.parent is not None:
            assert s.points[0].tolist() == skel.branches[b.parent[0]].points[b.parent[1]].tolist()
    with pytest.raises(StrokeError, match="no branch is at least"):
        strokes_from_skeleton(skel, min_length=1e6)
    with pytest.raises(TypeError, match="skeleton: expected a phloem.branching.Skeleton"):
        strokes_from_skeleton([[0, 0], [1, 1]])


def test_stroke_widths_are_inherited_and_scaled_like_the_strokes(tmp_path: Path) -> None:
    body = (
        '<g stroke-width="3"><path d="M0 0 L10 0"/>'  # inherited from the group
        '<path d="M0 5 L10 5" style="fill:none;stroke-width:7px"/>'  # style, in px
        '<path d="M0 9 L10 9" stroke-width="1mm"/>'  # a unit
        '<g transform="scale(2, 8)"><path d="M0 1 L5 1"/></g></g>'  # the mean scale: 4
        '<path d="M0 20 L10 20"/>'  # none set
        '<path d="M0 30 L10 30" stroke-width="0"/>'
    )
    svg = _svg(tmp_path, body, 'width="40" height="80" viewBox="0 0 20 40"')  # user units x 2
    got = read_svg_widths(svg)
    assert len(got) == len(read_svg(svg)) == 6
    assert got[0] == pytest.approx(6.0) and got[1] == pytest.approx(14.0)
    assert got[2] == pytest.approx(2 * 96 / 25.4) and got[3] == pytest.approx(3 * 4 * 2)
    assert got[4] is None and got[5] is None
    with pytest.raises(StrokeError, match="stroke-width: expected a length"):
        read_svg_widths(_svg(tmp_path, '<path d="M0 0 L9 9" stroke-width="wide"/>'))
