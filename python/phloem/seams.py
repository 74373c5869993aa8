"""Graph cuts: exact minimum cuts on grid graphs, and seams between overlapping images.

Both run in phloem's Rust core, with the GIL released. When a 4-connected grid has all its
terminal edges on the border, the source-tied pixels forming one arc of the border and the
sink-tied pixels another (a seam across a strip, as in quilting), the graph is planar and the
minimum cut is a shortest path in its dual graph (Schmidt, Töppe & Cremers, CVPR 2009),
found by Dijkstra's algorithm; otherwise the Boykov–Kolmogorov max-flow algorithm (PAMI 2004)
specialised to 4- and 8-connected grids runs. Both are exact. :func:`seam` is the
compositing step of graph-cut textures (Kwatra et al. 2003), of the fragment composition of
branching structures (Sibbing et al. 2010 §5.3) and of stroke-based editing (Luo et al.).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal, overload

import numpy as np
from numpy.typing import NDArray

from . import _core
from ._api import old_flag, renamed
from ._validate import as_image, as_mask, check_threads

__all__ = ["COSTS", "SeamResult", "grid_maxflow", "seam"]

#: The built-in seam costs of :func:`seam`.
COSTS = ("kwatra", "gradient", "luo")


@dataclass(frozen=True)
class SeamResult:
    """What :func:`seam` returns with ``full_output=True``.

    Attributes
    ----------
    take_b : (H, W) ndarray of bool
        Where the composite takes ``b`` (the default return value).
    energy : float
        The cut's energy: seam costs plus broken border ties.
    """

    take_b: NDArray[np.bool_]
    energy: float


def _connectivity(connectivity: Any) -> int:
    if isinstance(connectivity, bool) or connectivity not in (4, 8):
        raise ValueError(f"connectivity: expected 4 or 8, got {connectivity!r}")
    return int(connectivity)


def _capacities(
    values: Any, name: str, shape: tuple[int, ...] | None = None, *, allow_inf: bool = False
) -> NDArray[np.float32]:
    arr = np.asarray(values)
    if arr.dtype == np.bool_ or not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise TypeError(f"{name}: expected real-valued capacities, got dtype {arr.dtype}")
    arr = np.ascontiguousarray(arr, dtype=np.float32)
    if shape is not None and arr.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {arr.shape}")
    bad = np.isnan(arr) | (arr < 0) | (False if allow_inf else np.isinf(arr))
    if bad.any():
        where = tuple(int(i) for i in np.argwhere(bad)[0])
        kind = "non-negative (or +inf for a hard constraint)" if allow_inf else "finite and non-negative"
        raise ValueError(f"{name}: capacities must be {kind}; found {arr[where]} at {where}")
    return arr


def grid_maxflow(
    source: Any,
    sink: Any,
    edges: Any,
    *,
    connectivity: int = 4,
    directed: bool = False,
    threads: int | None = None,
) -> tuple[float, NDArray[np.bool_]]:
    """Maximum flow and minimum cut of a grid graph.

    Every pixel is a node joined to its 4 (or 8) neighbours, to the source and to the sink.

    Parameters
    ----------
    source, sink : (H, W) array_like
        Terminal capacities: ``source[y, x]`` from the source to the pixel, ``sink[y, x]``
        from the pixel to the sink. ``np.inf`` is a hard constraint (the pixel is on that
        side of every finite cut); a pixel may not be hard-tied to both.
    edges : (H, W, D) array_like
        Finite non-negative edge capacities. With ``directed=False``, ``D`` is 2 (or 4 with
        ``connectivity=8``): the capacity, both ways, of the edge from each pixel to its east
        and south neighbours (then south-east and south-west). With ``directed=True``, ``D``
        is 4 (or 8): the capacity from the pixel to its E, S, W, N (then SE, SW, NW, NE)
        neighbour. Capacities of edges that leave the grid are ignored.
    connectivity : {4, 8}, optional
        Neighbourhood (default 4).
    directed : bool, optional
        Layout of ``edges`` (default symmetric).
    threads : int, optional
        Worker threads. The planar case (4-connectivity, terminal edges only on the border in
        two non-interleaving arcs, e.g. the first column tied to the source and the last to
        the sink) is solved as a shortest path in the dual graph, on one thread. Otherwise
        grids of 2^13 pixels or more are cut in two (twice over for big ones), the halves
        solved in parallel and the Boykov–Kolmogorov search finished on the whole. Either way
        the result is exact and the same for any number of threads.

    Returns
    -------
    flow : float
        The maximum flow, equal to the capacity of the minimum cut.
    sink_side : (H, W) bool ndarray
        ``True`` for pixels on the sink side of a minimum cut (the convention of PyMaxflow's
        ``get_grid_segments``).

    Examples
    --------
    Two pixels, the left one tied to the source, the right to the sink, joined by an edge of
    capacity 2: the cut severs that edge.

    >>> import numpy as np
    >>> from phloem.seams import grid_maxflow
    >>> flow, side = grid_maxflow([[np.inf, 0]], [[0, np.inf]], np.array([[[2.0, 0], [0, 0]]]))
    >>> flow, side.tolist()
    (2.0, [[False, True]])
    """
    conn = _connectivity(connectivity)
    s = _capacities(source, "source", allow_inf=True)
    if s.ndim != 2 or 0 in s.shape:
        raise ValueError(f"source: expected a non-empty (H, W) array, got shape {s.shape}")
    t = _capacities(sink, "sink", s.shape, allow_inf=True)
    d = conn if directed else conn // 2
    e = _capacities(edges, "edges", (*s.shape, d))
    both = np.isinf(s) & np.isinf(t)
    if both.any():
        y, x = np.argwhere(both)[0]
        raise ValueError(f"sink: pixel ({y}, {x}) has infinite capacity to both terminals")
    flow, side, _ = _core.grid_maxflow(
        s, t, e, connectivity=conn, directed=bool(directed), threads=check_threads(threads), method="auto"
    )
    return flow, side


@overload
def seam(
    a: Any,
    b: Any,
    region: Any,
    *,
    cost: Literal["kwatra", "gradient", "luo"] | NDArray[Any] = ...,
    a_mask: Any = ...,
    b_mask: Any = ...,
    seeds: Any = ...,
    border_weight: float | None = ...,
    connectivity: int = ...,
    threads: int | None = ...,
    full_output: Literal[False] = ...,
) -> NDArray[np.bool_]: ...
@overload
def seam(
    a: Any,
    b: Any,
    region: Any,
    *,
    cost: Literal["kwatra", "gradient", "luo"] | NDArray[Any] = ...,
    a_mask: Any = ...,
    b_mask: Any = ...,
    seeds: Any = ...,
    border_weight: float | None = ...,
    connectivity: int = ...,
    threads: int | None = ...,
    full_output: Literal[True],
) -> SeamResult: ...


@renamed(return_energy=old_flag(lambda r: (r.take_b, r.energy)))
def seam(
    a: Any,
    b: Any,
    region: Any,
    *,
    cost: Literal["kwatra", "gradient", "luo"] | NDArray[Any] = "kwatra",
    a_mask: Any = None,
    b_mask: Any = None,
    seeds: Any = None,
    border_weight: float | None = None,
    connectivity: int = 4,
    threads: int | None = None,
    full_output: bool = False,
) -> NDArray[np.bool_] | SeamResult:
    """Minimum-cost seam between two overlapping images.

    ``a`` and ``b`` live in one frame; ``region`` is where both exist (the overlap, of any
    shape, possibly several pieces). Each region pixel is given to ``a`` or ``b`` so that the
    colour mismatch across the seam is minimal; the cut is exact. A region pixel whose
    4-neighbour lies where only ``a`` exists (``a_mask`` outside the region) is tied to ``a``,
    and likewise for ``b``, so the composite ``np.where(take_b[..., None], b, a)`` has no
    jump at the region border. Pixels at the frame border, or bordering both or neither, are
    free.

    Parameters
    ----------
    a, b : (H, W[, C]) array_like
        The two images, same shape, finite.
    region : (H, W) array_like of bool
        The overlap: where the labels are chosen. Must not be empty.
    cost : {"kwatra", "gradient", "luo"} or (H, W, D) ndarray, optional
        Cost of a seam between neighbours ``s`` and ``t`` (``‖·‖`` over channels):

        - ``"kwatra"`` (default): ``‖a(s) − b(s)‖ + ‖a(t) − b(t)‖`` (Kwatra et al. 2003,
          Eq. 1; the colour difference of Sibbing et al. 2010 §5.3);
        - ``"gradient"``: that cost over the sum of the four directional gradients
          ``‖G_a^d(s)‖ + ‖G_a^d(t)‖ + ‖G_b^d(s)‖ + ‖G_b^d(t)‖`` (Kwatra et al. 2003, Eq. 2);
        - ``"luo"``: ``min(d(s), d(t)) / G(s, t)`` with ``d = ‖a − b‖⁴`` and ``G`` the summed
          gradient magnitudes of both images at both pixels (Luo et al., Eq. 2), on colours
          scaled to 0–255, with the paper's border data term of 10000;
        - an array: your own finite non-negative costs in the symmetric layout of
          :func:`grid_maxflow` (east and south edges, then south-east and south-west).
    a_mask, b_mask : (H, W) array_like of bool, optional
        Where each image exists; each must contain ``region``. Default: the region itself
        (then nothing outside the region ties the labels).
    seeds : (H, W) array_like of int, optional
        Hard constraints inside the region: 0 free, 1 must take ``a``, 2 must take ``b``.
    border_weight : float, optional
        Cost of breaking a border tie: ``inf`` (a hard constraint) for the Kwatra costs and
        10000 for ``"luo"`` unless given.
    connectivity : {4, 8}, optional
        Pixel neighbourhood of the seam (default 4).
    threads : int, optional
        Worker threads for the cost computation.
    full_output : bool, optional
        Return a :class:`SeamResult` (``take_b`` and the cut's energy) instead of ``take_b``
        alone (``return_energy`` before; it still works, deprecated).

    Returns
    -------
    take_b : (H, W) bool ndarray
        ``True`` where the composite takes ``b``: the cut inside the region, and outside it
        wherever only ``b`` exists. A :class:`SeamResult` with ``full_output=True``.

    Examples
    --------
    ``a`` covers columns 0–5 and ``b`` columns 2–7; they differ everywhere except in columns
    4 and 5, so the seam passes between those two, where it costs nothing.

    >>> import numpy as np
    >>> from phloem.seams import seam
    >>> a, b = np.zeros((4, 8)), np.ones((4, 8))
    >>> b[:, 4:6] = 0
    >>> cols = np.arange(8)
    >>> a_mask, b_mask = np.broadcast_to(cols < 6, (4, 8)), np.broadcast_to(cols >= 2, (4, 8))
    >>> res = seam(a, b, a_mask & b_mask, a_mask=a_mask, b_mask=b_mask, full_output=True)
    >>> res.take_b[0].astype(int).tolist(), res.energy
    ([0, 0, 0, 0, 0, 1, 1, 1], 0.0)
    """
    ia = as_image(a, "a")
    ib = as_image(b, "b")
    if ib.shape != ia.shape:
        raise ValueError(f"b: expected the shape of a {np.shape(a)}, got {np.shape(b)}")
    shape = (ia.shape[0], ia.shape[1])
    reg = as_mask(region, "region", shape)
    if not reg.any():
        raise ValueError("region: is empty; expected at least one overlap pixel")
    conn = _connectivity(connectivity)
    am = None if a_mask is None else as_mask(a_mask, "a_mask", shape)
    bm = None if b_mask is None else as_mask(b_mask, "b_mask", shape)
    sd = None
    if seeds is not None:
        sarr = np.asarray(seeds)
        if sarr.shape != shape or not np.issubdtype(sarr.dtype, np.integer):
            raise ValueError(f"seeds: expected an integer array of shape {shape}, got {sarr.dtype} {sarr.shape}")
        if ((sarr < 0) | (sarr > 2)).any():
            raise ValueError("seeds: expected values 0 (free), 1 (take a) or 2 (take b)")
        sd = np.ascontiguousarray(sarr, dtype=np.uint8)
    edges = None
    name = "kwatra"
    if isinstance(cost, str):
        if cost not in COSTS:
            raise ValueError(f"cost: expected one of {COSTS} or an array of edge costs, got {cost!r}")
        name = cost
    else:
        edges = _capacities(cost, "cost", (*shape, conn // 2))
    bw = None
    if border_weight is not None:
        bw = float(border_weight)
        if not bw >= 0:
            raise ValueError(f"border_weight: expected a non-negative number or inf, got {border_weight!r}")
    take_b, energy, _ = _core.seam(
        ia,
        ib,
        reg,
        cost=name,
        connectivity=conn,
        border_weight=bw,
        a_mask=am,
        b_mask=bm,
        seeds=sd,
        edges=edges,
        threads=check_threads(threads),
    )
    return SeamResult(take_b, energy) if full_output else take_b
