"""The furcation model of Sibbing, Pavić, Kobbelt 2010, §4.3: where a branch forks (a linear SVM
over non-causal neighbourhoods) and how (the child's first segment copied from the best-matching
input furcation).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from .._validate import check_float, check_int
from ._elements import F64, _check_k, _check_skeleton, _dist, _elements, _generations, _tangent, _wrap
from .bending import default_h
from .skeleton import Branch, Skeleton

__all__ = ["FurcationModel"]

#: The quantile of the input's furcation distances that ``FurcationModel.fit`` takes as its
#: default ``min_spacing``: the closest pairs, a vertex or two apart, are children leaving one junction.
SPACING_QUANTILE = 0.1
#: Bins of the parent's net turn across a vertex (quantiles of the input's vertices) that the
#: SVM sees, one indicator each: real parents bend where they fork, which signed angles alone
#: cannot tell a linear classifier (a bend either way looks the same to it).
TURN_BINS = 4


def _noncausal(a_full: F64, r_full: F64, k: int, h: float) -> tuple[F64, F64]:
    """Non-causal neighbourhoods ``(α_{i-k..i+k}, r_{i-k..i+k} / h)`` of every vertex of a branch.

    ``a_full`` has one angle per vertex (0 at the two end points); outside the branch angles
    are padded with 0 (straight) and thickness with the end values.
    """
    n = len(a_full)
    a = np.concatenate([np.zeros(k), a_full, np.zeros(k)])
    r = np.concatenate([np.full(k, r_full[0]), r_full, np.full(k, r_full[-1])]) / h
    idx = np.arange(n)[:, None] + np.arange(2 * k + 1)[None, :]
    return a[idx], r[idx]


def _net_turns(na: F64) -> F64:
    """``|Σ α|`` over each non-causal neighbourhood: how far the parent turns across each vertex."""
    return np.asarray(np.abs(na.sum(axis=1)), dtype=np.float64)


def _turn_bins(na: F64, edges: F64) -> F64:
    """Indicators of the bin between ``edges`` that each vertex's net turn falls in, ``(n, len(edges) + 1)``."""
    idx = np.searchsorted(edges, _net_turns(na))
    return np.asarray(idx[:, None] == np.arange(len(edges) + 1)[None, :], dtype=np.float64)


def _per_vertex(branch: Branch) -> tuple[F64, F64]:
    a = np.zeros(len(branch))
    if len(branch) >= 3:
        a[1:-1] = branch.angles()
    return a, branch.thickness.copy()


def _gaps(n: int, furcations: Sequence[int]) -> tuple[F64, F64]:
    """Index distances ``n⁻, n⁺`` of every vertex to the previous / next furcation (or end point)."""
    marks = np.array(sorted({0, n - 1, *[int(f) for f in furcations]}), dtype=np.int64)
    i = np.arange(n)
    # the mark strictly before / after i (a furcation at i does not count for itself)
    prev_pos = np.searchsorted(marks, i, side="left") - 1
    next_pos = np.searchsorted(marks, i, side="right")
    prev = np.where(prev_pos >= 0, marks[np.clip(prev_pos, 0, len(marks) - 1)], 0)
    nxt = np.where(next_pos < len(marks), marks[np.clip(next_pos, 0, len(marks) - 1)], n - 1)
    return (i - prev).astype(np.float64), (nxt - i).astype(np.float64)


@dataclass
class FurcationModel:
    """The furcation model of §4.3: where to branch (linear SVM) and how (non-causal matching).

    Build it with :meth:`fit`.

    Attributes
    ----------
    h : float
        Resampling step; must equal the bending model's.
    k, c : int
        Half-width of the non-causal neighbourhood; candidates to choose among for the child's
        first segment.
    weights, bias : ndarray, float
        The linear classifier ``L(x) = weights · x + bias`` on standardised features
        ``(α_{i-k..i+k}, r_{i-k..i+k}/h, b_1..b_B, n⁻, n⁺)`` (``4k + 4 + B`` values). The
        paper's ``4k + 4`` are extended by ``B =`` :data:`TURN_BINS` indicators ``b`` of the
        parent's net turn ``|Σ α|`` across the vertex: real parents bend where they fork,
        away from the child (:func:`phloem.metrics.parent_turns`), and a linear classifier on
        signed angles cannot see a bend that may go either way.
    mean, scale : ndarray
        Feature standardisation.
    platt : (float, float)
        Sigmoid ``p = 1 / (1 + exp(A L(x) + B))`` that turns ``L`` into a probability.
    examples_alpha, examples_r : ndarray, shape (F, 2k + 1)
        Non-causal neighbourhoods of the input's furcation vertices.
    offsets : ndarray, shape (F,)
        Branching angle of each input child: its first heading minus the parent's tangent.
    child_alpha, child_r : list of ndarray
        First ``k + 1`` elements of each input child (its initial segment).
    child_r0 : ndarray, shape (F,)
        Thickness of each child's first vertex.
    counts : dict of int to list of int
        Number of children of each input branch, per generation (the distribution of ``d``).
    min_spacing : int
        Default minimum index distance between furcations picked on one branch.
    gaps : ndarray of int64
        Index distances between neighbouring furcations on one input branch: the spacing
        :meth:`pick` draws from where the SVM weights ``n⁻`` or ``n⁺`` negatively.
    turn_edges : ndarray, shape (TURN_BINS - 1,)
        Edges of the net-turn bins: quantiles of ``|Σ α|`` over the input's vertices.
    train_seconds : float
        Time spent training the SVM.

    Examples
    --------
    >>> from phloem.branching import synthetic_skeleton
    >>> sk = synthetic_skeleton(0)
    >>> fm = FurcationModel.fit(sk, h=2.0)
    >>> fm.weights.shape
    (20,)
    """

    h: float
    k: int
    c: int
    weights: F64
    bias: float
    mean: F64
    scale: F64
    platt: tuple[float, float]
    examples_alpha: F64
    examples_r: F64
    offsets: F64
    child_alpha: list[F64]
    child_r: list[F64]
    child_r0: F64
    counts: dict[int, list[int]]
    min_spacing: int = 0
    train_seconds: float = 0.0
    gaps: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    turn_edges: F64 = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def fit(
        cls,
        skeleton: Skeleton,
        *,
        h: float | None = None,
        k: int = 3,
        c: int = 2,
        svm_c: float = 1.0,
        min_spacing: int | None = None,
    ) -> FurcationModel:
        """Learn where and how the example structure branches.

        Parameters
        ----------
        skeleton : Skeleton
            The example; needs at least one child branch.
        h : float, optional
            Resampling step; default :func:`default_h` (use the bending model's).
        k : int
            Half-width of the non-causal neighbourhood (paper: 3).
        c : int
            Candidates for the child's first segment (paper's ``c``).
        svm_c : float
            SVM soft-margin constant ``C``; furcations are weighted up by the class ratio.
        min_spacing : int, optional
            Default minimum index distance between furcations picked on one branch (0 = none).
            Default: the :data:`SPACING_QUANTILE` quantile of the distances between neighbouring
            furcations on one input branch (rounded down), so the output clusters furcations no
            more tightly than all but the input's closest pairs do. The smallest distance would
            let the trace's close pairs (two children leaving one junction) set the spacing of
            every branch.

        Returns
        -------
        FurcationModel

        Examples
        --------
        >>> from phloem.branching import synthetic_skeleton
        >>> fm = FurcationModel.fit(synthetic_skeleton(1), h=2.0, k=2)
        >>> p = fm.probabilities(synthetic_skeleton(2).resample(2.0).branches[0])
        >>> bool(((0 <= p) & (p <= 1)).all())
        True
        """
        import time

        _check_skeleton(skeleton)
        h = default_h(skeleton) if h is None else check_float(h, "h", 0.0, inclusive=False)
        k = _check_k(k)
        c = check_int(c, "c", 1)
        svm_c = check_float(svm_c, "svm_c", 0.0, inclusive=False)
        src = skeleton.resample(h)
        kids = src.children()
        gaps = np.array([int(g) for v in kids.values() for g in np.diff(sorted({i for i, _ in v}))], np.int64)
        if min_spacing is None:
            min_spacing = int(np.floor(np.quantile(gaps, SPACING_QUANTILE))) if len(gaps) else 0
        min_spacing = check_int(min_spacing, "min_spacing", 0)
        gens = _generations(src)
        if not any(kids.values()):
            raise ValueError("skeleton: has no child branches, so there are no furcations to learn from")
        hoods = [_noncausal(*_per_vertex(b), k, h) for b in src.branches]
        turns = np.concatenate([_net_turns(na) for na, _ in hoods])
        turn_edges = np.quantile(turns, np.arange(1, TURN_BINS) / TURN_BINS)
        feats, labels = [], []
        ex_a, ex_r, offsets, ch_a, ch_r, ch_r0 = [], [], [], [], [], []
        counts: dict[int, list[int]] = {}
        for bi, b in enumerate(src.branches):
            na, nr = hoods[bi]
            fur = sorted({v for v, _ in kids[bi]})
            nm, npl = _gaps(len(b), fur)
            feats.append(np.hstack([na, nr, _turn_bins(na, turn_edges), nm[:, None], npl[:, None]]))
            lab = -np.ones(len(b), np.int32)
            lab[fur] = 1
            labels.append(lab)
            counts.setdefault(gens[bi], []).append(len(kids[bi]))
            for v, ci in kids[bi]:
                child = src.branches[ci]
                ex_a.append(na[v])
                ex_r.append(nr[v])
                offsets.append(_wrap(child.heading() - _tangent(b, v)))
                ca, cr = _elements(child)
                ch_a.append(ca[: k + 1])
                ch_r.append(cr[: k + 1])
                ch_r0.append(float(child.thickness[0]))
        X = np.vstack(feats)
        y = np.concatenate(labels)
        mean = X.mean(axis=0)
        scale = X.std(axis=0)
        scale[scale < 1e-12] = 1.0
        Z = ((X - mean) / scale).astype(np.float32)
        t0 = time.perf_counter()
        w, b0 = _linear_svm(Z, y, svm_c)
        train = time.perf_counter() - t0
        f = Z.astype(np.float64) @ w + b0
        platt = _platt(f, y)
        return cls(
            h=h,
            k=k,
            c=c,
            weights=w,
            bias=b0,
            mean=mean,
            scale=scale,
            platt=platt,
            examples_alpha=np.vstack(ex_a),
            examples_r=np.vstack(ex_r),
            offsets=np.asarray(offsets),
            child_alpha=ch_a,
            child_r=ch_r,
            child_r0=np.asarray(ch_r0),
            counts=counts,
            min_spacing=min_spacing,
            train_seconds=train,
            gaps=gaps,
            turn_edges=turn_edges,
        )

    def features(self, branch: Branch, furcations: Sequence[int] = ()) -> F64:
        """The ``4k + 4 + TURN_BINS`` raw features of every vertex of a branch resampled to ``h``."""
        a_full, r_full = _per_vertex(branch)
        na, nr = _noncausal(a_full, r_full, self.k, self.h)
        nm, npl = _gaps(len(branch), furcations)
        return np.hstack([na, nr, _turn_bins(na, self.turn_edges), nm[:, None], npl[:, None]])

    def decision(self, branch: Branch, furcations: Sequence[int] = ()) -> F64:
        """The classifier value ``L(x)`` per vertex (positive: furcation side)."""
        z = (self.features(branch, furcations) - self.mean) / self.scale
        return np.asarray(z @ self.weights + self.bias, dtype=np.float64)

    def probabilities(self, branch: Branch, furcations: Sequence[int] = ()) -> F64:
        """Furcation probability of every vertex of ``branch`` (resampled to ``h``).

        Parameters
        ----------
        branch : Branch
            A branch already resampled to the model's step ``h``.
        furcations : sequence of int
            Vertices that already carry a furcation (they set ``n⁻`` and ``n⁺``).

        Returns
        -------
        ndarray of float64, shape (len(branch),)
        """
        A, B = self.platt
        return np.asarray(1.0 / (1.0 + np.exp(np.clip(A * self.decision(branch, furcations) + B, -500, 500))))

    def pick(
        self,
        branch: Branch,
        d: int,
        *,
        existing: Sequence[int] = (),
        min_spacing: int | None = None,
        rng: np.random.Generator | None = None,
        tried: Sequence[int] = (),
    ) -> list[int]:
        """Pick ``d`` furcation vertices of maximum probability, one after another (§4.3).

        Each pick updates ``n⁻, n⁺`` of the others; with ``min_spacing`` a pick also blocks the
        vertices closer than that. End points are never picked.

        §4.3 counts on ``n⁻, n⁺`` to keep furcations apart. On an input whose gaps are
        heavy-tailed (bursts of furcations between long bare stretches) the linear SVM weights
        one or both negatively instead: each pick draws the next to its side, and the picks pack
        a stretch at ``min_spacing`` (a comb; ``docs/pipelines/branching/quality.md``). For
        such a model, given ``rng``, every furcation (``existing`` and picked) blocks the
        vertices closer than a spacing drawn from the input's :attr:`gaps` (at least
        ``min_spacing``), so that children are spaced along their parent as the input's are.
        ``tried`` are vertices tried before where no child could start: they count as
        furcations but block only ``min_spacing``, so that failed tries do not use up a branch.

        Examples
        --------
        >>> from phloem.branching import synthetic_skeleton
        >>> fm = FurcationModel.fit(synthetic_skeleton(0), h=2.0)
        >>> b = synthetic_skeleton(3).resample(2.0).branches[0]
        >>> picks = fm.pick(b, 3, min_spacing=5)
        >>> len(picks), all(abs(p - q) >= 5 for p in picks for q in picks if p != q)
        (3, True)
        """
        d = check_int(d, "d", 0)
        spacing = self.min_spacing if min_spacing is None else check_int(min_spacing, "min_spacing", 0)

        draw = rng is not None and len(self.gaps) > 0 and bool((self.weights[-2:] < 0).any())

        def blocked() -> int:
            return max(spacing, int(rng.choice(self.gaps))) if draw and rng is not None else spacing

        chosen = [int(e) for e in existing] + [int(e) for e in tried]
        radius = [blocked() for _ in existing] + [spacing for _ in tried]
        out: list[int] = []
        n = len(branch)
        for _ in range(d):
            p = self.probabilities(branch, chosen)
            p[[0, n - 1]] = -1.0
            for f, s in zip(chosen, radius, strict=True):
                p[max(0, f - max(s - 1, 0)) : f + max(s, 1)] = -1.0
            i = int(np.argmax(p))
            if p[i] < 0:
                break
            chosen.append(i)
            radius.append(blocked())
            out.append(i)
        return out

    def child_start(self, branch: Branch, vertex: int, rng: np.random.Generator) -> list[int]:
        """Input furcations ordered for copying a child's first segment at ``vertex`` (§4.3).

        The first entry is drawn among the ``c`` best matches of the non-causal neighbourhood
        with probability proportional to quality; the rest follow by decreasing quality
        (fallbacks when the first would cross the structure). Besides the paper's angles and
        thicknesses the match compares the neighbourhoods' net turns ``Σ α``, signed, so that the
        child leaves on the side of the parent's bend that the input's children leave on (the
        outer side: a junction opens as a ``Y``). Matched element by element alone, a grown
        parent's bend, spread over other vertices than an input kink, finds examples of either
        side about as often.
        """
        a_full, r_full = _per_vertex(branch)
        na, nr = _noncausal(a_full, r_full, self.k, self.h)
        q = _dist(self.examples_alpha, na[vertex][None, :]) * _dist(self.examples_r, nr[vertex][None, :])
        q *= _dist(self.examples_alpha.sum(axis=1)[:, None], np.array([[na[vertex].sum()]]))
        order = np.argsort(-q, kind="stable")
        top = order[: self.c]
        first = int(rng.choice(top, p=q[top] / q[top].sum()))
        return [first] + [int(o) for o in order if o != first]


def _linear_svm(Z: NDArray[np.float32], y: NDArray[np.int32], svm_c: float) -> tuple[F64, float]:
    """Train a linear C-SVC (OpenCV's libsvm port) and return its hyperplane ``(w, b)``.

    The positive class is weighted by the negative/positive ratio so that the rare furcations
    are not ignored. ``w, b`` are read back from raw outputs and oriented so that ``w·z + b > 0``
    means "furcation".
    """
    svm = cv2.ml.SVM.create()
    svm.setType(cv2.ml.SVM_C_SVC)
    svm.setKernel(cv2.ml.SVM_LINEAR)
    svm.setC(svm_c)
    pos = max(int((y > 0).sum()), 1)
    svm.setClassWeights(np.array([1.0, max(1.0, (len(y) - pos) / pos)]))
    svm.setTermCriteria((cv2.TERM_CRITERIA_MAX_ITER + cv2.TERM_CRITERIA_EPS, 100000, 1e-6))
    svm.train(Z, cv2.ml.ROW_SAMPLE, y.reshape(-1, 1))
    dim = Z.shape[1]
    probe = np.vstack([np.zeros(dim), np.eye(dim)]).astype(np.float32)
    raw = svm.predict(probe, flags=cv2.ml.STAT_MODEL_RAW_OUTPUT)[1].ravel().astype(np.float64)
    b, w = raw[0], raw[1:] - raw[0]
    # OpenCV's raw output sign is not tied to the label order; orient by the predicted labels.
    lab = svm.predict(Z)[1].ravel()
    f = Z.astype(np.float64) @ w + b
    ref = lab if (lab > 0).any() and (lab < 0).any() else y
    if f[ref > 0].mean() < f[ref < 0].mean():
        w, b = -w, -b
    return w, float(b)


def _platt(f: F64, y: NDArray[np.int32]) -> tuple[float, float]:
    """Platt's sigmoid fit ``p = 1 / (1 + exp(A f + B))`` by Newton's method (Lin et al. 2007)."""
    n_pos, n_neg = float((y > 0).sum()), float((y <= 0).sum())
    t = np.where(y > 0, (n_pos + 1) / (n_pos + 2), 1 / (n_neg + 2))
    A, B = 0.0, math.log((n_neg + 1) / (n_pos + 1))
    for _ in range(100):
        z = np.clip(A * f + B, -500, 500)
        p = 1.0 / (1.0 + np.exp(z))
        # gradient and Hessian of the cross-entropy with respect to (A, B)
        g = np.array([((t - p) * f).sum(), (t - p).sum()])
        wgt = p * (1 - p)
        H = np.array([[(wgt * f * f).sum(), (wgt * f).sum()], [(wgt * f).sum(), wgt.sum()]]) + 1e-12 * np.eye(2)
        step = np.linalg.solve(H, g)
        A, B = A - float(step[0]), B - float(step[1])
        if np.abs(step).max() < 1e-10:
            break
    return A, B
