"""Displacement fields on the shared canvas: the one sampler every leaves stage uses.

A field is ``(H, W, 2)`` float32 ``(dx, dy)``; ``sample(image, field)(row, col) = image(row + dy,
col + dx)``, bilinear, 0 (transparent) outside the image. The work is done by the Rust core's
``tps_sample`` (the sampler of :mod:`phloem.warp`, parallel, GIL released), so every stage
resamples the same way and 1 thread gives the same bits as 2.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import _core
from .._validate import as_image, check_threads, restore_ndim

__all__ = ["as_field", "sample", "sample_checked"]


def as_field(field: Any, name: str, shape: tuple[int, int] | None = None) -> NDArray[np.float32]:
    """Return ``field`` as a finite C-contiguous ``(H, W, 2)`` float32 array (of size ``shape``)."""
    f = as_image(field, name)
    if f.shape[2] != 2:
        raise ValueError(f"{name}: expected a displacement field of shape (H, W, 2), got {np.shape(field)}")
    if shape is not None and f.shape[:2] != tuple(shape):
        raise ValueError(f"{name}: expected a field of size {tuple(shape)}, got {f.shape[:2]}")
    return f


def sample(image: Any, field: Any, *, threads: int | None = None) -> NDArray[np.float32]:
    """Resample ``image`` by the displacement ``field`` (bilinear, 0 outside).

    Parameters
    ----------
    image : (H, W) or (H, W, C) array_like
        Any number of channels; uint8/uint16 are scaled to [0, 1].
    field : (H, W, 2) array_like of float
        ``(dx, dy)`` per output pixel: output ``(row, col)`` reads ``image(row + dy, col + dx)``.
    threads : int, optional
        Worker threads (default: the core's pool); the result does not depend on it.

    Returns
    -------
    (H, W) or (H, W, C) ndarray of float32
        The same number of dimensions as ``image``.
    """
    img = as_image(image, "image")
    f = as_field(field, "field", img.shape[:2])
    return restore_ndim(sample_checked(img, f, check_threads(threads)), image)


def sample_checked(image: NDArray[np.float32], field: NDArray[np.float32], threads: int | None) -> NDArray[np.float32]:
    """:func:`sample` for arrays already checked: C-contiguous float32 ``(H, W, C)`` and
    ``(H, W, 2)`` (a stage's own intermediates; skips the copies and finiteness scans)."""
    return np.asarray(_core.tps_sample(image, field, threads=threads), dtype=np.float32)
