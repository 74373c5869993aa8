"""Exact Euclidean distance transforms that give the same result on every call."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

#: Up to this distance (px) OpenCV's float32 result is within 0.5 of the true squared distance,
#: so the nearest integer recovers it; beyond, SciPy's transform is used.
EXACT_UP_TO = 1024.0


def euclidean_distance(inside: NDArray[np.bool_]) -> NDArray[np.float32]:
    """Distance (px) from every pixel of ``inside`` to the nearest pixel that is not, 0 outside;
    very large (OpenCV's sentinel) everywhere when no pixel is outside.

    OpenCV's ``DIST_MASK_PRECISE`` transform is exact but, in OpenCV 5.1, its float32 result
    can differ from one call to the next by about 1e-5 px, so a trace that compares radii could
    change between runs. The true distance is the square root of an integer (the squared
    distance between two pixel centres), so the squared result is rounded to the nearest
    integer, which removes the noise. About 5x faster than ``scipy.ndimage.distance_transform_edt``,
    which is used where a distance exceeds :data:`EXACT_UP_TO`.
    """
    mask = np.asarray(inside, bool)
    d = cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    if mask.all():  # nothing outside: keep OpenCV's sentinel
        return np.asarray(d, np.float32)
    if float(d.max()) > EXACT_UP_TO:
        from scipy import ndimage  # type: ignore[import-untyped]

        return np.asarray(ndimage.distance_transform_edt(mask), np.float32)
    return np.sqrt(np.rint(np.square(d.astype(np.float64)))).astype(np.float32)
