"""A small trainable crown/trunk pixel classifier, the light stand-in for the paper's FCN (Argudo et al. 2017 §4.3)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from .._api import Seed
from .._validate import as_mask, check_float, check_int, check_seed
from ._checks import F32, F64, Mask, as_rgba, check_alpha_threshold
from .segmentation import segment

__all__ = ["TrunkClassifier"]


def _trunk_features(img: F32, opaque: Mask, prior: Mask) -> F64:
    """Per-pixel features of the opaque pixels (rows of the result, in ``np.nonzero`` order).

    Position (relative height, offset from the trunk's foot), the smoothed width profile (as a
    fraction of the widest row and against the foot's width), thickness (distance to the
    transparent background), CIELAB colour, local lightness contrast, and the training-free
    segmenter's answer with the signed height above its crown baseline.
    """
    h, w = opaque.shape
    ys, xs = np.nonzero(opaque)
    rows = np.flatnonzero(opaque.any(axis=1))
    top, bottom = int(rows[0]), int(rows[-1])
    height = float(bottom - top + 1)
    width = opaque.sum(axis=1).astype(np.float64)
    k = max(1, round(0.01 * h)) | 1
    padded = np.pad(width, k // 2, mode="edge")
    width = np.median(np.lib.stride_tricks.sliding_window_view(padded, k), axis=1)
    widest = max(float(width.max()), 1.0)
    base = width[max(top, bottom - max(1, int(0.1 * height)) + 1) : bottom + 1]
    foot = max(float(np.quantile(base, 0.3)), 1.0)
    low = ys >= bottom - max(1, int(0.02 * height))
    cx = float(np.median(xs[low])) if low.any() else w / 2
    dt = cv2.distanceTransform(opaque.astype(np.uint8), cv2.DIST_L2, 5)
    lab = cv2.cvtColor(np.ascontiguousarray(img[..., :3]), cv2.COLOR_RGB2Lab)
    lum: F32 = np.ascontiguousarray(lab[..., 0] / 100.0, dtype=np.float32)
    mean = cv2.blur(lum, (7, 7))
    contrast = np.sqrt(np.maximum(cv2.blur(np.square(lum), (7, 7)) - mean * mean, 0.0))
    prows = np.flatnonzero((opaque & ~prior).any(axis=1))
    baseline = int(prows[-1]) if prows.size else bottom
    f = np.stack(
        [
            (ys - top) / height,
            np.abs(xs - cx) / widest,
            width[ys] / widest,
            np.log(np.maximum(width[ys], 1.0) / foot),
            dt[ys, xs] / widest,
            lum[ys, xs],
            lab[ys, xs, 1] / 128.0,
            lab[ys, xs, 2] / 128.0,
            contrast[ys, xs],
            prior[ys, xs].astype(np.float64),
            (ys - baseline) / height,
        ],
        axis=1,
    )
    return np.asarray(f, dtype=np.float64)


# The columns of _trunk_features.
_N_FEATURES = 11


def _number_list(data: dict[str, Any], key: str, n: int) -> F64:
    v = data.get(key)
    if not (isinstance(v, list) and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
        raise ValueError(f"data: {key!r} must be a list of numbers")
    if len(v) != n:
        raise ValueError(f"data: {key!r} must hold {n} numbers, got {len(v)}")
    try:
        arr = np.asarray(v, np.float64)
    except OverflowError:  # an integer beyond float64
        arr = np.full(1, np.inf)
    if not np.isfinite(arr).all():
        raise ValueError(f"data: {key!r} must hold finite numbers")
    return arr


def _quadratic(f: F64) -> F64:
    iu = np.triu_indices(f.shape[1])
    return np.hstack([np.ones((len(f), 1)), f, f[:, iu[0]] * f[:, iu[1]]])


def _trunk_from_rows(opaque: Mask, raw: Mask) -> Mask:
    """The trunk as :func:`segment` defines it, from a per-pixel guess: climbing from the bottom,
    the crown baseline is the first row where under half of the opaque pixels are trunk; the
    trunk is the opaque part below it that touches the bottom row."""
    rows = np.flatnonzero(opaque.any(axis=1))
    bottom = int(rows[-1])
    n_op = opaque.sum(axis=1)
    n_tr = (raw & opaque).sum(axis=1)
    y = bottom
    while y >= rows[0] and n_op[y] > 0 and n_tr[y] * 2 >= n_op[y]:
        y -= 1
    out = np.zeros(opaque.shape, np.bool_)
    if y >= bottom:
        return out
    below = opaque.copy()
    below[: y + 1] = False
    _, labels = cv2.connectedComponents(below.astype(np.uint8), connectivity=8)
    keep = np.unique(labels[bottom][below[bottom]])
    return np.ascontiguousarray(np.isin(labels, keep[keep > 0]))


@dataclass(frozen=True)
class TrunkClassifier:
    """A small trunk/crown pixel classifier trained on a few user-labelled exemplars (§4.3).

    The paper fine-tuned an FCN on 55 hand-segmented trees. This is the light-weight
    counterpart: logistic regression on quadratic terms of a dozen per-pixel features
    (position, width profile, thickness, CIELAB colour, local contrast and the training-free
    :func:`segment`'s answer), fitted by Newton's method with a small L2 penalty. Its pixel
    guesses become a trunk the way :func:`segment` defines one: everything below the crown
    baseline that touches the bottom. Train it with :meth:`fit` on a few of your own trees
    when :func:`segment` fails on a library's style, and pass it to :func:`prepare` or
    :class:`Library`.

    Attributes
    ----------
    coef : (d,) float64 ndarray
        Weights of the quadratic features.
    mean, scale : (11,) float64 ndarray
        Feature standardisation.
    alpha_threshold : float
        Alpha at or above this is opaque.
    """

    coef: F64
    mean: F64
    scale: F64
    alpha_threshold: float = 0.5

    @classmethod
    def fit(
        cls,
        images: Sequence[Any],
        trunks: Sequence[Any],
        *,
        samples: int = 20000,
        l2: float = 1e-3,
        seed: Seed = 0,
        alpha_threshold: float = 0.5,
    ) -> TrunkClassifier:
        """Train on normalised exemplars and their trunk masks.

        Parameters
        ----------
        images : sequence of (S, S, 4) ndarray
            Normalised exemplars (see :func:`normalize`).
        trunks : sequence of (S, S) bool ndarray
            Their trunk masks (``True`` on trunk pixels).
        samples : int, optional
            Opaque pixels drawn per image, half trunk and half crown where possible.
        l2 : float, optional
            Ridge penalty on the weights.
        seed : int or numpy.random.Generator, optional
            Seed of the pixel sampling.
        alpha_threshold : float, optional

        Returns
        -------
        TrunkClassifier

        Examples
        --------
        >>> import numpy as np, phloem
        >>> img = np.zeros((100, 100, 4), np.float32); img[20:60, 20:80] = (0.1, 0.6, 0.1, 1.0)
        >>> img[60:100, 45:55] = (0.4, 0.3, 0.1, 1.0)
        >>> truth = np.zeros((100, 100), bool); truth[60:, 45:55] = True
        >>> clf = phloem.trees.TrunkClassifier.fit([img], [truth])
        >>> bool((clf.predict(img) == truth).all())
        True
        """
        imgs = list(images)
        masks = list(trunks)
        if not imgs or len(imgs) != len(masks):
            raise ValueError(f"trunks: expected one trunk mask per image, got {len(masks)} for {len(imgs)} images")
        samples = check_int(samples, "samples", 10)
        l2 = check_float(l2, "l2", 0.0)
        t = check_alpha_threshold(alpha_threshold)
        rng = np.random.default_rng(check_seed(seed))
        xs_, ys_ = [], []
        for i, (im, tm) in enumerate(zip(imgs, masks)):
            img = as_rgba(im, f"images[{i}]")
            opaque = img[..., 3] >= t
            if not opaque.any():
                raise ValueError(f"images[{i}]: every pixel is transparent")
            truth = as_mask(tm, f"trunks[{i}]", opaque.shape)[opaque]
            f = _trunk_features(img, opaque, segment(img, alpha_threshold=t))
            pick = []
            for cls_ in (True, False):
                idx = np.flatnonzero(truth == cls_)
                if idx.size:
                    pick.append(rng.choice(idx, size=min(idx.size, samples // 2), replace=False))
            sel = np.sort(np.concatenate(pick))
            xs_.append(f[sel])
            ys_.append(truth[sel].astype(np.float64))
        x = np.vstack(xs_)
        y = np.concatenate(ys_)
        mean = x.mean(axis=0)
        scale = x.std(axis=0)
        scale[scale < 1e-9] = 1.0
        q = _quadratic((x - mean) / scale)
        coef = np.zeros(q.shape[1])
        reg = l2 * len(y) * np.eye(q.shape[1])
        reg[0, 0] = 0.0
        for _ in range(30):
            p = 1.0 / (1.0 + np.exp(-np.clip(q @ coef, -30, 30)))
            grad = q.T @ (p - y) + reg @ coef
            hess = (q * (p * (1 - p))[:, None]).T @ q + reg + 1e-9 * np.eye(q.shape[1])
            step = np.linalg.solve(hess, grad)
            coef -= step
            if float(np.abs(step).max()) < 1e-6:
                break
        return cls(coef=coef, mean=mean, scale=scale, alpha_threshold=t)

    def probability(self, rgba: Any) -> F32:
        """Per-pixel trunk probability (0 on transparent pixels)."""
        img = as_rgba(rgba)
        opaque = img[..., 3] >= self.alpha_threshold
        out = np.zeros(opaque.shape, np.float32)
        if not opaque.any():
            return out
        f = _trunk_features(img, opaque, segment(img, alpha_threshold=self.alpha_threshold))
        z = _quadratic((f - self.mean) / self.scale) @ self.coef
        out[opaque] = 1.0 / (1.0 + np.exp(-np.clip(z, -30, 30)))
        return out

    def predict(self, rgba: Any) -> Mask:
        """The trunk mask of a normalised exemplar, as :func:`segment` returns one."""
        img = as_rgba(rgba)
        opaque = img[..., 3] >= self.alpha_threshold
        if not opaque.any():
            return np.zeros(opaque.shape, np.bool_)
        return _trunk_from_rows(opaque, self.probability(img) >= 0.5)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready parameters (see :meth:`from_dict`)."""
        return {
            "format": "phloem.trees.TrunkClassifier",
            "version": 1,
            "coef": self.coef.tolist(),
            "mean": self.mean.tolist(),
            "scale": self.scale.tolist(),
            "alpha_threshold": self.alpha_threshold,
        }

    @classmethod
    def from_dict(cls, data: Any) -> TrunkClassifier:
        """Rebuild a classifier saved with :meth:`to_dict`; malformed data gives a one-line error."""
        if not isinstance(data, dict) or data.get("format") != "phloem.trees.TrunkClassifier":
            raise ValueError("data: not a phloem.trees.TrunkClassifier record (its 'format' must say so)")
        if data.get("version", 1) != 1:
            raise ValueError(f"data: unsupported TrunkClassifier version {data.get('version')!r} (this phloem reads 1)")
        d = _N_FEATURES
        sizes = {"coef": 1 + d + d * (d + 1) // 2, "mean": d, "scale": d}
        arrays = {key: _number_list(data, key, n) for key, n in sizes.items()}
        if not (arrays["scale"] > 0).all():
            raise ValueError("data: 'scale' must hold positive numbers")
        t = data.get("alpha_threshold")
        if not (isinstance(t, (int, float)) and not isinstance(t, bool) and 0.0 < t <= 1.0):
            raise ValueError(f"data: 'alpha_threshold' must be a number in (0, 1], got {t!r:.40}")
        return cls(coef=arrays["coef"], mean=arrays["mean"], scale=arrays["scale"], alpha_threshold=float(t))
