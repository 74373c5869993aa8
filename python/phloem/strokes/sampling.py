"""Global texture sampling (Luo et al. §2): where along the source stroke each target sample takes
its piece, chosen by dynamic programming so that the summed compositing energy of neighbouring
pieces is minimal.

Between two control pairs the target samples lie evenly, about one spacing ``h`` apart. The
uniform mapping would take sample ``i`` at the same fraction of the source segment; the
programme may move it by up to :data:`BAND` half-steps of the uniform source step either way
(:data:`CANDIDATES` positions, the uniform one among them) while the mapping stays monotone
with a bounded stretch: each source step lies within ``[1/stretch, stretch]`` times the
uniform one. The end samples stay on the controls. The uniform mapping is one of the paths,
so the chosen one never costs more.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

from . import fetch as _fetch
from .stroke_set import StrokePair

F64 = NDArray[np.float64]

#: Candidate positions either side of the uniform one, in half uniform source steps.
BAND: Final = 4
#: Candidate source positions per free sample.
CANDIDATES: Final = 2 * BAND + 1


@dataclass(frozen=True)
class Sampling:
    """The samples of one stroke pair and the source positions chosen for them.

    Attributes
    ----------
    target_arc, source_arc : (n,) ndarray of float64
        Arc length (px) of each sample along the target stroke and of its piece's centre along
        the source stroke.
    half_length : (n,) ndarray of float64
        Half the length of each sample's piece (the local sample spacing).
    energy : float
        The summed compositing energy of neighbouring pieces along the chosen mapping.
    uniform_energy : float
        The same sum along the uniform (arc-length proportional) mapping.
    """

    target_arc: F64
    source_arc: F64
    half_length: F64
    energy: float
    uniform_energy: float


def best_path(energies: list[F64]) -> tuple[list[int], float]:
    """The minimum-energy path through a chain of candidate sets (Viterbi).

    ``energies[i]`` is the ``(K_i, K_{i+1})`` cost of going from candidate ``a`` of sample
    ``i`` to candidate ``b`` of sample ``i + 1`` (``inf`` where not allowed). Returns one
    candidate index per sample and the path's energy; ties go to the lowest index. ``inf``
    if no path is allowed.
    """
    if not energies:
        return [0], 0.0
    cost = np.zeros(energies[0].shape[0])
    back = []
    for e in energies:
        total = cost[:, None] + e
        arg = np.argmin(total, axis=0)
        back.append(arg)
        cost = total[arg, np.arange(total.shape[1])]
    end = int(np.argmin(cost))
    path = [end]
    for arg in reversed(back):
        path.append(int(arg[path[-1]]))
    return path[::-1], float(cost[end])


@dataclass(frozen=True)
class _Segment:
    target_arc: F64  # (m + 1,)
    candidates: list[F64]  # per sample
    uniform: list[int]  # the uniform candidate's index per sample
    step: float  # uniform source step
    half_length: float


def _segment(t0: float, t1: float, s0: float, s1: float, spacing: float, stretch: float) -> _Segment:
    m = max(1, round((t1 - t0) / spacing))
    target = np.linspace(t0, t1, m + 1)
    step = (s1 - s0) / m
    lo, hi = step / stretch, step * stretch
    offsets = np.arange(-BAND, BAND + 1)
    cands, uni = [], []
    for i in range(m + 1):
        if i in (0, m):
            cands.append(np.array([s0 if i == 0 else s1]))
            uni.append(0)
            continue
        c = s0 + i * step + offsets * (step / 2)
        # Only positions some path can reach from the first control and still leave the last
        # one reachable: the others cannot be on a path, so they are not scored.
        eps = 1e-9 * max(1.0, abs(s1))
        keep = (c >= max(s0, s0 + i * lo, s1 - (m - i) * hi) - eps) & (
            c <= min(s1, s0 + i * hi, s1 - (m - i) * lo) + eps
        )
        cands.append(c[keep])
        uni.append(int(np.flatnonzero(offsets[keep] == 0)[0]))
    return _Segment(target, cands, uni, step, (t1 - t0) / m)


def _segments(pair: StrokePair, spacing: float, stretch: float) -> list[_Segment]:
    tl, sl = pair.target.length(), pair.source.length()
    c = pair.controls
    return [
        _segment(tl * c[k, 1], tl * c[k + 1, 1], sl * c[k, 0], sl * c[k + 1, 0], spacing, stretch)
        for k in range(len(c) - 1)
    ]


def sample(
    pair: StrokePair,
    part: _fetch.StrokeSource,
    *,
    spacing: float,
    stretch: float,
    uniform: bool = False,
    threads: int | None,
) -> Sampling:
    """The samples of ``pair`` with their source positions: chosen by the dynamic programme
    (or the uniform mapping if ``uniform``), and both mappings' energies."""
    segments = _segments(pair, spacing, stretch)
    if uniform:
        # Only the uniform path is scored: its own energy is all the result reports.
        segments = [
            _Segment(g.target_arc, [c[u : u + 1] for c, u in zip(g.candidates, g.uniform, strict=True)],
                     [0] * len(g.candidates), g.step, g.half_length)
            for g in segments
        ]  # fmt: skip
    rows, pairs, index = [], [], []
    # Every candidate piece of every segment, numbered; then the allowed transitions.
    n = 0
    for seg in segments:
        idx = []
        for i, c in enumerate(seg.candidates):
            t = np.full(len(c), seg.target_arc[i])
            rows.append(_fetch.specs(pair, t, c, part, np.full(len(c), seg.half_length)))
            idx.append(np.arange(n, n + len(c)))
            n += len(c)
        index.append(idx)
    tables: list[list[F64]] = []
    for seg, idx in zip(segments, index, strict=True):
        lo, hi = seg.step / stretch - 1e-9, seg.step * stretch + 1e-9
        tab = []
        for i in range(len(seg.candidates) - 1):
            d = seg.candidates[i + 1][None, :] - seg.candidates[i][:, None]
            ok = (d >= lo) & (d <= hi)
            a, b = np.nonzero(ok)
            pairs.append(np.stack([idx[i][a], idx[i + 1][b]], axis=1))
            tab.append(np.where(ok, 0.0, np.inf))
        tables.append(tab)
    flat_pairs = np.concatenate(pairs) if pairs else np.zeros((0, 2), np.int64)
    spec = np.concatenate(rows)
    energies = _fetch.pair_energies(part, spec, flat_pairs.astype(np.int64), threads=threads)
    k = 0
    for tab in tables:
        for e in tab:
            ok = np.isfinite(e)
            cnt = int(ok.sum())
            e[ok] = energies[k : k + cnt]
            k += cnt
    target_arc: list[float] = []
    source_arc: list[float] = []
    halves: list[float] = []
    total = uniform_total = 0.0
    for s, (seg, tab) in enumerate(zip(segments, tables, strict=True)):
        path_uniform = seg.uniform
        e_uniform = float(sum(tab[i][path_uniform[i], path_uniform[i + 1]] for i in range(len(tab))))
        path, e_path = best_path(tab)
        total += e_path
        uniform_total += e_uniform
        first = 0 if s == 0 else 1  # a control's sample is shared with the segment before
        target_arc.extend(seg.target_arc[first:].tolist())
        source_arc.extend(float(seg.candidates[i][path[i]]) for i in range(first, len(path)))
        halves.extend([seg.half_length] * (len(path) - first))
    return Sampling(np.array(target_arc), np.array(source_arc), np.array(halves), total, uniform_total)
