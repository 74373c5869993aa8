"""phloem.seams: max-flow against PyMaxflow, cut values, seam costs, constraints, errors."""

from __future__ import annotations

from dataclasses import astuple

import maxflow
import numpy as np
import pytest

from phloem.seams import grid_maxflow, seam

# (row, col) steps of the directed layout: E, S, W, N, SE, SW, NW, NE.
DIRS = [(0, 1), (1, 0), (0, -1), (-1, 0), (1, 1), (1, -1), (-1, -1), (-1, 1)]
SYM = [0, 1, 4, 5]
BIG = 1e12  # PyMaxflow's stand-in for an infinite terminal capacity


def _directed(edges: np.ndarray, directed: bool, k: int) -> np.ndarray:
    """Any layout as (H, W, k) directed capacities, zero on edges leaving the grid."""
    h, w = edges.shape[:2]
    out = np.zeros((h, w, k))
    if directed:
        out[:] = edges
    else:
        for s, d in enumerate(SYM[: k // 2]):
            dy, dx = DIRS[d]
            out[..., d] = edges[..., s]
            # The reverse edge sits at the neighbour, direction d ^ 2.
            ys, xs = np.mgrid[0:h, 0:w]
            ny, nx = ys + dy, xs + dx
            ok = (ny >= 0) & (ny < h) & (nx >= 0) & (nx < w)
            out[ny[ok], nx[ok], d ^ 2] = edges[..., s][ok]
    for d in range(k):
        dy, dx = DIRS[d]
        ys, xs = np.mgrid[0:h, 0:w]
        out[..., d][(ys + dy < 0) | (ys + dy >= h) | (xs + dx < 0) | (xs + dx >= w)] = 0
    return out


def cut_value(source, sink, edges, side, *, directed=False, k=4) -> float:
    """Capacity of the cut `side` (True = sink side), summed independently in numpy."""
    e = _directed(np.asarray(edges, dtype=np.float64), directed, k)
    src = np.minimum(np.asarray(source, np.float64), BIG)
    snk = np.minimum(np.asarray(sink, np.float64), BIG)
    v = src[side].sum() + snk[~side].sum()
    h, w = side.shape
    for d in range(k):
        dy, dx = DIRS[d]
        ys, xs = np.mgrid[0:h, 0:w]
        ny, nx = np.clip(ys + dy, 0, h - 1), np.clip(xs + dx, 0, w - 1)
        crosses = ~side & side[ny, nx]
        v += (e[..., d] * crosses).sum()
    return float(v)


def pymaxflow(source, sink, edges, *, directed=False, k=4) -> tuple[float, np.ndarray]:
    """The same graph solved by PyMaxflow (the C++ Boykov–Kolmogorov library)."""
    g = maxflow.Graph[float]()
    ids = g.add_grid_nodes(source.shape)
    dirs = range(k) if directed else SYM[: k // 2]
    for s, d in enumerate(dirs):
        st = np.zeros((3, 3))
        st[1 + DIRS[d][0], 1 + DIRS[d][1]] = 1
        g.add_grid_edges(ids, weights=np.asarray(edges[..., s], np.float64), structure=st, symmetric=not directed)
    g.add_grid_tedges(ids, np.minimum(source, BIG), np.minimum(sink, BIG))
    return g.maxflow(), g.get_grid_segments(ids)


def random_graph(rng, h, w, d, *, hard=True):
    edges = rng.integers(0, 20, (h, w, d)).astype(np.float32) / 4
    source = np.where(rng.random((h, w)) < 0.2, rng.random((h, w)) * 5, 0).astype(np.float32)
    sink = np.where(rng.random((h, w)) < 0.2, rng.random((h, w)) * 5, 0).astype(np.float32)
    if hard:
        source[:, 0] = np.inf
        sink[:, -1] = np.inf
        source[:, -1] = 0
    return source, sink, edges


@pytest.mark.parametrize("k", [4, 8])
@pytest.mark.parametrize("directed", [False, True])
@pytest.mark.parametrize("seed", range(6))
def test_flow_matches_pymaxflow_and_labels_are_a_min_cut(seed, directed, k):
    rng = np.random.default_rng(seed)
    h, w = rng.integers(2, 40, 2)
    d = k if directed else k // 2
    source, sink, edges = random_graph(rng, h, w, d, hard=seed % 2 == 0)
    flow, side = grid_maxflow(source, sink, edges, connectivity=k, directed=directed)
    ref, _ = pymaxflow(source, sink, edges, directed=directed, k=k)
    assert flow == pytest.approx(ref, rel=1e-5, abs=1e-6)
    assert cut_value(source, sink, edges, side, directed=directed, k=k) == pytest.approx(ref, rel=1e-5, abs=1e-6)
    if seed % 2 == 0:
        assert not side[:, 0].any() and side[:, -1].all()


@pytest.mark.parametrize("threads", [1, 2])
def test_large_grid_split_in_halves_matches_pymaxflow(threads):
    rng = np.random.default_rng(7)
    source, sink, edges = random_graph(rng, 300, 260, 2)
    flow, side = grid_maxflow(source, sink, edges, threads=threads)
    ref, _ = pymaxflow(source, sink, edges)
    assert flow == pytest.approx(ref, rel=1e-5)
    assert cut_value(source, sink, edges, side) == pytest.approx(ref, rel=1e-5)


def border_cycle(h: int, w: int) -> list[tuple[int, int]]:
    """The border pixels clockwise from the top-left one."""
    return (
        [(0, x) for x in range(w)]
        + [(y, w - 1) for y in range(1, h)]
        + [(h - 1, x) for x in range(w - 2, -1, -1)]
        + [(y, 0) for y in range(h - 2, 0, -1)]
    )


def planar_graph(rng, h, w, directed):
    """Terminals only on the border: a source arc and a sink arc of random lengths and
    positions (finite, zero and infinite capacities, some pixels tied to both terminals),
    the other border pixels tied equally to both or to none; edges with many zeros."""
    d = 4 if directed else 2
    edges = (rng.integers(0, 12, (h, w, d)) * (rng.random((h, w, d)) < 0.7)).astype(np.float32) / 4
    source = np.zeros((h, w), np.float32)
    sink = np.zeros((h, w), np.float32)
    cyc = border_cycle(h, w)
    n = len(cyc)
    n_src = int(rng.integers(1, n))
    n_snk = int(rng.integers(1, n - n_src + 1))
    gap = int(rng.integers(0, n - n_src - n_snk + 1))
    start = int(rng.integers(0, n))
    for i in range(n):
        p = cyc[(start + i) % n]
        v = rng.choice([np.inf, 0.0, *rng.integers(1, 40, 4) / 4])
        if i < n_src:
            source[p] = v if i else 1 + rng.integers(0, 40) / 4
            if np.isfinite(source[p]) and rng.random() < 0.25:
                sink[p] = source[p] / 2
        elif n_src + gap <= i < n_src + gap + n_snk:
            sink[p] = v if i > n_src + gap else 1 + rng.integers(0, 40) / 4
            if np.isfinite(sink[p]) and rng.random() < 0.25:
                source[p] = sink[p] / 4
        elif rng.random() < 0.5:
            source[p] = sink[p] = rng.integers(0, 10)
    return source, sink, edges


def core_maxflow(source, sink, edges, *, directed=False, k=4, method="auto"):
    """phloem's engine with the method exposed: (flow, sink side, method used)."""
    from phloem import _core

    def f32(a):
        return np.ascontiguousarray(a, np.float32)

    return _core.grid_maxflow(
        f32(source), f32(sink), f32(edges), connectivity=k, directed=directed, threads=None, method=method
    )


@pytest.mark.parametrize("directed", [False, True])
@pytest.mark.parametrize("seed", range(40))
def test_planar_cut_matches_pymaxflow_and_boykov_kolmogorov(seed, directed):
    """Terminals on two border arcs: the dual shortest path runs, and its flow and labels are
    those of an exact min cut (PyMaxflow's value, the labels' own cut value)."""
    rng = np.random.default_rng(1000 + seed)
    h, w = (int(v) for v in rng.integers(2, 30, 2))
    source, sink, edges = planar_graph(rng, h, w, directed)
    flow, side, used = core_maxflow(source, sink, edges, directed=directed)
    assert used == "planar"
    ref, _ = pymaxflow(source, sink, edges, directed=directed)
    assert flow == pytest.approx(ref, rel=1e-6, abs=1e-6)
    assert cut_value(source, sink, edges, side, directed=directed) == pytest.approx(ref, rel=1e-6, abs=1e-6)
    assert not side[np.isinf(source)].any() and side[np.isinf(sink)].all()
    flow_bk, _, used_bk = core_maxflow(source, sink, edges, directed=directed, method="bk")
    assert used_bk == "bk" and flow_bk == pytest.approx(flow, rel=1e-6, abs=1e-6)
    # The public function gives the same cut.
    f2, s2 = grid_maxflow(source, sink, edges, directed=directed)
    assert f2 == flow and np.array_equal(s2, side)


def test_planar_method_falls_back_where_the_graph_is_not_planar():
    rng = np.random.default_rng(5)
    h, w = 9, 11
    source, sink, edges = planar_graph(rng, h, w, False)
    cases = {}
    interior = source.copy()
    interior[4, 5] = 3.0
    cases["interior terminal"] = (interior, sink, edges, 4)
    inter_s, inter_t = np.zeros((h, w)), np.zeros((h, w))
    inter_s[0, 0], inter_t[0, -1], inter_s[-1, -1], inter_t[-1, 0] = 2.0, 3.0, np.inf, 1.5
    cases["interleaved arcs"] = (inter_s, inter_t, edges, 4)
    cases["8-connected"] = (source, sink, rng.integers(0, 9, (h, w, 4)).astype(np.float32), 8)
    cases["one row"] = (source[:1], sink[:1], edges[:1], 4)
    for what, (s, t, e, k) in cases.items():
        flow, side, used = core_maxflow(s, t, e, k=k)
        assert used == "bk", what
        ref, _ = pymaxflow(s, t, e, k=k)
        assert flow == pytest.approx(ref, rel=1e-6, abs=1e-6), what
        assert cut_value(s, t, e, side, k=k) == pytest.approx(ref, rel=1e-6, abs=1e-6), what
        with pytest.raises(ValueError, match="^method:"):
            core_maxflow(s, t, e, k=k, method="planar")


def test_seam_strip_takes_the_planar_method(bark):
    """The benchmark's problem (infinite terminal edges on the first and last column)."""
    h, w = 96, 24
    a, b = bark[:h, :w], bark[100 : 100 + h, 37 : 37 + w]
    edges = kwatra_edges(a, b).astype(np.float32)
    source, sink = np.zeros((h, w)), np.zeros((h, w))
    source[:, 0] = np.inf
    sink[:, -1] = np.inf
    flow, side, used = core_maxflow(source, sink, edges)
    assert used == "planar"
    flow_bk, _, _ = core_maxflow(source, sink, edges, method="bk")
    assert flow == pytest.approx(flow_bk, rel=1e-6)
    assert cut_value(source, sink, edges, side) == pytest.approx(flow_bk, rel=1e-6)


def kwatra_edges(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Kwatra et al. 2003 Eq. 1 for east and south edges, written independently in numpy."""
    d = np.sqrt(((a.astype(np.float64) - b) ** 2).sum(-1))
    e = np.zeros((*d.shape, 2))
    e[:, :-1, 0] = d[:, :-1] + d[:, 1:]
    e[:-1, :, 1] = d[:-1, :] + d[1:, :]
    return e


@pytest.mark.parametrize("shape", [(64, 16), (96, 48)])
def test_real_image_seam_flow_matches_pymaxflow(bark, shape):
    h, w = shape
    a, b = bark[:h, :w], bark[100 : 100 + h, 37 : 37 + w]
    edges = kwatra_edges(a, b).astype(np.float32)
    source = np.zeros((h, w), np.float32)
    sink = np.zeros((h, w), np.float32)
    source[:, 0] = np.inf
    sink[:, -1] = np.inf
    flow, side = grid_maxflow(source, sink, edges)
    ref, _ = pymaxflow(source, sink, edges)
    assert flow == pytest.approx(ref, rel=1e-5)
    assert cut_value(source, sink, edges, side) == pytest.approx(ref, rel=1e-5)
    # The same problem through seam(): a covers columns 0..w-2, b columns 1..w-1.
    region = np.zeros((h, w), bool)
    region[:, 1:-1] = True
    cols = np.arange(w)
    am, bm = np.broadcast_to(cols < w - 1, (h, w)), np.broadcast_to(cols > 0, (h, w))
    take_b, energy = astuple(seam(a, b, region, a_mask=am, b_mask=bm, full_output=True))
    # Edges from the tied border columns into the region are not cut by seam() (those pixels
    # are outside the region), so compare against the flow on the region's own edges.
    inner = edges.copy()
    inner[:, 0, 0] = 0
    inner[:, -2, 0] = 0

    src_t = np.zeros((h, w))
    src_t[:, 1] = BIG
    snk_t = np.zeros((h, w))
    snk_t[:, -2] = BIG
    ref_inner, _ = pymaxflow(src_t, snk_t, inner)
    assert energy == pytest.approx(ref_inner, rel=1e-5)
    assert not take_b[:, :2].any() and take_b[:, -2:].all()


def test_seam_costs_match_independent_numpy_costs(bark):
    a, b = bark[:40, :50], bark[60:100, 90:140]
    region = np.ones((40, 50), bool)
    seeds = np.zeros((40, 50), np.int8)
    seeds[:, 0], seeds[:, -1] = 1, 2
    _mask, e_builtin = astuple(seam(a, b, region, seeds=seeds, full_output=True))
    _mask2, e_numpy = astuple(seam(a, b, region, seeds=seeds, cost=kwatra_edges(a, b), full_output=True))
    assert e_builtin == pytest.approx(e_numpy, rel=1e-5)
    # Luo's cost from its definition: min(d(s), d(t)) / G(s, t) on 0-255 colours.
    a8, b8 = 255.0 * a.astype(np.float64), 255.0 * b.astype(np.float64)
    d = (np.sqrt(((a8 - b8) ** 2).sum(-1))) ** 4

    def gmag(img):
        pad = np.pad(img, ((1, 1), (1, 1), (0, 0)), mode="edge")
        gx = pad[1:-1, 2:] - pad[1:-1, :-2]
        gy = pad[2:, 1:-1] - pad[:-2, 1:-1]
        # one-sided differences span one pixel at the border, central ones two
        sx = np.full(img.shape[:2], 2.0)
        sx[:, [0, -1]] = 1
        sy = np.full(img.shape[:2], 2.0)
        sy[[0, -1], :] = 1
        return np.sqrt((np.sqrt((gx**2).sum(-1)) / sx) ** 2 + (np.sqrt((gy**2).sum(-1)) / sy) ** 2)

    delta = gmag(a8) + gmag(b8)
    e = np.zeros((40, 50, 2))
    e[:, :-1, 0] = np.minimum(d[:, :-1], d[:, 1:]) / (delta[:, :-1] + delta[:, 1:] + 1e-6)
    e[:-1, :, 1] = np.minimum(d[:-1], d[1:]) / (delta[:-1] + delta[1:] + 1e-6)
    _, e_luo = astuple(seam(a, b, region, seeds=seeds, cost="luo", full_output=True))
    _, e_luo_np = astuple(seam(a, b, region, seeds=seeds, cost=e.astype(np.float32), full_output=True))
    assert e_luo == pytest.approx(e_luo_np, rel=1e-4)


def test_seam_on_a_disk_respects_the_border_rule(bark):
    """A disk-shaped overlap: old content on the left, a new disk fragment (as in Sibbing et
    al. §5.3) on the right. Region pixels next to old-only pixels keep a, next to new-only
    pixels take b."""
    h, w = 80, 80
    yy, xx = np.mgrid[0:h, 0:w]
    old = xx < 45
    new = (yy - 40) ** 2 + (xx - 45) ** 2 < 30**2
    region = old & new
    a, b = bark[:h, :w], bark[120 : 120 + h, 60 : 60 + w]
    for cost in ("kwatra", "gradient", "luo"):
        take_b = seam(a, b, region, a_mask=old, b_mask=new, cost=cost, border_weight=np.inf)

        for y, x in zip(*np.nonzero(region)):
            nb = [(y + dy, x + dx) for dy, dx in DIRS[:4] if 0 <= y + dy < h and 0 <= x + dx < w]
            by_a = any(old[p] and not new[p] for p in nb)
            by_b = any(new[p] and not old[p] for p in nb)
            if by_a and not by_b:
                assert not take_b[y, x], (cost, y, x)
            if by_b and not by_a:
                assert take_b[y, x], (cost, y, x)
        assert (take_b[new & ~old]).all() and not take_b[old & ~new].any()
        assert not take_b[~old & ~new].any()


def test_seeds_are_hard_and_identical_images_cost_nothing(bark):
    a = bark[:30, :30]
    region = np.ones((30, 30), bool)
    seeds = np.zeros((30, 30), int)
    seeds[10, 10], seeds[20, 20] = 2, 1
    take_b, energy = astuple(seam(a, a, region, seeds=seeds, full_output=True))
    assert energy == 0
    assert take_b[10, 10] and not take_b[20, 20]


def test_threads_do_not_change_the_seam(bark):
    a, b = bark[:128, :96], bark[128:, 100:196]
    region = np.ones(a.shape[:2], bool)
    seeds = np.zeros(a.shape[:2], int)
    seeds[:, 0], seeds[:, -1] = 1, 2
    one = astuple(seam(a, b, region, seeds=seeds, cost="gradient", threads=1, full_output=True))
    two = astuple(seam(a, b, region, seeds=seeds, cost="gradient", threads=2, full_output=True))
    assert np.array_equal(one[0], two[0]) and one[1] == two[1]


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"source": np.zeros((3, 3)), "sink": np.zeros((3, 4)), "edges": np.zeros((3, 3, 2))}, "sink"),
        ({"source": np.zeros((3, 3)), "sink": np.zeros((3, 3)), "edges": np.zeros((3, 3, 3))}, "edges"),
        ({"source": np.zeros((3, 3)), "sink": np.zeros((3, 3)), "edges": -np.ones((3, 3, 2))}, "edges"),
        ({"source": np.full((3, 3), np.nan), "sink": np.zeros((3, 3)), "edges": np.zeros((3, 3, 2))}, "source"),
        ({"source": -np.ones((3, 3)), "sink": np.zeros((3, 3)), "edges": np.zeros((3, 3, 2))}, "source"),
        ({"source": np.full((3, 3), np.inf), "sink": np.full((3, 3), np.inf), "edges": np.zeros((3, 3, 2))}, "sink"),
        ({"source": np.zeros((0, 3)), "sink": np.zeros((0, 3)), "edges": np.zeros((0, 3, 2))}, "source"),
        ({"source": np.zeros((3, 3)), "sink": np.zeros((3, 3)), "edges": np.full((3, 3, 2), np.inf)}, "edges"),
    ],
)
def test_grid_maxflow_bad_input(kwargs, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        grid_maxflow(**kwargs)


def test_grid_maxflow_bad_connectivity():
    with pytest.raises(ValueError, match="^connectivity:"):
        grid_maxflow(np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 2, 3)), connectivity=6)


def test_seam_bad_input(bark):
    a = bark[:10, :10]
    region = np.ones((10, 10), bool)
    cases = [
        (dict(a=a, b=bark[:10, :9], region=region), "b"),
        (dict(a=a, b=a, region=np.zeros((10, 10), bool)), "region"),
        (dict(a=a, b=a, region=np.ones((9, 10), bool)), "region"),
        (dict(a=np.full((10, 10), np.nan), b=np.zeros((10, 10)), region=region), "a"),
        (dict(a=a, b=np.where(region[..., None], np.inf, a), region=region), "b"),
        (dict(a=a, b=a, region=region, cost="sobel"), "cost"),
        (dict(a=a, b=a, region=region, cost=np.ones((10, 10, 3))), "cost"),
        (dict(a=a, b=a, region=region, cost=-np.ones((10, 10, 2))), "cost"),
        (dict(a=a, b=a, region=region, seeds=np.full((10, 10), 3)), "seeds"),
        (dict(a=a, b=a, region=np.eye(10, dtype=bool), seeds=np.ones((10, 10), int)), "seeds"),
        (dict(a=a, b=a, region=region, a_mask=np.eye(10, dtype=bool)), "a_mask"),
        (dict(a=a, b=a, region=region, border_weight=-1.0), "border_weight"),
        (dict(a=a, b=a, region=region, connectivity=5), "connectivity"),
    ]
    for kwargs, name in cases:
        with pytest.raises(ValueError, match=f"^{name}:"):
            seam(**kwargs)
