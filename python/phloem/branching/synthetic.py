"""A random branching structure with known statistics, for tests, benches and examples."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._validate import check_float, check_int, check_seed
from ._elements import F64, _tangent
from .skeleton import Branch, Skeleton

__all__ = ["synthetic_skeleton"]


def synthetic_skeleton(
    seed: Any = 0, *, length: float = 240.0, h: float = 2.0, sigma: float = 0.25, furcations: int = 4
) -> Skeleton:
    """A random branching structure with known statistics, for tests, benches and examples.

    A main branch is a random walk of ``length`` pixels with step ``h`` whose turning angles
    follow ``α_i = 0.5 α_{i-1} + N(0, σ²)``; its thickness tapers from 4 px and drops by 30 %
    at each of the ``furcations`` furcation vertices (the rule a furcation model can learn),
    where a child (a shorter, thinner walk leaving at 0.4–0.9 rad to a random side) starts.
    The shape is the bounding box plus a margin.

    Examples
    --------
    >>> sk = synthetic_skeleton(0)
    >>> len(sk.branches), sk.branches[1].parent[0]
    (5, 0)
    """
    rng = np.random.default_rng(check_seed(seed))
    length = check_float(length, "length", 0.0, inclusive=False)
    h = check_float(h, "h", 0.0, inclusive=False)
    sigma = check_float(sigma, "sigma", 0.0)
    furcations = check_int(furcations, "furcations", 0)

    def walk(n: int) -> F64:
        a = np.zeros(n)
        for i in range(n):
            a[i] = (0.5 * a[i - 1] if i else 0.0) + rng.normal(0.0, sigma)
        return a

    n = max(int(length / h), 8)
    a = walk(n - 2)
    spacing = max(n // (furcations + 1), 1)
    fur = sorted(
        int(v) for v in rng.choice(np.arange(spacing // 2 + 2, n - 3), size=min(furcations, n - 6), replace=False)
    )
    thick = 4.0 * np.linspace(1.0, 0.6, n)
    for v in fur:
        thick[v + 1 :] *= 0.7
    thick = np.maximum(thick * (1.0 + 0.03 * rng.standard_normal(n)), 0.3)
    main = Branch.from_angles([0.0, 0.0], 0.0, a, thick, h)
    branches = [main]
    for v in fur:
        cn = max(int(rng.uniform(0.25, 0.45) * n), 10)
        hd = _tangent(main, v) + float(rng.choice([-1.0, 1.0])) * float(rng.uniform(0.4, 0.9))
        ct = thick[v] * 0.7 * np.linspace(1.0, 0.6, cn) * (1.0 + 0.03 * rng.standard_normal(cn))
        branches.append(Branch.from_angles(main.points[v], hd, walk(cn - 2), ct, h, parent=(0, v)))
    pts = np.vstack([b.points for b in branches])
    lo = pts.min(axis=0) - 10.0
    for b in branches:
        b.points = b.points - lo
    hi = np.vstack([b.points for b in branches]).max(axis=0) + 10.0
    return Skeleton(branches, (math.ceil(hi[1]), math.ceil(hi[0])))
