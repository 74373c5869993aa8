"""Strokes from SVG drawings (Inkscape, Illustrator, any editor that writes paths).

Every ``<path>``, ``<polyline>``, ``<polygon>`` and ``<line>`` becomes strokes, one per subpath,
in document order, in the pixel frame of the drawing: the root's ``viewBox`` mapped onto its
``width`` × ``height`` (``xMidYMid meet``, lengths in px, mm, cm, in, pt or pc at 96 dpi), then
every ``transform`` from the root down. Curves (cubic and quadratic Béziers, elliptical arcs)
are flattened to points about 1 px apart. A *layer* is a group whose Inkscape label, Illustrator
``data-name`` or ``id`` names it (case-insensitive); draw the source strokes in a layer
``source`` over the photo and the target strokes in a layer ``target``.
Content of ``<defs>``, ``<clipPath>``, ``<mask>``, ``<marker>``, ``<pattern>`` and ``<symbol>``
is not drawn and is skipped, as is ``<use>``. :func:`read_svg_widths` reads each stroke's drawn
width (``stroke-width``, as an attribute or in ``style``, inherited from the groups above it,
scaled by its transform), for the target widths of :func:`phloem.strokes.edit`.
"""

from __future__ import annotations

import math
import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .stroke_set import MAX_POINTS, Stroke, StrokeError

__all__ = ["read_svg", "read_svg_widths"]

F64 = NDArray[np.float64]
#: Largest SVG file read (a drawing of strokes is kilobytes).
MAX_BYTES = 64 * 1024 * 1024
#: Spacing of the points of a flattened curve, px.
STEP = 1.0
_UNITS = {"": 1.0, "px": 1.0, "pt": 96 / 72, "pc": 16.0, "mm": 96 / 25.4, "cm": 96 / 2.54, "in": 96.0}
_SKIP = {"defs", "clipPath", "mask", "marker", "pattern", "symbol", "use", "metadata", "title", "desc", "style"}
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_NUM_AT = re.compile(r"[\s,]*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)")
_FLAG_AT = re.compile(r"[\s,]*([01])")
_CMD_AT = re.compile(r"[\s,]*([MmLlHhVvCcSsQqTtAaZz])")
_END = re.compile(r"[\s,]*\Z")
_TRANSFORM = re.compile(r"\s*(matrix|translate|scale|rotate|skewX|skewY)\s*\(([^)]*)\)\s*,?")
_STYLE_WIDTH = re.compile(r"(?:^|;)\s*stroke-width\s*:\s*([^;]*)")
_ARGS = {"M": 2, "L": 2, "H": 1, "V": 1, "C": 6, "S": 4, "Q": 4, "T": 2, "A": 7, "Z": 0}


def _local(tag: Any) -> str:
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else ""


def _attr(el: ET.Element, name: str) -> str | None:
    for k, v in el.attrib.items():
        if _local(k) == name:
            return v
    return None


def _numbers(text: str, where: str) -> list[float]:
    vals = [float(v) for v in _NUMBER.findall(text)]
    if any(not math.isfinite(v) for v in vals):
        raise StrokeError(f"{where}: a number is too large")
    return vals


def _length(text: str | None, where: str, *, positive: bool = True) -> float | None:
    if text is None or text.strip().endswith("%"):
        return None
    m = re.fullmatch(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-z]*)\s*", text)
    if m is None or m.group(2) not in _UNITS:
        raise StrokeError(f"{where}: expected a length in px, mm, cm, in, pt or pc, got {text[:40]!r}")
    v = float(m.group(1)) * _UNITS[m.group(2)]
    if not math.isfinite(v) or (positive and v <= 0):
        raise StrokeError(f"{where}: expected a {'positive ' if positive else ''}length, got {text[:40]!r}")
    return v


def _transform(text: str | None, where: str) -> F64:
    """The 3 × 3 matrix of an SVG ``transform`` attribute (identity when absent)."""
    m = np.eye(3)
    if not text or not text.strip():
        return m
    pos = 0
    while pos < len(text):
        t = _TRANSFORM.match(text, pos)
        if t is None:
            if text[pos:].strip():
                raise StrokeError(f"{where}: cannot read transform {text[pos : pos + 40]!r}")
            break
        pos = t.end()
        name, a = t.group(1), _numbers(t.group(2), where)
        need = {"matrix": (6,), "translate": (1, 2), "scale": (1, 2), "rotate": (1, 3), "skewX": (1,), "skewY": (1,)}
        if len(a) not in need[name]:
            raise StrokeError(f"{where}: {name}() takes {' or '.join(map(str, need[name]))} numbers, got {len(a)}")
        if name == "matrix":
            step = np.array([[a[0], a[2], a[4]], [a[1], a[3], a[5]], [0, 0, 1]])
        elif name == "translate":
            step = np.array([[1, 0, a[0]], [0, 1, a[1] if len(a) > 1 else 0.0], [0, 0, 1]])
        elif name == "scale":
            step = np.diag([a[0], a[1] if len(a) > 1 else a[0], 1.0])
        elif name == "rotate":
            c, s = math.cos(math.radians(a[0])), math.sin(math.radians(a[0]))
            cx, cy = (a[1], a[2]) if len(a) == 3 else (0.0, 0.0)
            step = np.array([[c, -s, cx - c * cx + s * cy], [s, c, cy - s * cx - c * cy], [0, 0, 1]])
        elif name == "skewX":
            step = np.array([[1, math.tan(math.radians(a[0])), 0], [0, 1, 0], [0, 0, 1]])
        else:
            step = np.array([[1, 0, 0], [math.tan(math.radians(a[0])), 1, 0], [0, 0, 1]])
        m = m @ step
    return m


def _root_matrix(root: ET.Element) -> F64:
    """User units of the root onto pixels: ``viewBox`` onto ``width`` × ``height``, xMidYMid meet."""
    vb = _attr(root, "viewBox")
    w, h = _length(_attr(root, "width"), "width"), _length(_attr(root, "height"), "height")
    if vb is None:
        return np.eye(3)
    v = _numbers(vb, "viewBox")
    if len(v) != 4 or v[2] <= 0 or v[3] <= 0:
        raise StrokeError(f"viewBox: expected 'min-x min-y width height' with a positive size, got {vb[:40]!r}")
    w = w if w is not None else v[2]
    h = h if h is not None else v[3]
    s = min(w / v[2], h / v[3])
    tx, ty = (w - v[2] * s) / 2 - v[0] * s, (h - v[3] * s) / 2 - v[1] * s
    return np.array([[s, 0, tx], [0, s, ty], [0, 0, 1]])


def _cubic(p0: F64, p1: F64, p2: F64, p3: F64) -> F64:
    n = int(
        min(max(math.ceil(float(np.hypot(*(p1 - p0)) + np.hypot(*(p2 - p1)) + np.hypot(*(p3 - p2))) / STEP), 2), 4096)
    )
    t = np.linspace(0.0, 1.0, n + 1)[1:, None]
    return (1 - t) ** 3 * p0 + 3 * (1 - t) ** 2 * t * p1 + 3 * (1 - t) * t**2 * p2 + t**3 * p3


def _quadratic(p0: F64, p1: F64, p2: F64) -> F64:
    return _cubic(p0, p0 + 2 / 3 * (p1 - p0), p2 + 2 / 3 * (p1 - p2), p2)


def _arc(p0: F64, rx: float, ry: float, phi: float, large: bool, sweep: bool, p1: F64) -> F64:
    """Points of an SVG elliptical arc (endpoint parametrisation, SVG 1.1 F.6.5–F.6.6)."""
    if rx == 0 or ry == 0 or np.array_equal(p0, p1):
        return p1[None, :]
    rx, ry = abs(rx), abs(ry)
    c, s = math.cos(math.radians(phi)), math.sin(math.radians(phi))
    dx, dy = (p0 - p1) / 2
    x1, y1 = c * dx + s * dy, -s * dx + c * dy
    lam = (x1 / rx) ** 2 + (y1 / ry) ** 2
    if lam > 1:
        rx, ry = rx * math.sqrt(lam), ry * math.sqrt(lam)
    num = rx * rx * ry * ry - rx * rx * y1 * y1 - ry * ry * x1 * x1
    den = rx * rx * y1 * y1 + ry * ry * x1 * x1
    k = math.sqrt(max(num / den, 0.0)) if den > 0 else 0.0
    if large == sweep:
        k = -k
    cx1, cy1 = k * rx * y1 / ry, -k * ry * x1 / rx
    cx, cy = c * cx1 - s * cy1 + (p0[0] + p1[0]) / 2, s * cx1 + c * cy1 + (p0[1] + p1[1]) / 2
    t0 = math.atan2((y1 - cy1) / ry, (x1 - cx1) / rx)
    t1 = math.atan2((-y1 - cy1) / ry, (-x1 - cx1) / rx)
    dt = t1 - t0
    if sweep and dt < 0:
        dt += 2 * math.pi
    elif not sweep and dt > 0:
        dt -= 2 * math.pi
    n = int(min(max(math.ceil(abs(dt) * max(rx, ry) / STEP), 2), 4096))
    t = t0 + dt * np.linspace(0.0, 1.0, n + 1)[1:]
    ex, ey = rx * np.cos(t), ry * np.sin(t)
    out = np.stack([c * ex - s * ey + cx, s * ex + c * ey + cy], axis=1)
    out[-1] = p1
    return out


def _read_args(d: str, pos: int, cmd: str, where: str) -> tuple[list[float], int]:
    """The arguments of one ``cmd`` starting at ``d[pos]``; an arc's flags are single characters
    (compact writers give ``a5 5 0 1110 10`` for flags 1, 1 and the point 10 10)."""
    up = cmd.upper()
    out = []
    for k in range(_ARGS[up]):
        m = (_FLAG_AT if up == "A" and k in (3, 4) else _NUM_AT).match(d, pos)
        if m is None:
            what = "flag (0 or 1)" if up == "A" and k in (3, 4) else "number"
            raise StrokeError(
                f"{where}: command {cmd!r} needs {_ARGS[up]} numbers; expected a {what} at character {pos}"
            )
        v = float(m.group(1))
        if not math.isfinite(v):
            raise StrokeError(f"{where}: a number is too large")
        out.append(v)
        pos = m.end()
    return out, pos


def _path(d: str, where: str) -> list[F64]:
    """Subpaths of SVG path data as point arrays (user units)."""
    subpaths: list[list[F64]] = []
    cur: list[F64] = []
    pos = np.zeros(2)
    start = np.zeros(2)
    last_ctrl: F64 | None = None
    last_cmd = ""
    i, cmd = 0, ""
    while _END.match(d, i) is None:
        m = _CMD_AT.match(d, i)
        if m is not None:
            if not cmd and m.group(1) not in "Mm":
                raise StrokeError(f"{where}: path data must start with a moveto (M), got {m.group(1)!r}")
            cmd, i = m.group(1), m.end()
            if cmd in "Zz":
                if cur:
                    cur.append(start[None, :].copy())
                    subpaths.append(cur)
                    cur = []
                pos = start.copy()
                last_ctrl, last_cmd = None, "Z"
                continue
        elif not cmd:
            raise StrokeError(f"{where}: path data must start with a moveto (M)")
        elif cmd in "Zz":
            raise StrokeError(f"{where}: numbers after a closepath (Z) at character {i}")
        a, i = _read_args(d, i, cmd, where)
        up = cmd.upper()
        rel = cmd.islower()
        base = pos if rel else np.zeros(2)
        if up == "M":
            if cur:
                subpaths.append(cur)
            pos = base + a[:2]
            start = pos.copy()
            cur = [pos[None, :].copy()]
            cmd = "l" if rel else "L"  # further pairs are linetos
            last_ctrl, last_cmd = None, "M"
            continue
        if not cur:
            cur = [pos[None, :].copy()]
        if up == "L":
            new = base + a[:2]
            pts = new[None, :]
        elif up == "H":
            new = np.array([a[0] + (pos[0] if rel else 0.0), pos[1]])
            pts = new[None, :]
        elif up == "V":
            new = np.array([pos[0], a[0] + (pos[1] if rel else 0.0)])
            pts = new[None, :]
        elif up == "C":
            c1, c2, new = base + a[0:2], base + a[2:4], base + a[4:6]
            pts, last_ctrl = _cubic(pos, c1, c2, new), c2
        elif up == "S":
            c1 = 2 * pos - last_ctrl if last_ctrl is not None and last_cmd in "CS" else pos
            c2, new = base + a[0:2], base + a[2:4]
            pts, last_ctrl = _cubic(pos, c1, c2, new), c2
        elif up == "Q":
            q, new = base + a[0:2], base + a[2:4]
            pts, last_ctrl = _quadratic(pos, q, new), q
        elif up == "T":
            q = 2 * pos - last_ctrl if last_ctrl is not None and last_cmd in "QT" else pos
            new = base + a[0:2]
            pts, last_ctrl = _quadratic(pos, q, new), q
        else:  # A
            new = base + a[5:7]
            pts = _arc(pos, a[0], a[1], a[2], a[3] == 1.0, a[4] == 1.0, new)
        if up not in "CSQT":
            last_ctrl = None
        last_cmd = up
        cur.append(pts)
        pos = new
        if sum(len(p) for p in cur) > MAX_POINTS:
            raise StrokeError(f"{where}: the path flattens to more than {MAX_POINTS} points")
    if cur:
        subpaths.append(cur)
    return [np.concatenate(c) for c in subpaths]


def _element_points(el: ET.Element, name: str, where: str) -> list[F64]:
    if name == "path":
        return _path(_attr(el, "d") or "", where)
    if name in ("polyline", "polygon"):
        v = _numbers(_attr(el, "points") or "", where)
        if len(v) % 2:
            raise StrokeError(f"{where}: 'points' must hold x, y pairs, got an odd count ({len(v)})")
        pts = np.asarray(v, np.float64).reshape(-1, 2)
        if name == "polygon" and len(pts):
            pts = np.concatenate([pts, pts[:1]])
        return [pts] if len(pts) else []
    if name == "line":
        c: list[float] = []
        for k in ("x1", "y1", "x2", "y2"):
            length = _length(_attr(el, k) or "0", f"{where}: {k}", positive=False)
            c.append(0.0 if length is None else length)
        return [np.array([[c[0], c[1]], [c[2], c[3]]])]
    return []


def _label(el: ET.Element) -> str | None:
    for key in ("label", "data-name", "id"):
        v = _attr(el, key)
        if v:
            return v.strip().lower()
    return None


def _stroke_width(el: ET.Element, inherited: float | None, where: str) -> float | None:
    """The element's ``stroke-width`` in its user units (``style`` before the attribute, as CSS
    has it), else the inherited one; None where no element above sets one."""
    style = _attr(el, "style")
    m = _STYLE_WIDTH.search(style) if style else None
    text = m.group(1) if m else _attr(el, "stroke-width")
    if text is None or text.strip() in ("", "inherit"):
        return inherited
    return _length(text, f"{where}: stroke-width", positive=False)


def _walk(
    el: ET.Element, m: F64, in_layer: bool, layer: str | None, where: str, width: float | None = None
) -> Iterator[tuple[F64, float | None, str]]:
    for child in el:
        name = _local(child.tag)
        if name in _SKIP:
            continue
        cm = m @ _transform(_attr(child, "transform"), f"{where}: transform")
        inside = in_layer or layer is None or (name in ("g", "svg") and _label(child) == layer)
        w = _stroke_width(child, width, f"{where}: <{name}>")
        if name in ("g", "svg", "a", "switch"):
            yield from _walk(child, cm, inside, layer, where, w)
        elif inside:
            ident = _attr(child, "id")
            place = f"{where}: <{name}{' id=' + repr(ident) if ident else ''}>"
            # A stroke's width scales with the mean scale of its transform.
            px = None if w is None or w <= 0 else w * math.sqrt(abs(np.linalg.det(cm[:2, :2])))
            for pts in _element_points(child, name, place):
                xy = np.c_[pts, np.ones(len(pts))] @ cm.T
                yield xy[:, :2], px, place


def read_svg(svg: str | os.PathLike[str], *, layer: str | None = None) -> list[Stroke]:
    """The strokes drawn in an SVG file, in document order, in pixels.

    Parameters
    ----------
    svg : path-like
        The SVG file.
    layer : str, optional
        Only the strokes of the group (layer) with this label, Illustrator name or id
        (case-insensitive); default every stroke of the drawing.

    Returns
    -------
    list of Stroke
        One stroke per subpath; subpaths shorter than ``1e-3`` px (a click, not a stroke) are left out.

    Raises
    ------
    StrokeError
        An unreadable or malformed file, a layer that is absent or holds no stroke.
    """
    return [s for s, _ in _read(svg, layer)]


def read_svg_widths(svg: str | os.PathLike[str], *, layer: str | None = None) -> list[float | None]:
    """The drawn width in pixels of each stroke :func:`read_svg` returns, in the same order.

    ``stroke-width`` from the element's ``style`` or attribute, else from the nearest group
    above it that sets one, times the mean scale of the element's transform (and the
    ``viewBox``); None where nothing sets a width or it is 0. Draw the target strokes as
    thick as the object should be, and pass these as ``widths=`` to :func:`phloem.strokes.edit`
    (``phloem strokes edit --svg-widths``).

    Examples
    --------
    >>> import pathlib, tempfile
    >>> from phloem.strokes import read_svg_widths
    >>> svg = pathlib.Path(tempfile.mkdtemp()) / "t.svg"
    >>> _ = svg.write_text('<svg xmlns="http://www.w3.org/2000/svg"><g style="stroke-width:4">'
    ...                    '<path d="M0 0 L10 0"/><path d="M0 5 L10 5" stroke-width="9"/>'
    ...                    '<path d="M0 9 L5 9" transform="scale(2)"/></g></svg>')
    >>> read_svg_widths(svg)
    [4.0, 9.0, 8.0]
    """
    return [w for _, w in _read(svg, layer)]


def _read(svg: str | os.PathLike[str], layer: str | None) -> list[tuple[Stroke, float | None]]:
    p = Path(svg)
    try:
        size = p.stat().st_size
        if size > MAX_BYTES:
            raise StrokeError(f"svg: {p}: {size} bytes is larger than the {MAX_BYTES}-byte limit for a stroke drawing")
        root = ET.fromstring(p.read_bytes())
    except OSError as exc:
        raise StrokeError(f"svg: {p}: cannot read the file ({exc.strerror or exc})") from None
    except ET.ParseError as exc:
        raise StrokeError(f"svg: {p}: not a well-formed SVG file ({exc})") from None
    except RecursionError:
        raise StrokeError(f"svg: {p}: elements nested too deeply") from None
    if _local(root.tag) != "svg":
        raise StrokeError(f"svg: {p}: the root element is <{_local(root.tag)}>, expected <svg>")
    want = None if layer is None else str(layer).strip().lower()
    try:
        found = list(_walk(root, _root_matrix(root), False, want, f"svg: {p}"))
    except RecursionError:
        raise StrokeError(f"svg: {p}: elements nested too deeply") from None
    except StrokeError as exc:
        msg = str(exc)
        raise StrokeError(msg if msg.startswith("svg: ") else f"svg: {p}: {msg}") from None
    out = []
    for pts, width, place in found:
        try:
            out.append((Stroke(pts), width))
        except StrokeError as exc:
            if "zero length" in str(exc):
                continue
            raise StrokeError(f"{place}: {str(exc).removeprefix('points')}") from None
    if not out:
        what = f"layer {layer!r}" if layer is not None else "the drawing"
        raise StrokeError(f"svg: {p}: {what} holds no stroke (paths, polylines, polygons or lines)")
    return out
