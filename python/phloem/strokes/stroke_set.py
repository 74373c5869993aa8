"""Strokes and stroke sets (Luo, Lin, Shen & Chen, §2) and their JSON file format.

A :class:`Stroke` is a polyline of ``(x, y)`` pixel positions (origin top-left, the project's
convention) with a local orientation at every point (:meth:`Stroke.tangents`). A
:class:`StrokePair` joins a source stroke, drawn along the object's skeleton in the input
image, to the target stroke it is re-drawn along in the output, with control-point pairs
that pin positions of one to positions of the other. A control pair is two arc-length
fractions ``(u_source, u_target)`` in ``[0, 1]``; the stroke's two end points, ``(0, 0)`` and
``(1, 1)``, are always controls (the paper's default), further pairs must increase along both
strokes. A :class:`StrokeSet` is the list of pairs, optionally with the input image's shape
and the output's size.

The file format is JSON::

    {"format": "phloem.strokes", "version": 1,
     "source_shape": [H, W],               # optional: the input image the source strokes lie on
     "target_size": [H, W],                # optional: the output image
     "pairs": [
        {"source": [[x, y], ...], "target": [[x, y], ...],
         "controls": [[0, 0], [0.4, 0.55], [1, 1]],       # optional; default the end points
         "width": 24},                                     # optional: see below
        ...
     ]}

A pair's optional ``width`` is the object's width wanted along the target stroke, in output px:
a number, or ``[[u, width], ...]`` at arc-length fractions ``u`` of the target stroke
(increasing; linear in between, constant beyond the first and last). Without it the object
keeps its width in the photo (the paper); with it each piece is scaled by the ratio of the
wanted width to the object's width across the source stroke there.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from .._json import JsonFile, is_number, short_repr

__all__ = ["Stroke", "StrokeError", "StrokePair", "StrokeSet"]

F64 = NDArray[np.float64]
FORMAT = "phloem.strokes"
VERSION = 1
#: No image phloem reads is wider than 2^20 px (its pixel limit is 2^28).
MAX_COORD = 2.0**20
#: Points of one stroke, and pairs of one set: bounds that keep every loop over a file finite.
MAX_POINTS = 2**20
MAX_PAIRS = 4096
#: Shortest stroke, in px: a shorter one has no direction to align texture to.
MIN_LENGTH = 1e-3


class StrokeError(ValueError):
    """A stroke, stroke set or stroke file that is malformed or does not fit its image."""


def _as_points(points: Any, where: str) -> F64:
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise StrokeError(f"{where}: expected an (N, 2) array of (x, y) points") from None
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise StrokeError(f"{where}: expected an (N, 2) array of (x, y) points, got shape {arr.shape}")
    if not 2 <= arr.shape[0] <= MAX_POINTS:
        raise StrokeError(f"{where}: a stroke needs 2 to {MAX_POINTS} points, got {arr.shape[0]}")
    bad = ~(np.abs(arr) <= MAX_COORD).all(axis=1)
    if bad.any():
        j = int(np.argmax(bad))
        raise StrokeError(
            f"{where}[{j}]: coordinates must be finite (no NaN or infinity) and within ±{MAX_COORD:.0f} px, "
            f"got {arr[j].tolist()}"
        )
    # Repeated points carry no direction; dropping them keeps every tangent defined.
    keep = np.ones(len(arr), bool)
    keep[1:] = (np.diff(arr, axis=0) != 0).any(axis=1)
    arr = arr[keep]
    length = float(np.hypot(*np.diff(arr, axis=0).T).sum()) if len(arr) > 1 else 0.0
    if length < MIN_LENGTH:
        raise StrokeError(f"{where}: the stroke has zero length; expected at least two distinct points")
    return np.ascontiguousarray(arr)


@dataclass(frozen=True, eq=False)
class Stroke:
    """A polyline of ``(x, y)`` points with a direction at every point.

    Parameters
    ----------
    points : (N, 2) array_like
        Pixel positions ``(x, y)``, in drawing order; at least two distinct ones. Consecutive
        repeats are dropped.

    Examples
    --------
    >>> from phloem.strokes import Stroke
    >>> s = Stroke([[0, 0], [30, 0], [30, 40]])
    >>> s.length(), s.tangents()[1].round(3).tolist(), s.at(0.5).tolist()
    (70.0, [0.707, 0.707], [30.0, 5.0])
    """

    points: F64

    def __post_init__(self) -> None:
        object.__setattr__(self, "points", _as_points(self.points, "points"))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Stroke) and np.array_equal(self.points, other.points)

    def __hash__(self) -> int:
        return hash(self.points.tobytes())

    def __len__(self) -> int:
        return len(self.points)

    def arc(self) -> F64:
        """Cumulative arc length at every point, ``(N,)`` from 0 to :meth:`length`."""
        seg = np.hypot(*np.diff(self.points, axis=0).T)
        return np.concatenate([[0.0], np.cumsum(seg)])

    def length(self) -> float:
        """Length of the polyline in px."""
        return float(self.arc()[-1])

    def tangents(self) -> F64:
        """Unit direction ``(dx, dy)`` at every point, ``(N, 2)``: the mean of the directions of
        the two edges that meet there (the edge's own at the ends; the incoming edge's where
        the stroke turns back on itself)."""
        d = np.diff(self.points, axis=0)
        d /= np.hypot(d[:, 0], d[:, 1])[:, None]
        t = np.empty_like(self.points)
        t[0], t[-1] = d[0], d[-1]
        mid = d[:-1] + d[1:]
        n = np.hypot(mid[:, 0], mid[:, 1])
        t[1:-1] = np.where((n > 1e-12)[:, None], mid / np.maximum(n, 1e-12)[:, None], d[:-1])
        return t

    def at(self, u: Any) -> F64:
        """Positions at arc-length fractions ``u`` in ``[0, 1]`` (clipped), shape ``u.shape + (2,)``."""
        s = self.arc()
        q = np.clip(np.asarray(u, dtype=np.float64), 0.0, 1.0) * s[-1]
        x = np.interp(q, s, self.points[:, 0])
        y = np.interp(q, s, self.points[:, 1])
        return np.stack([x, y], axis=-1)

    def directions(self, u: Any, *, half: float = 2.0) -> F64:
        """Unit directions at arc-length fractions ``u``, shape ``u.shape + (2,)``: each the chord
        over ``± half`` px of arc (clipped to the stroke), so a polyline's corners and a traced
        skeleton's pixel steps do not jitter what follows the stroke."""
        length = self.length()
        q = np.asarray(u, dtype=np.float64) * length
        d = self.at(np.clip(q + half, 0.0, length) / length) - self.at(np.clip(q - half, 0.0, length) / length)
        n = np.hypot(d[..., 0], d[..., 1])
        good = n > 1e-9
        out = np.where(good[..., None], d / np.where(good, n, 1.0)[..., None], self.tangents()[0])
        return np.asarray(out / np.hypot(out[..., 0], out[..., 1])[..., None], dtype=np.float64)

    def project(self, point: Any) -> float:
        """The arc-length fraction of the stroke's point nearest ``point`` ``(x, y)``."""
        p = np.asarray(point, dtype=np.float64).reshape(2)
        a, b = self.points[:-1], self.points[1:]
        ab = b - a
        t = np.clip(((p - a) * ab).sum(1) / (ab * ab).sum(1), 0.0, 1.0)
        near = a + t[:, None] * ab
        j = int(np.argmin(((near - p) ** 2).sum(1)))
        s = self.arc()
        return float((s[j] + t[j] * (s[j + 1] - s[j])) / s[-1])

    def bounds(self) -> tuple[float, float, float, float]:
        """``(x_min, y_min, x_max, y_max)`` of the points."""
        lo, hi = self.points.min(axis=0), self.points.max(axis=0)
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def _as_controls(controls: Any, where: str) -> F64:
    if controls is None:
        return np.array([[0.0, 0.0], [1.0, 1.0]])
    try:
        arr = np.asarray(controls, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise StrokeError(f"{where}: expected (K, 2) pairs of arc-length fractions (u_source, u_target)") from None
    if arr.ndim != 2 or arr.shape[1] != 2 or not 2 <= len(arr) <= MAX_POINTS:
        raise StrokeError(
            f"{where}: expected (K, 2) pairs of arc-length fractions (u_source, u_target), K >= 2, got shape {arr.shape}"
        )
    if not ((arr >= 0) & (arr <= 1)).all():
        raise StrokeError(f"{where}: arc-length fractions must lie in [0, 1] (and not be NaN)")
    if arr[0].tolist() != [0.0, 0.0] or arr[-1].tolist() != [1.0, 1.0]:
        raise StrokeError(f"{where}: the first pair must be [0, 0] and the last [1, 1] (the strokes' end points)")
    if not ((np.diff(arr, axis=0) > 0).all()):
        j = int(np.argmax(~(np.diff(arr, axis=0) > 0).all(axis=1))) + 1
        raise StrokeError(
            f"{where}[{j}]: control pairs must increase along both strokes, got {arr[j - 1].tolist()} then {arr[j].tolist()}"
        )
    return np.ascontiguousarray(arr)


def _as_width(width: Any, where: str) -> F64 | None:
    """A pair's target width: None, a number, or (K, 2) ``(u, width)`` pairs; as (K, 2) pairs."""
    if width is None:
        return None
    if isinstance(width, (bool, np.bool_)):
        raise StrokeError(f"{where}: expected a width in px or (K, 2) pairs (u, width), got {width!r}")
    if np.ndim(width) == 0:
        try:
            arr = np.full((2, 2), float(width))
        except (TypeError, ValueError, OverflowError):
            raise StrokeError(f"{where}: expected a width in px or (K, 2) pairs (u, width)") from None
        arr[:, 0] = (0.0, 1.0)
    else:
        try:
            arr = np.asarray(width, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            raise StrokeError(f"{where}: expected a width in px or (K, 2) pairs (u, width)") from None
        if arr.ndim != 2 or arr.shape[1] != 2 or not 1 <= len(arr) <= MAX_POINTS:
            raise StrokeError(f"{where}: expected a width in px or (K, 2) pairs (u, width), got shape {arr.shape}")
        if not ((arr[:, 0] >= 0) & (arr[:, 0] <= 1)).all():
            raise StrokeError(f"{where}: arc-length fractions u must lie in [0, 1] (and not be NaN)")
        if not (np.diff(arr[:, 0]) > 0).all():
            raise StrokeError(f"{where}: arc-length fractions u must increase")
    if not ((arr[:, 1] > 0) & (arr[:, 1] <= MAX_COORD)).all():
        raise StrokeError(f"{where}: widths must be positive px (at most {MAX_COORD:.0f}), got {arr[:, 1].tolist()}")
    return np.ascontiguousarray(arr)


@dataclass(frozen=True, eq=False)
class StrokePair:
    """A source stroke, the target stroke it is re-drawn along, and their control pairs.

    Parameters
    ----------
    source, target : Stroke or (N, 2) array_like
        The strokes, ``(x, y)`` points; the source in the input image, the target in the output.
    controls : (K, 2) array_like, optional
        Arc-length fractions ``(u_source, u_target)``, from ``(0, 0)`` to ``(1, 1)``, increasing
        in both; default the end points only.
    width : float or (K, 2) array_like, optional
        The object's width wanted along the target stroke, in output px: one number, or
        ``(u, width)`` pairs at increasing arc-length fractions ``u`` of the target (linear in
        between, constant beyond). Default None: the object's own width in the photo.
    """

    source: Stroke
    target: Stroke
    controls: F64
    width: F64 | None

    def __init__(self, source: Any, target: Any, controls: Any = None, width: Any = None) -> None:
        object.__setattr__(self, "source", _stroke(source, "source"))
        object.__setattr__(self, "target", _stroke(target, "target"))
        object.__setattr__(self, "controls", _as_controls(controls, "controls"))
        object.__setattr__(self, "width", _as_width(width, "width"))

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, StrokePair)
            and self.source == other.source
            and self.target == other.target
            and np.array_equal(self.controls, other.controls)
            and _same_width(self.width, other.width)
        )

    def __hash__(self) -> int:
        return hash(
            (self.source, self.target, self.controls.tobytes(), None if self.width is None else self.width.tobytes())
        )

    def width_at(self, u: Any) -> F64 | None:
        """The wanted width (px) at arc-length fractions ``u`` of the target, or None."""
        if self.width is None:
            return None
        return np.interp(np.asarray(u, np.float64), self.width[:, 0], self.width[:, 1])

    def with_controls(self, points: Sequence[tuple[Any, Any]]) -> StrokePair:
        """This pair with control pairs pinned at point pairs ``[((xs, ys), (xt, yt)), ...]``:
        each point is projected onto its stroke, and the pairs join the end points in order
        along the source stroke."""
        uv = [(self.source.project(p), self.target.project(q)) for p, q in points]
        uv.sort()
        return StrokePair(self.source, self.target, [(0.0, 0.0), *uv, (1.0, 1.0)], self.width)


def _same_width(a: F64 | None, b: F64 | None) -> bool:
    return (a is None and b is None) or (a is not None and b is not None and np.array_equal(a, b))


def _stroke(value: Any, where: str) -> Stroke:
    if isinstance(value, Stroke):
        return value
    try:
        return Stroke(value)
    except StrokeError as exc:
        msg = str(exc)
        raise StrokeError(where + msg[len("points") :] if msg.startswith("points") else f"{where}: {msg}") from None


def _check_shape(value: Any, where: str) -> tuple[int, int]:
    if not (
        isinstance(value, (list, tuple))
        and len(value) == 2
        and all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and 1 <= v <= MAX_COORD for v in value)
    ):
        raise StrokeError(f"{where}: expected [H, W] with two positive integers, got {short_repr(value)}")
    return int(value[0]), int(value[1])


@dataclass(frozen=True)
class StrokeSet(JsonFile):
    """Corresponding source and target strokes (Luo et al. §2: ``S_s`` and ``S_t``).

    Parameters
    ----------
    pairs : sequence of StrokePair
        At least one pair.
    source_shape : (H, W), optional
        The input image the source strokes lie on; when given, every source point must lie in it.
    target_size : (H, W), optional
        The output image; when given, every target point must lie in it.
    """

    error: ClassVar[type[ValueError]] = StrokeError
    file_format: ClassVar[str] = FORMAT
    file_version: ClassVar[int] = VERSION
    what: ClassVar[str] = "stroke set"
    pairs: tuple[StrokePair, ...]
    source_shape: tuple[int, int] | None = None
    target_size: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        pairs = tuple(self.pairs)
        if not 1 <= len(pairs) <= MAX_PAIRS:
            raise StrokeError(f"pairs: expected 1 to {MAX_PAIRS} stroke pairs, got {len(pairs)}")
        for i, p in enumerate(pairs):
            if not isinstance(p, StrokePair):
                raise StrokeError(f"pairs[{i}]: expected a StrokePair, got {type(p).__name__}")
        object.__setattr__(self, "pairs", pairs)
        if self.source_shape is not None:
            object.__setattr__(self, "source_shape", _check_shape(list(self.source_shape), "source_shape"))
            self._inside("source", self.source_shape)
        if self.target_size is not None:
            object.__setattr__(self, "target_size", _check_shape(list(self.target_size), "target_size"))
            self._inside("target", self.target_size)

    def _inside(self, side: str, shape: tuple[int, int]) -> None:
        h, w = shape
        for i, p in enumerate(self.pairs):
            pts = getattr(p, side).points
            out = ~((pts[:, 0] >= 0) & (pts[:, 0] <= w - 1) & (pts[:, 1] >= 0) & (pts[:, 1] <= h - 1))
            if out.any():
                j = int(np.argmax(out))
                raise StrokeError(
                    f"pairs[{i}].{side}[{j}]: point {pts[j].tolist()} lies outside the {w}×{h} image "
                    f"(x in [0, {w - 1}], y in [0, {h - 1}])"
                )

    @classmethod
    def from_lists(
        cls,
        source: Sequence[Any],
        target: Sequence[Any],
        *,
        controls: Sequence[Any] | None = None,
        widths: Sequence[Any] | None = None,
        source_shape: tuple[int, int] | None = None,
        target_size: tuple[int, int] | None = None,
    ) -> StrokeSet:
        """Pair ``source[i]`` with ``target[i]`` (lists of strokes or (N, 2) arrays of (x, y)),
        with ``controls[i]`` as their control pairs (default the end points) and ``widths[i]``
        as the object's width wanted along the target (see :class:`StrokePair`; default the
        object's own).

        Examples
        --------
        >>> from phloem.strokes import StrokeSet
        >>> body = [[10, 50], [90, 50]]           # along the object in the photo
        >>> bent = [[20, 80], [60, 20], [120, 60]]  # the same object, re-drawn bent
        >>> s = StrokeSet.from_lists([body], [bent], controls=[[[0, 0], [0.5, 0.4], [1, 1]]], target_size=(128, 128))
        >>> StrokeSet.from_json(s.to_json()) == s
        True
        >>> StrokeSet.from_lists([body], [])
        Traceback (most recent call last):
        ...
        phloem.strokes.stroke_set.StrokeError: target: expected one target stroke per source stroke (1), got 0
        """
        for name, v in (("source", source), ("target", target)):
            if isinstance(v, (np.ndarray, str)) or not isinstance(v, Sequence):
                raise StrokeError(
                    f"{name}: expected a list of strokes ((N, 2) arrays of (x, y)), got {type(v).__name__}"
                )
        if len(source) != len(target):
            raise StrokeError(
                f"target: expected one target stroke per source stroke ({len(source)}), got {len(target)}"
            )
        for name, per in (("controls", controls), ("widths", widths)):
            if per is not None and len(per) != len(source):
                raise StrokeError(f"{name}: expected one entry per stroke pair ({len(source)}), got {len(per)}")
        pairs = []
        for i, (s, t) in enumerate(zip(source, target, strict=True)):
            try:
                pairs.append(
                    StrokePair(s, t, None if controls is None else controls[i], None if widths is None else widths[i])
                )
            except StrokeError as exc:
                raise StrokeError(_at_pair(exc, i)) from None
        return cls(tuple(pairs), source_shape, target_size)

    def bounds(self, side: str = "target") -> tuple[float, float, float, float]:
        """``(x_min, y_min, x_max, y_max)`` over the ``"source"`` or ``"target"`` strokes."""
        if side not in ("source", "target"):
            raise ValueError(f"side: expected 'source' or 'target', got {side!r}")
        b = np.array([getattr(p, side).bounds() for p in self.pairs])
        return float(b[:, 0].min()), float(b[:, 1].min()), float(b[:, 2].max()), float(b[:, 3].max())

    def to_dict(self) -> dict[str, Any]:
        """The file format's dictionary."""
        out: dict[str, Any] = {"format": FORMAT, "version": VERSION}
        if self.source_shape is not None:
            out["source_shape"] = list(self.source_shape)
        if self.target_size is not None:
            out["target_size"] = list(self.target_size)
        out["pairs"] = []
        for p in self.pairs:
            pair: dict[str, Any] = {
                "source": p.source.points.tolist(),
                "target": p.target.points.tolist(),
                "controls": p.controls.tolist(),
            }
            if p.width is not None:
                pair["width"] = p.width.tolist()
            out["pairs"].append(pair)
        return out

    @classmethod
    def from_dict(cls, data: Any) -> StrokeSet:
        """Build a stroke set from the file format's dictionary, with errors that say what is wrong."""
        data = cls.check_header(data)
        pairs = data.get("pairs")
        if not isinstance(pairs, list) or not pairs:
            raise StrokeError("'pairs' must be a non-empty list of {'source': ..., 'target': ...} objects")
        out = []
        for i, p in enumerate(pairs):
            where = f"pairs[{i}]"
            if not isinstance(p, dict) or "source" not in p or "target" not in p:
                raise StrokeError(f"{where} must be an object with 'source' and 'target' point lists (and 'controls')")
            src = _json_pairs(p["source"], f"{where}.source")
            tgt = _json_pairs(p["target"], f"{where}.target")
            ctl = None if p.get("controls") is None else _json_pairs(p["controls"], f"{where}.controls")
            wid = p.get("width")
            if wid is not None and not is_number(wid):
                wid = _json_pairs(wid, f"{where}.width")
            try:
                out.append(StrokePair(src, tgt, ctl, wid))
            except StrokeError as exc:
                raise StrokeError(_at_pair(exc, i)) from None
        shape = None if data.get("source_shape") is None else _check_shape(data["source_shape"], "source_shape")
        size = None if data.get("target_size") is None else _check_shape(data["target_size"], "target_size")
        return cls(tuple(out), shape, size)


def _at_pair(exc: StrokeError, i: int) -> str:
    """``exc``'s message with the pair it concerns named first."""
    msg = str(exc)
    if msg.startswith(("source", "target", "controls", "width")):
        return f"pairs[{i}].{msg}"
    return f"pairs[{i}]: {msg}"


def _json_pairs(points: Any, where: str) -> Any:
    """A file's list of number pairs, type-checked (numpy would read "1" or true as numbers)."""
    if not isinstance(points, list):
        raise StrokeError(f"{where} must be a list of number pairs, got {type(points).__name__}")
    if len(points) > MAX_POINTS:
        raise StrokeError(f"{where}: at most {MAX_POINTS} points, got {len(points)}")
    for j, p in enumerate(points):
        if not (isinstance(p, list) and len(p) == 2 and is_number(p[0]) and is_number(p[1])):
            raise StrokeError(f"{where}[{j}] must be a pair of two numbers, got {short_repr(p)}")
    return points
