"""One exemplar from RGBA image to :class:`Tree`: the preprocessing of Argudo et al. 2017 §4 and its output (§4.7)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .._validate import as_mask, check_int
from ._checks import F32, F64, Mask, as_rgba
from ._outline import dilated_outline, simplify_outline
from .atlas import normalize
from .classifier import TrunkClassifier
from .contour_space import fill_contour
from .contours import contour, pin_points, resample
from .segmentation import segment

__all__ = ["Tree", "prepare"]


@dataclass(frozen=True)
class Tree:
    """One preprocessed exemplar (paper §4.7).

    Attributes
    ----------
    image : (S, S, 4) float32 ndarray
        The normalised RGBA image.
    trunk : (S, S) bool ndarray
        The trunk mask.
    contour : (K, 2) float64 ndarray
        The longest exterior contour ``C``, counter-clockwise.
    pins : (b, l, r)
        Pin point indices into ``contour``.
    resampled : (N, 2) float64 ndarray
        ``C_r``: crown, left trunk side, right trunk side (see :func:`resample`).
    simplified : (M, 2) float64 ndarray
        ``C_s``: the dilated, simplified contour for mean value coordinates.
    split : (int, int, int)
        Points of ``resampled`` on the crown and the two trunk sides.
    outline : (L, 2) float64 ndarray
        The dilated outline of the interior of ``resampled`` that ``simplified`` samples and
        that :func:`cages` matches against (about one point per pixel).
    dilation : int
        The dilation ``outline`` and ``simplified`` were made with.
    """

    image: F32
    trunk: Mask
    contour: F64
    pins: tuple[int, int, int]
    resampled: F64
    simplified: F64
    split: tuple[int, int, int]
    outline: F64
    dilation: int = 8

    @property
    def vector(self) -> F64:
        """``u``: the mean-subtracted ``(x, y)`` of ``resampled``, flattened to length 2N (§3)."""
        centred: F64 = self.resampled - self.resampled.mean(axis=0)
        return centred.ravel()


def prepare(
    rgba: Any,
    *,
    trunk: Any = None,
    classifier: TrunkClassifier | None = None,
    size: int = 1024,
    alpha_threshold: float = 0.5,
    split: tuple[int, int, int] = (1600, 200, 200),
    m: int = 100,
    dilation: int = 8,
    normalized: bool = False,
) -> Tree:
    """Preprocess one exemplar: normalise, segment, contour, pins, resample, simplify (§4).

    Parameters
    ----------
    rgba : (M, N, 4) ndarray
        The exemplar.
    trunk : (S, S) bool ndarray, optional
        A trunk mask for the *normalised* image, e.g. drawn by hand; :func:`segment` otherwise.
    classifier : TrunkClassifier, optional
        Segment with this trained classifier instead of :func:`segment` (ignored with ``trunk``).
    size, alpha_threshold : optional
        See :func:`normalize`.
    split : optional
        See :func:`resample`.
    m, dilation : optional
        See :func:`simplify`.
    normalized : bool, optional
        ``rgba`` is already the output of :func:`normalize`; use it as it is.

    Returns
    -------
    Tree

    Examples
    --------
    >>> import numpy as np, phloem
    >>> img = np.zeros((120, 80, 4), np.float32)
    >>> img[10:70, 10:70] = 1.0; img[70:110, 35:45] = 1.0
    >>> tree = phloem.trees.prepare(img, size=128, split=(160, 20, 20), m=30)
    >>> tree.image.shape, tree.resampled.shape, tree.simplified.shape, tree.vector.shape
    ((128, 128, 4), (200, 2), (30, 2), (400,))
    """
    img = as_rgba(rgba) if normalized else normalize(rgba, size=size, alpha_threshold=alpha_threshold)
    if trunk is None and classifier is not None:
        tm = classifier.predict(img)
    elif trunk is None:
        tm = segment(img, alpha_threshold=alpha_threshold)
    else:
        tm = as_mask(trunk, "trunk", img.shape[:2])
    c = contour(img[..., 3], alpha_threshold=alpha_threshold)
    pins = pin_points(c, tm)
    cr = resample(c, pins, split=split)
    # The dilated outline once: C_s samples it here, and cages() matches against it later.
    dilation = check_int(dilation, "dilation", 0)
    outline = dilated_outline(fill_contour(cr, img.shape[:2]), dilation)
    cs = simplify_outline(outline, check_int(m, "m", 3))
    counts = (int(split[0]), int(split[1]), int(split[2]))
    return Tree(
        image=img,
        trunk=tm,
        contour=c,
        pins=pins,
        resampled=cr,
        simplified=cs,
        split=counts,
        outline=outline,
        dilation=dilation,
    )
