"""Gradient-domain solvers: seamless (Poisson) blending and smooth field interpolation.

Both solve sparse symmetric systems on pixel grids in phloem's Rust core by conjugate
gradients preconditioned with the core's one Galerkin multigrid (parallel, GIL released, the
same result for any number of threads); :func:`seamless` starts from a full-multigrid first
guess, and small fields are factored directly. ``docs/engines/solvers.md`` describes the solvers.
"""

from __future__ import annotations

import numbers
import warnings
from dataclasses import dataclass
from typing import Any, Literal, overload

import numpy as np
from numpy.typing import NDArray

from . import _core
from ._api import old_flag, renamed
from ._validate import as_image, as_labels, as_mask, check_int, check_threads, restore_ndim

__all__ = ["FieldResult", "SeamlessResult", "interpolate_field", "seamless"]


@dataclass(frozen=True)
class SeamlessResult:
    """What :func:`seamless` returns with ``full_output=True``.

    Attributes
    ----------
    image : (M, N[, C]) ndarray of float32
        The blended image (the default return value).
    iterations : int
        Conjugate-gradient iterations run.
    residual : float
        Final relative residual ``‖b − A f‖ / ‖b‖`` (the largest over channels).
    """

    image: NDArray[np.float32]
    iterations: int
    residual: float


@dataclass(frozen=True)
class FieldResult:
    """What :func:`interpolate_field` returns with ``full_output=True``.

    Attributes
    ----------
    field : (M, N, D) or (M, N) ndarray of float32
        The interpolated field (the default return value).
    iterations : int
        Conjugate-gradient iterations run (the most over components).
    residual : float
        Final relative residual of the normal equations (the largest over components).
    """

    field: NDArray[np.float32]
    iterations: int
    residual: float


def _tol(tol: Any) -> float:
    t = float(tol) if isinstance(tol, numbers.Real) and not isinstance(tol, bool) else float("nan")
    if not 0.0 < t < 1.0:  # also rejects NaN
        raise ValueError(f"tol: expected a number in (0, 1), got {tol!r}")
    return t


def _offset(offset: Any) -> tuple[int, int]:
    try:
        r, c = offset
    except (TypeError, ValueError):
        raise TypeError(f"offset: expected (row, col), got {offset!r}") from None
    for v in (r, c):
        if isinstance(v, bool) or not isinstance(v, numbers.Integral):
            raise TypeError(f"offset: expected integer (row, col), got {offset!r}")
    return int(r), int(c)


def _converged(residual: float, tol: float) -> None:
    if residual > tol:
        warnings.warn(
            f"the solver stopped at relative residual {residual:.3g} above tol={tol:g}; raise max_iterations",
            RuntimeWarning,
            stacklevel=3,
        )


@overload
def seamless(
    src: Any,
    dst: Any,
    mask: Any,
    offset: tuple[int, int],
    *,
    mode: Literal["normal", "mixed"] = ...,
    fixed: Any = ...,
    labels: Any = ...,
    tol: float = ...,
    max_iterations: int = ...,
    threads: int | None = ...,
    full_output: Literal[False] = ...,
) -> NDArray[np.float32]: ...
@overload
def seamless(
    src: Any,
    dst: Any,
    mask: Any,
    offset: tuple[int, int],
    *,
    mode: Literal["normal", "mixed"] = ...,
    fixed: Any = ...,
    labels: Any = ...,
    tol: float = ...,
    max_iterations: int = ...,
    threads: int | None = ...,
    full_output: Literal[True],
) -> SeamlessResult: ...


@renamed(return_info=old_flag(lambda r: (r.image, {"iterations": r.iterations, "residual": r.residual})))
def seamless(
    src: Any,
    dst: Any,
    mask: Any,
    offset: tuple[int, int],
    *,
    mode: Literal["normal", "mixed"] = "normal",
    fixed: Any = None,
    labels: Any = None,
    tol: float = 1e-6,
    max_iterations: int = 200,
    threads: int | None = None,
    full_output: bool = False,
) -> NDArray[np.float32] | SeamlessResult:
    """Paste the gradients of ``src`` into ``dst`` over ``mask`` (Poisson image editing).

    Solves, per channel, the discrete Poisson equation of Pérez et al. (2003, Eq. 7) on the
    region Ω = ``mask`` placed at ``offset`` in ``dst``: for every pixel ``p`` of Ω,
    ``|N_p| f_p − Σ_{q∈N_p∩Ω} f_q = Σ_{q∈N_p∖Ω} f*_q + Σ_{q∈N_p} v_pq`` where ``N_p`` are the
    4-neighbours of ``p`` inside ``dst`` and

    - ``v_pq = g_p − g_q`` with ``g`` the source (``mode="normal"``), or the one of the source
      and destination differences with the larger magnitude (``mode="mixed"``, Eq. 13); with
      ``labels``, the source difference is 0 between pixels of different labels;
    - ``f*_q`` is the destination value outside Ω (Dirichlet), and the source value at
      ``fixed`` pixels (the constraint of Sibbing et al. 2010, §5.3: the fragment keeps its
      colours where it has no neighbour);
    - neighbours outside ``dst`` are dropped: the border of ``dst`` is free (Neumann).

    Mask pixels that land outside ``dst`` are clipped. Source values are read with the
    source's edge replicated, so the guidance is zero across the source's border. A connected
    part of Ω that touches no Dirichlet pixel (it fills a whole connected part of ``dst``) is
    determined up to a constant only and keeps the mean of the source over it.

    Parameters
    ----------
    src : (m, n[, C]) array_like
        Source image. Integer images are scaled to [0, 1].
    dst : (M, N[, C]) array_like
        Destination image, with as many channels as ``src``.
    mask : (m, n) array_like of bool
        Region to blend, in ``src`` coordinates; any shape, holes and several parts allowed.
    offset : (int, int)
        (row, col) of ``src``'s top-left pixel in ``dst``; may be negative.
    mode : {"normal", "mixed"}, optional
        Guidance field (default ``"normal"``).
    fixed : (m, n) array_like of bool, optional
        Pixels of ``mask`` that keep their ``src`` values exactly.
    labels : (m, n) array_like of int, optional
        Guidance labels (default: none, one label): the guidance keeps the source's gradient
        between two neighbours of the same label and is zero between different labels, also
        across the border of the region (label the pixels outside it apart). Pasting several
        pieces at once, e.g. fragments labelled by origin, this spreads their level
        differences smoothly instead of keeping them as steps, and lets the region's border
        take the destination's values.
    tol : float, optional
        Stop when ``‖b − A f‖ / ‖b‖ ≤ tol`` in every channel (default 1e-6).
    max_iterations : int, optional
        Most conjugate-gradient iterations (default 200; 2–6 are typical). A
        ``RuntimeWarning`` says if ``tol`` was not reached.
    threads : int, optional
        Worker threads (default: ``PHLOEM_NUM_THREADS`` or all cores).
    full_output : bool, optional
        Return a :class:`SeamlessResult` (the image, iterations and final residual) instead
        of the image alone (``return_info`` before; it still works, deprecated).

    Returns
    -------
    image : (M, N[, C]) ndarray of float32
        ``dst`` (as float32) with the region replaced by the solution; a
        :class:`SeamlessResult` with ``full_output=True``.

    References
    ----------
    .. [1] P. Pérez, M. Gangnet, A. Blake, "Poisson image editing", ACM TOG 22(3), 2003.
    .. [2] D. Sibbing, D. Pavić, L. Kobbelt, "Image synthesis for branching structures",
       Computer Graphics Forum 29(7), 2010, §5.3.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> bark = phloem.data.bark()[..., :3]
    >>> dst = np.full((128, 128, 3), 0.5, np.float32)
    >>> yy, xx = np.mgrid[:64, :64]
    >>> disk = (yy - 31.5) ** 2 + (xx - 31.5) ** 2 < 30**2
    >>> res = phloem.blend.seamless(bark[:64, :64], dst, disk, (32, 32), full_output=True)
    >>> res.image.shape, res.residual < 1e-6
    ((128, 128, 3), True)
    >>> bool(np.all(res.image[0] == 0.5))   # outside the region dst is unchanged
    True
    """
    s = as_image(src, "src", finite=False)  # the core checks src before it solves
    d = as_image(dst, "dst", finite=False)  # the core checks while it copies dst into the output
    if s.shape[2] != d.shape[2]:
        raise ValueError(f"dst: expected {s.shape[2]} channels like src, got {d.shape[2]}")
    m = as_mask(mask, "mask", s.shape[:2])
    fx = None if fixed is None else as_mask(fixed, "fixed", s.shape[:2])
    lab = None if labels is None else as_labels(labels, "labels")
    if lab is not None and lab.shape != s.shape[:2]:
        raise ValueError(f"labels: expected shape {s.shape[:2]} like src, got {lab.shape}")
    if mode not in ("normal", "mixed"):
        raise ValueError(f"mode: expected 'normal' or 'mixed', got {mode!r}")
    t = _tol(tol)
    out, iterations, residual = _core.seamless(
        s,
        d,
        m,
        _offset(offset),
        mixed=mode == "mixed",
        tol=t,
        max_iterations=check_int(max_iterations, "max_iterations", 1),
        fixed=fx,
        threads=check_threads(threads),
        labels=lab,
    )
    _converged(residual, t)
    image = restore_ndim(out, dst)
    return SeamlessResult(image, iterations, residual) if full_output else image


@overload
def interpolate_field(
    region: Any,
    points: Any,
    values: Any,
    *,
    tol: float = ...,
    max_iterations: int = ...,
    threads: int | None = ...,
    full_output: Literal[False] = ...,
) -> NDArray[np.float32]: ...
@overload
def interpolate_field(
    region: Any,
    points: Any,
    values: Any,
    *,
    tol: float = ...,
    max_iterations: int = ...,
    threads: int | None = ...,
    full_output: Literal[True],
) -> FieldResult: ...


@renamed(return_info=old_flag(lambda r: (r.field, {"iterations": r.iterations, "residual": r.residual})))
def interpolate_field(
    region: Any,
    points: Any,
    values: Any,
    *,
    tol: float = 1e-10,
    max_iterations: int = 2000,
    threads: int | None = None,
    full_output: bool = False,
) -> NDArray[np.float32] | FieldResult:
    """The smoothest field over ``region`` that takes ``values`` at ``points``.

    Minimises ``E = Σ_p ‖(L d)_p‖²`` over the pixels of ``region`` subject to
    ``d[points[k]] = values[k]``, where ``L`` is the 4-neighbour Laplacian: the displacement
    field of Sibbing et al. (2010, §5.3) that deforms a fragment so its skeleton fits. Inside
    the region ``(L d)_p = 4 d_p − Σ d_q`` as in the paper; at the region's border only the
    neighbours inside the region count (``(L d)_p = deg(p) d_p − Σ d_q``, the graph
    Laplacian), so no value outside the region is needed. Constant fields have zero energy
    and are reproduced exactly; affine ones are not (the border rows do not vanish on them).
    Every connected part of ``region`` (4-connectivity) needs at least one point; the
    constrained pixels are eliminated, so they are hit exactly.

    Parameters
    ----------
    region : (M, N) array_like of bool
        Pixels where the field is defined.
    points : (K, 2) array_like of int
        (row, col) of the constrained pixels, each inside ``region``. A pixel may repeat only
        with the same value.
    values : (K, D) or (K,) array_like of float
        The field's value at each point (``D = 2`` for displacements; any ``D`` works).
    tol : float, optional
        Relative residual of the normal equations to reach (default 1e-10; the system's
        condition number grows with the fourth power of the region's size, so keep it small
        when the field must be accurate).
    max_iterations : int, optional
        Most conjugate-gradient iterations per component (default 2000).
    threads : int, optional
        Worker threads; components are solved in parallel.
    full_output : bool, optional
        Return a :class:`FieldResult` (the field, iterations and final residual) instead of
        the field alone (``return_info`` before; it still works, deprecated).

    Returns
    -------
    field : (M, N, D) or (M, N) ndarray of float32
        The field (2-D when ``values`` is 1-D); NaN outside ``region``. A
        :class:`FieldResult` with ``full_output=True``.

    References
    ----------
    .. [1] D. Sibbing, D. Pavić, L. Kobbelt, "Image synthesis for branching structures",
       Computer Graphics Forum 29(7), 2010, §5.3.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> region = np.ones((20, 30), bool)
    >>> d = phloem.blend.interpolate_field(region, [(5, 5), (15, 25)], [(1.0, 0.0), (-1.0, 2.0)])
    >>> d.shape, d[5, 5].tolist(), d[15, 25].tolist()
    ((20, 30, 2), [1.0, 0.0], [-1.0, 2.0])
    >>> bool(np.abs(np.diff(d, axis=1)).max() < 0.2)   # smooth
    True
    """
    reg = np.asarray(region)
    if reg.ndim != 2:
        raise ValueError(f"region: expected a 2-D mask, got shape {reg.shape}")
    reg = as_mask(reg, "region", reg.shape)
    pts = np.asarray(points)
    if pts.size == 0:
        pts = pts.reshape(0, 2)
    if pts.dtype == np.bool_ or not np.issubdtype(pts.dtype, np.integer):
        raise TypeError(f"points: expected integer (row, col) coordinates, got dtype {pts.dtype}")
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"points: expected shape (K, 2), got {pts.shape}")
    vals = np.asarray(values)
    if vals.dtype == np.bool_ or not (np.issubdtype(vals.dtype, np.integer) or np.issubdtype(vals.dtype, np.floating)):
        raise TypeError(f"values: expected real numbers, got dtype {vals.dtype}")
    flat = vals.ndim == 1
    if flat:
        vals = vals[:, None]
    if vals.ndim != 2 or vals.shape[0] != pts.shape[0] or vals.shape[1] == 0:
        raise ValueError(
            f"values: expected shape ({pts.shape[0]}, D) or ({pts.shape[0]},) like points, got {vals.shape}"
        )
    t = _tol(tol)
    out, iterations, residual = _core.interpolate_field(
        reg,
        np.ascontiguousarray(pts, dtype=np.int64),
        np.ascontiguousarray(vals, dtype=np.float64),
        tol=t,
        max_iterations=check_int(max_iterations, "max_iterations", 1),
        threads=check_threads(threads),
    )
    _converged(residual, t)
    field = out[:, :, 0] if flat else out
    return FieldResult(field, iterations, residual) if full_output else field
