"""The skeleton of a branching structure (Sibbing et al. 2010, §4.1) and its JSON file format.

A :class:`Skeleton` is a list of :class:`Branch` polylines. Every branch holds its vertices as
``(x, y)`` pixel positions (origin top-left, the project's convention), a thickness (radius, in
pixels) per vertex, and the branch and vertex it grows out of (``parent``; ``None`` for a root).
A parent always comes before its children in the list, so a skeleton is a forest by
construction.

After :meth:`Skeleton.resample` every edge of every branch has the same length ``h``; the
signed turning angles between successive edges (:meth:`Branch.angles`) and the thicknesses then
define each branch up to a rigid motion (§4.1), which is what the bending and furcation models
learn from.

The file format is JSON::

    {"format": "phloem.skeleton", "version": 1,
     "shape": [H, W],                      # optional: the image the skeleton belongs to
     "branches": [
        {"points": [[x, y], ...], "thickness": [r, ...], "parent": null},
        {"points": [[x, y], ...], "thickness": [r, ...], "parent": [0, 17]}
     ]}
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import cv2
import numpy as np
from numpy.typing import NDArray

from .. import _core
from .._api import Size, renamed
from .._json import JsonFile, is_number, short_repr
from .._validate import as_image, check_float, check_size

__all__ = ["Branch", "Skeleton", "SkeletonError"]

F64 = NDArray[np.float64]
FORMAT = "phloem.skeleton"
VERSION = 1
# Bounds that keep every loop over a skeleton finite and every OpenCV drawing call valid: no
# image phloem reads is wider than 2^20 px (the pixel limit is 2^28), OpenCV refuses line
# thicknesses over 32767 (a radius of 2^14), and resampling makes at most MAX_VERTICES vertices
# (what that costs to fit: docs/hardening/inputs.md).
MAX_COORD = 2.0**20
MAX_THICKNESS = 2.0**13
MAX_VERTICES = 2**20
_MAX_LENGTH = 2**28


class SkeletonError(ValueError):
    """A skeleton (or skeleton file) that is malformed or does not fit its image."""


def _as_points(points: Any, where: str) -> F64:
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise SkeletonError(f"{where}: points must be a list of [x, y] number pairs") from None
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise SkeletonError(f"{where}: points must have shape (n, 2), got {arr.shape}")
    if arr.shape[0] < 2:
        raise SkeletonError(f"{where}: a branch needs at least 2 points, got {arr.shape[0]}")
    bad = ~(np.abs(arr) <= MAX_COORD).all(axis=1)
    if bad.any():
        j = int(np.argmax(bad))
        raise SkeletonError(
            f"{where}.points[{j}]: coordinates must be finite (no NaN or infinity) and within ±{MAX_COORD:.0f} px, got {arr[j].tolist()}"
        )
    return np.ascontiguousarray(arr)


def _as_thickness(thickness: Any, n: int, where: str) -> F64:
    try:
        arr = np.asarray(thickness, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise SkeletonError(f"{where}: thickness must be a number or a list of numbers") from None
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise SkeletonError(f"{where}: thickness must have one value per point ({n}), got shape {arr.shape}")
    bad = ~((arr >= 0) & (arr <= MAX_THICKNESS))
    if bad.any():
        j = int(np.argmax(bad))
        raise SkeletonError(
            f"{where}.thickness[{j}]: expected a radius in [0, {MAX_THICKNESS:.0f}] px, got {float(arr[j])!r}"
        )
    return np.ascontiguousarray(arr)


def _json_points(points: Any, where: str) -> Any:
    """The points of a file's branch, type-checked (numpy would read "1" or true as numbers)."""
    if not isinstance(points, list):
        raise SkeletonError(f"{where}.points must be a list of [x, y] pairs, got {type(points).__name__}")
    for j, p in enumerate(points):
        if not (isinstance(p, list) and len(p) == 2 and is_number(p[0]) and is_number(p[1])):
            raise SkeletonError(f"{where}.points[{j}] must be [x, y] with two numbers, got {short_repr(p)}")
    return points


def _json_thickness(thickness: Any, where: str) -> Any:
    if is_number(thickness):
        return thickness
    if not isinstance(thickness, list):
        raise SkeletonError(f"{where}.thickness must be a number or a list of numbers, got {type(thickness).__name__}")
    for j, t in enumerate(thickness):
        if not is_number(t):
            raise SkeletonError(f"{where}.thickness[{j}] must be a number, got {short_repr(t)}")
    return thickness


@dataclass
class Branch:
    """One polyline of a skeleton.

    Attributes
    ----------
    points : ndarray of float64, shape (n, 2)
        Vertices as ``(x, y)`` pixel positions, ``n >= 2``.
    thickness : ndarray of float64, shape (n,)
        Branch radius at each vertex, in pixels.
    parent : tuple of int or None
        ``(branch index, vertex index)`` of the parent vertex this branch grows out of, or
        ``None`` for a root branch.
    """

    points: F64
    thickness: F64
    parent: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        self.points = _as_points(self.points, "branch")
        self.thickness = _as_thickness(self.thickness, len(self.points), "branch")
        if self.parent is not None:
            self.parent = (int(self.parent[0]), int(self.parent[1]))

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def length(self) -> float:
        """Arc length of the polyline in pixels."""
        return float(np.linalg.norm(np.diff(self.points, axis=0), axis=1).sum())

    def angles(self) -> F64:
        """Signed turning angles ``α_i`` at the interior vertices, in radians in ``(-π, π]``.

        ``α_i`` (``i = 1 .. n-2``) is the angle from edge ``x_i - x_(i-1)`` to edge
        ``x_(i+1) - x_i``; positive turns are counter-clockwise on the screen (towards ``-y``).
        The result has ``n - 2`` entries. :meth:`from_angles` inverts it.

        Examples
        --------
        >>> b = Branch([[0, 0], [1, 0], [1, -1]], [1, 1, 1])
        >>> b.angles().round(4)
        array([1.5708])
        """
        d = np.diff(self.points, axis=0)
        # Screen y grows downwards, so a counter-clockwise turn on screen has a negative cross
        # product in (x, y); flip the sign so that positive means counter-clockwise as seen.
        heading = np.arctan2(-d[:, 1], d[:, 0])
        turn = np.diff(heading)
        return np.asarray(np.pi - (np.pi - turn) % (2 * np.pi), dtype=np.float64)

    def heading(self) -> float:
        """Direction of the first edge, in radians, counter-clockwise on screen from ``+x``."""
        d = self.points[1] - self.points[0]
        return float(math.atan2(-d[1], d[0]))

    @classmethod
    def from_angles(
        cls,
        start: Sequence[float],
        heading: float,
        angles: Any,
        thickness: Any,
        h: float,
        parent: tuple[int, int] | None = None,
    ) -> Branch:
        """Rebuild a branch from its start, first heading, turning angles and edge length ``h``.

        Examples
        --------
        >>> b = Branch([[0, 0], [2, 0], [2, 2], [4, 2]], [1, 2, 3, 4])
        >>> c = Branch.from_angles(b.points[0], b.heading(), b.angles(), b.thickness, 2.0)
        >>> bool(np.allclose(c.points, b.points))
        True
        """
        angles = np.asarray(angles, dtype=np.float64)
        headings = heading + np.concatenate([[0.0], np.cumsum(angles)])
        steps = h * np.stack([np.cos(headings), -np.sin(headings)], axis=1)
        pts = np.vstack(
            [
                np.asarray(start, dtype=np.float64)[None, :],
                np.asarray(start, dtype=np.float64) + np.cumsum(steps, axis=0),
            ]
        )
        return cls(pts, thickness, parent)

    def resample(self, h: float) -> Branch:
        """Resample to constant edge length ``h`` by arc length.

        Vertices are placed at arc lengths ``0, h, 2h, ...``; a remainder shorter than ``h`` at
        the end is dropped (a branch shorter than ``h`` keeps its two end points). Thickness is
        interpolated linearly by arc length.
        """
        h = check_float(h, "h", 0.0, inclusive=False)
        seg = np.linalg.norm(np.diff(self.points, axis=0), axis=1)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        total = float(cum[-1])
        if total / h + 2 > MAX_VERTICES:
            raise ValueError(
                f"h: resampling a {total:.3g}-px branch at h={h:g} would make about {total / h:.3g} vertices,"
                f" more than the limit of {MAX_VERTICES}; pass a larger h"
            )
        count = math.floor(total / h + 1e-9) + 1
        if count < 2:
            return Branch(self.points[[0, -1]].copy(), self.thickness[[0, -1]].copy(), self.parent)
        # Points at arc lengths k*h would leave chords shorter than h where the polyline turns;
        # the walk goes by chords instead so that every edge has length exactly h (fewer
        # vertices where the polyline is very curved). Thickness follows the arc length of each
        # new vertex's nearest point on the old polyline (phloem_core::resample).
        pts, s = _core.polyline_resample(np.ascontiguousarray(self.points), cum, count, float(h))
        thick = np.interp(s, cum, self.thickness)
        return Branch(pts, thick, self.parent)


@dataclass
class Skeleton(JsonFile):
    """A branching structure: branches with thickness, each child attached to a parent vertex.

    Parameters
    ----------
    branches : list of Branch
        Parents come before their children.
    shape : tuple of int, optional
        ``(H, W)`` of the image the skeleton belongs to; when given, every vertex must lie
        inside it.

    Examples
    --------
    >>> sk = Skeleton([Branch([[0, 0], [5, 0], [10, 0]], 2.0), Branch([[5, 0], [5, 8]], 1.0, parent=(0, 1))])
    >>> r = sk.resample(1.0)
    >>> [len(b) for b in r.branches], r.branches[1].parent
    ([11, 9], (0, 5))
    >>> Skeleton.from_json(sk.to_json()) == sk
    True
    """

    error: ClassVar[type[ValueError]] = SkeletonError
    file_format: ClassVar[str] = FORMAT
    file_version: ClassVar[int] = VERSION
    what: ClassVar[str] = "skeleton"
    branches: list[Branch] = field(default_factory=list)
    shape: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        self.branches = list(self.branches)
        if self.shape is not None:
            self.shape = (int(self.shape[0]), int(self.shape[1]))
        self.validate()

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Skeleton) or self.shape != other.shape or len(self.branches) != len(other.branches):
            return False
        return all(
            a.parent == b.parent and np.array_equal(a.points, b.points) and np.array_equal(a.thickness, b.thickness)
            for a, b in zip(self.branches, other.branches)
        )

    def validate(self) -> None:
        """Raise :class:`SkeletonError` if parents are out of order or vertices leave the image."""
        for i, b in enumerate(self.branches):
            if not isinstance(b, Branch):
                raise SkeletonError(f"branches[{i}] must be a Branch, got {type(b).__name__}")
            if b.parent is not None:
                pb, pv = b.parent
                if not 0 <= pb < i:
                    raise SkeletonError(
                        f"branches[{i}].parent: branch index {pb} must refer to an earlier branch (0..{i - 1})"
                    )
                if not 0 <= pv < len(self.branches[pb]):
                    raise SkeletonError(
                        f"branches[{i}].parent: vertex {pv} is outside branch {pb} ({len(self.branches[pb])} vertices)"
                    )
        if self.shape is not None:
            self.check_inside(self.shape)
        elif (total := self.total_length()) > _MAX_LENGTH:
            raise SkeletonError(
                f"branches: a total length of {total:.3g} px is more than any image phloem reads can hold"
                f" ({_MAX_LENGTH} px, the pixel limit)"
            )

    def check_inside(self, shape: tuple[int, int], name: str = "") -> None:
        """Raise :class:`SkeletonError` naming the first vertex outside an ``(H, W)`` image.

        ``name`` (e.g. ``"target_skeleton"``) prefixes the message.
        """
        h, w = shape
        for i, b in enumerate(self.branches):
            x, y = b.points[:, 0], b.points[:, 1]
            bad = (x < -0.5) | (y < -0.5) | (x > w - 0.5) | (y > h - 0.5)
            if bad.any():
                j = int(np.argmax(bad))
                where = f"{name}: branches[{i}]" if name else f"branches[{i}]"
                raise SkeletonError(f"{where}.points[{j}] = ({x[j]:.1f}, {y[j]:.1f}) is outside the {w}x{h} image")

    @classmethod
    def stack(cls, parts: Sequence[Skeleton]) -> Skeleton:
        """The skeletons one below the other in one image: a forest with their branches.

        Each part is moved down by the heights of the parts above it; parent indices are
        renumbered. Every part needs a ``shape``.

        Examples
        --------
        >>> a = Skeleton([Branch([[0, 1], [4, 1]], 1.0)], (3, 5))
        >>> b = Skeleton([Branch([[1, 0], [1, 2]], 1.0), Branch([[1, 1], [3, 1]], 1.0, parent=(0, 1))], (4, 6))
        >>> s = Skeleton.stack([a, b])
        >>> s.shape, s.branches[2].parent, s.branches[1].points[0].tolist()
        ((7, 6), (1, 1), [1.0, 3.0])
        """
        out: list[Branch] = []
        y0, width = 0, 0
        for i, part in enumerate(parts):
            if part.shape is None:
                raise SkeletonError(f"parts[{i}]: a skeleton without a shape cannot be stacked")
            base = len(out)
            for b in part.branches:
                parent = None if b.parent is None else (b.parent[0] + base, b.parent[1])
                out.append(Branch(b.points + [0.0, float(y0)], b.thickness.copy(), parent))
            y0 += part.shape[0]
            width = max(width, part.shape[1])
        if not out:
            raise SkeletonError("parts: expected at least one skeleton with branches")
        return cls(out, (y0, width))

    # -- geometry ---------------------------------------------------------------------------

    def children(self) -> dict[int, list[tuple[int, int]]]:
        """For each branch index, its ``(vertex index, child branch index)`` furcations."""
        out: dict[int, list[tuple[int, int]]] = {i: [] for i in range(len(self.branches))}
        for i, b in enumerate(self.branches):
            if b.parent is not None:
                out[b.parent[0]].append((b.parent[1], i))
        return out

    def total_length(self) -> float:
        """Sum of all branch lengths in pixels."""
        return float(sum(b.length() for b in self.branches))

    def vertex_bound(self, h: float) -> float:
        """At most how many vertices :meth:`resample` at ``h`` makes (two more per branch than its length over ``h``)."""
        return float(sum(b.length() / h + 2 for b in self.branches))

    def resample(self, h: float) -> Skeleton:
        """Every branch resampled to constant edge length ``h`` (§4.1); attachments remapped.

        A child's parent vertex becomes the resampled parent vertex nearest to the old one.
        """
        h = check_float(h, "h", 0.0, inclusive=False)
        count = self.vertex_bound(h)
        if count > MAX_VERTICES:
            raise ValueError(
                f"h: resampling {self.total_length():.3g} px of branches at h={h:g} would make about {count:.3g} vertices,"
                f" more than the limit of {MAX_VERTICES}; pass a larger h"
            )
        new = [b.resample(h) for b in self.branches]
        for b in new:
            if b.parent is not None:
                pb, pv = b.parent
                old = self.branches[pb].points[pv]
                b.parent = (pb, int(np.argmin(np.linalg.norm(new[pb].points - old, axis=1))))
        return Skeleton(new, self.shape)

    def bounds(self) -> tuple[float, float, float, float]:
        """``(x_min, y_min, x_max, y_max)`` over all vertices."""
        pts = np.vstack([b.points for b in self.branches])
        return float(pts[:, 0].min()), float(pts[:, 1].min()), float(pts[:, 0].max()), float(pts[:, 1].max())

    # -- drawing ----------------------------------------------------------------------------

    @renamed(shape="size")
    def mask(self, size: Size | None = None) -> NDArray[np.bool_]:
        """The structure as a boolean ``(H, W)`` mask: every edge drawn with its thickness.

        ``size`` is the mask's ``(H, W)`` (an int: a square; default: the skeleton's own
        ``shape``); ``shape=`` before (deprecated).
        """
        hw = self.shape if size is None else check_size(size)
        if hw is None:
            raise SkeletonError("mask: the skeleton has no shape; pass size=(H, W)")
        out = np.zeros(hw, np.uint8)
        for b in self.branches:
            for (p, q), (r0, r1) in zip(zip(b.points[:-1], b.points[1:]), zip(b.thickness[:-1], b.thickness[1:])):
                r = max(0.5 * (r0 + r1), 0.5)
                cv2.line(
                    out, _pt(p), _pt(q), 1, thickness=min(max(1, round(2 * r)), 32767), lineType=cv2.LINE_8, shift=4
                )
        return out.astype(bool)

    @renamed(shape="size")
    def draw(
        self,
        image: Any = None,
        *,
        size: Size | None = None,
        color: Sequence[float] = (1.0, 0.2, 0.1),
        width: int = 1,
        vertices: bool = False,
    ) -> NDArray[np.float32]:
        """Draw the skeleton's centre lines (and optionally vertices) over an image.

        Parameters
        ----------
        image : array, optional
            ``(H, W)`` or ``(H, W, C)`` float image in ``[0, 1]``; a black canvas of ``size``
            (or the skeleton's shape) when omitted.
        size : int or (int, int), optional
            ``(H, W)`` of that black canvas (an int: a square); ``shape`` before (deprecated).
        color : sequence of float
            RGB colour of the lines.
        width : int
            Line width in pixels.
        vertices : bool
            Also mark every vertex with a small dot.

        Returns
        -------
        ndarray of float32, shape (H, W, 3)
        """
        if image is None:
            hw = self.shape if size is None else check_size(size)
            if hw is None:
                raise SkeletonError("draw: pass an image or size=(H, W)")
            canvas = np.zeros((*hw, 3), np.float32)
        else:
            img = as_image(image, "image")
            canvas = np.repeat(img, 3, axis=2) if img.shape[2] == 1 else np.ascontiguousarray(img[:, :, :3]).copy()
        col = tuple(float(c) for c in color)
        for b in self.branches:
            pts = np.round(b.points * 16).astype(np.int32)
            cv2.polylines(canvas, [pts], False, col, thickness=int(width), lineType=cv2.LINE_AA, shift=4)
            if vertices:
                for p in b.points:
                    cv2.circle(canvas, _pt(p), 16 * max(1, width), col, -1, cv2.LINE_AA, shift=4)
        return canvas

    # -- files ------------------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready dictionary of the file format."""
        return {
            "format": FORMAT,
            "version": VERSION,
            "shape": list(self.shape) if self.shape is not None else None,
            "branches": [
                {
                    "points": b.points.tolist(),
                    "thickness": b.thickness.tolist(),
                    "parent": list(b.parent) if b.parent is not None else None,
                }
                for b in self.branches
            ],
        }

    @classmethod
    def from_dict(cls, data: Any) -> Skeleton:
        """Build a skeleton from the file format's dictionary, with errors that say what is wrong."""
        data = cls.check_header(data)
        branches = data.get("branches")
        if not isinstance(branches, list) or not branches:
            raise SkeletonError("'branches' must be a non-empty list")
        out = []
        for i, b in enumerate(branches):
            where = f"branches[{i}]"
            if not isinstance(b, dict) or "points" not in b:
                raise SkeletonError(f"{where} must be an object with 'points' (and 'thickness', 'parent')")
            pts = _as_points(_json_points(b["points"], where), where)
            thick = _as_thickness(_json_thickness(b.get("thickness", 1.0), where), len(pts), where)
            parent = b.get("parent")
            if parent is not None:
                if not (
                    isinstance(parent, (list, tuple))
                    and len(parent) == 2
                    and all(isinstance(v, int) and not isinstance(v, bool) for v in parent)
                ):
                    raise SkeletonError(
                        f"{where}.parent must be null or [branch index, vertex index], got {short_repr(parent)}"
                    )
                parent = (parent[0], parent[1])
            out.append(Branch(pts, thick, parent))
        shape = data.get("shape")
        if shape is not None:
            if not (
                isinstance(shape, (list, tuple))
                and len(shape) == 2
                and all(isinstance(v, int) and not isinstance(v, bool) and 0 < v <= MAX_COORD for v in shape)
            ):
                raise SkeletonError(
                    f"'shape' must be [H, W] with integers in 1..{MAX_COORD:.0f}, got {short_repr(shape)}"
                )
            shape = (shape[0], shape[1])
        return cls(out, shape)


def _pt(p: F64) -> tuple[int, int]:
    return round(float(p[0]) * 16), round(float(p[1]) * 16)
