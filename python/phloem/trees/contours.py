"""The overall contour of one exemplar and its fixed-length versions (Argudo et al. 2017 §4.2, §4.4–4.6).

:func:`contour` extracts it (§4.2), :func:`pin_points` finds B, L and R on it (§4.4),
:func:`resample` gives it N points split between crown and trunk (§4.5) and :func:`simplify` makes
the M-point cage of the dilated interior (§4.6). Coordinates are ``(x, y)`` pixel positions with
``y`` down; counter-clockwise means as seen on the screen.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validate import as_mask, check_int
from ._checks import F64, as_alpha_mask, as_points, check_alpha_threshold
from ._outline import dilated_outline, equal_chords, longest_exterior, screen_area, simplify_outline

__all__ = ["contour", "pin_points", "resample", "signed_area", "simplify"]


def signed_area(points: Any) -> float:
    """Signed area of a closed polygon, positive when it runs counter-clockwise on screen.

    With image coordinates (``y`` down) this is minus the usual shoelace sum, so that the
    paper's counter-clockwise contours have a positive area.

    Examples
    --------
    >>> import phloem
    >>> phloem.trees.signed_area([(0, 0), (0, 2), (2, 2), (2, 0)])   # down, right, up on screen
    4.0
    """
    return screen_area(as_points(points, "points"))


def contour(alpha: Any, *, alpha_threshold: float = 0.5) -> F64:
    """The overall tree contour: the longest exterior contour of the alpha mask (paper §4.2).

    All contours of the thresholded alpha are found by border following (Suzuki & Abe 1985,
    OpenCV's ``findContours`` with a two-level hierarchy); those not inside another contour are
    exterior, the rest interior (holes). The longest exterior contour is returned,
    counter-clockwise on screen (positive :func:`signed_area`), through the centres of its
    boundary pixels.

    Parameters
    ----------
    alpha : (M, N) ndarray or (M, N, 4) ndarray
        The alpha channel (bool, or real values compared with ``alpha_threshold``), or an RGBA
        image whose alpha is used.
    alpha_threshold : float, optional
        Alpha at or above this is opaque (the paper's 0.5).

    Returns
    -------
    (K, 2) float64 ndarray
        ``(x, y)`` of the contour pixels, in order, not repeating the first point.

    Raises
    ------
    ValueError
        If the mask is empty.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> m = np.zeros((8, 8), bool); m[2:5, 3:6] = True
    >>> c = phloem.trees.contour(m)
    >>> len(c), phloem.trees.signed_area(c) > 0
    (8, True)
    """
    t = check_alpha_threshold(alpha_threshold)
    mask = as_alpha_mask(alpha, t)
    return longest_exterior(mask)


def pin_points(points: Any, trunk: Any) -> tuple[int, int, int]:
    """The pin points B, L, R of a counter-clockwise tree contour (paper §4.4).

    B, the tree bottom, is the contour point with the largest ``y`` (the paper's minimum with
    ``y`` up), the median one of several. Walking from B backwards (to the left on screen) and
    forwards (to the right) along the contour, L and R are the first points at or above the crown
    baseline, the lowest row of crown pixels (the lowest non-trunk row of the opaque mask, i.e.
    the row above the highest trunk row when ``trunk`` holds the trunk below the crown). With no
    trunk pixels, L = R = B.

    Parameters
    ----------
    points : (K, 2) ndarray
        Counter-clockwise contour, as from :func:`contour`.
    trunk : (M, N) bool ndarray
        Trunk mask, as from :func:`segment` or drawn by hand.

    Returns
    -------
    (b, l, r) : tuple of int
        Indices into ``points``. Counter-clockwise from B one meets R, then L.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> img = np.zeros((100, 100, 4), np.float32)
    >>> img[20:60, 20:80] = 1.0; img[60:100, 45:55] = 1.0
    >>> c = phloem.trees.contour(img)
    >>> b, l, r = phloem.trees.pin_points(c, phloem.trees.segment(img))
    >>> c[b].tolist(), c[l].tolist(), c[r].tolist()
    ([50.0, 99.0], [44.0, 59.0], [55.0, 59.0])
    """
    p = as_points(points, "points")
    tm = np.asarray(trunk)
    if tm.ndim != 2:
        raise ValueError(f"trunk: expected an (H, W) mask, got shape {tm.shape}")
    tm = as_mask(tm, "trunk", tm.shape)
    n = len(p)
    ymax = p[:, 1].max()
    lows = np.flatnonzero(p[:, 1] == ymax)
    # Contour indices of the lowest points, taken as a run around the loop so the median is
    # the middle of the bottom edge even when the run wraps past index 0.
    if lows.size > 1:
        gaps = np.diff(np.concatenate([lows, [lows[0] + n]]))
        start = int(np.argmax(gaps)) + 1
        lows = np.roll(lows, -start)
    b = int(lows[len(lows) // 2])
    rows = np.flatnonzero(tm.any(axis=1))
    if rows.size == 0:
        return b, b, b
    baseline = int(rows[0]) - 1  # lowest crown row lies just above the trunk's top

    def walk(direction: int) -> int:
        i = b
        for _ in range(n):
            if p[i, 1] <= baseline:
                return i
            i = (i + direction) % n
        return b

    r = walk(+1)
    l_ = walk(-1)
    return b, l_, r


def resample(points: Any, pins: tuple[int, int, int], *, split: tuple[int, int, int] = (1600, 200, 200)) -> F64:
    """Resample a contour to a fixed number of points between its pin points (paper §4.5).

    The counter-clockwise contour is cut at the pins into the crown (R to L, over the top), the
    left trunk side (L down to B) and the right trunk side (B up to R). Each gets a fixed number
    of points, placed with (near) equal chord lengths within the segment. The paper used
    N = 2000 points: 1600 on the crown and 200 on each trunk side.

    Parameters
    ----------
    points : (K, 2) ndarray
        Counter-clockwise contour.
    pins : (b, l, r)
        Pin indices into ``points``, as from :func:`pin_points`.
    split : (int, int, int), optional
        Points on the crown, the left and the right trunk side.

    Returns
    -------
    (sum(split), 2) float64 ndarray
        The resampled contour ``C_r``, counter-clockwise, starting at R: the crown occupies
        ``[0, split[0])`` (so row 0 is R and row ``split[0]`` is L), the left trunk side the
        next ``split[1]`` rows (row ``split[0] + split[1]`` is B), the right side the rest.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> img = np.zeros((100, 100, 4), np.float32)
    >>> img[20:60, 20:80] = 1.0; img[60:100, 45:55] = 1.0
    >>> c = phloem.trees.contour(img)
    >>> pins = phloem.trees.pin_points(c, phloem.trees.segment(img))
    >>> cr = phloem.trees.resample(c, pins, split=(80, 10, 10))
    >>> cr.shape, cr[80].tolist(), cr[90].tolist()
    ((100, 2), [44.0, 59.0], [50.0, 99.0])
    """
    p = as_points(points, "points")
    n = len(p)
    try:
        b, l_, r = (int(i) for i in pins)
    except (TypeError, ValueError):
        raise TypeError(f"pins: expected three indices (b, l, r), got {pins!r}") from None
    for name, i in (("b", b), ("l", l_), ("r", r)):
        if not 0 <= i < n:
            raise ValueError(f"pins: {name}={i} is not an index into the {n} contour points")
    try:
        counts = tuple(int(c) for c in split)
    except (TypeError, ValueError):
        raise TypeError(f"split: expected three point counts, got {split!r}") from None
    if len(counts) != 3 or min(counts) < 1:
        raise ValueError(f"split: expected three counts >= 1, got {split!r}")

    return _resample_parts(p, (b, l_, r), counts)


def _resample_parts(p: F64, pins: tuple[int, int, int], counts: tuple[int, ...]) -> F64:
    """Cut the closed contour at the pins into crown (R to L), left (L to B) and right (B to R)
    and resample each part with equal chords."""
    b, l_, r = pins
    n = len(p)

    def path(i: int, j: int, full: bool) -> F64:
        # Contour from index i forwards to index j inclusive (the whole loop when i == j and full).
        k = (j - i) % n
        if k == 0 and full:
            k = n
        idx = (i + np.arange(k + 1)) % n
        return p[idx]

    parts = (path(r, l_, full=True), path(l_, b, full=False), path(b, r, full=False))
    return np.concatenate([equal_chords(part, c) for part, c in zip(parts, counts)])


def simplify(mask: Any, *, m: int = 100, dilation: int = 8) -> F64:
    """The simplified contour ``C_s`` for mean value coordinates (paper §4.6).

    The mask (the interior of ``C_r``, see :func:`prepare`) is dilated ``dilation`` times with a
    3 x 3 square, and its longest exterior contour resampled to ``m`` points of equal chord
    length, counter-clockwise, starting at its lowest point. Dilating keeps the tree's pixels
    away from the cage, where the warp distorts most.

    Parameters
    ----------
    mask : (M, N) bool ndarray
        The tree's interior.
    m : int, optional
        Number of points (the paper's M = 100).
    dilation : int, optional
        Dilation iterations (the paper used 8).

    Returns
    -------
    (m, 2) float64 ndarray

    Examples
    --------
    >>> import numpy as np, phloem
    >>> mask = np.zeros((64, 64), bool); mask[20:40, 20:40] = True
    >>> cs = phloem.trees.simplify(mask, m=40, dilation=2)
    >>> cs.shape, float(cs[:, 0].min()), float(cs[:, 1].max())
    ((40, 2), 18.0, 41.0)
    """
    arr = np.asarray(mask)
    if arr.ndim != 2:
        raise ValueError(f"mask: expected an (H, W) mask, got shape {arr.shape}")
    mk = as_mask(arr, "mask", arr.shape)
    m = check_int(m, "m", 3)
    dilation = check_int(dilation, "dilation", 0)
    if not mk.any():
        raise ValueError("mask: expected some set pixels, the mask is empty")
    return simplify_outline(dilated_outline(mk, dilation), m)
