"""Argument checks shared by every public function.

Each check raises ``ValueError`` (or ``TypeError`` for a wrong kind of object) whose message
starts with the parameter's name, so a user knows which argument to fix.
"""

from __future__ import annotations

import hashlib
import math
import numbers
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "as_image",
    "as_labels",
    "as_mask",
    "check_float",
    "check_patch_size",
    "check_seed",
    "check_size",
    "check_threads",
    "derive_seed",
    "restore_ndim",
]


def _array(value: Any, name: str) -> NDArray[Any]:
    """``np.asarray(value)``, with numpy's own errors (ragged nesting, odd objects) as ours."""
    try:
        return np.asarray(value)
    except (ValueError, TypeError, OverflowError):
        raise TypeError(f"{name}: expected an array of numbers, got a ragged or mixed {type(value).__name__}") from None


def as_image(image: Any, name: str, *, finite: bool = True) -> NDArray[np.float32]:
    """Return ``image`` as a C-contiguous ``(H, W, C)`` float32 array.

    uint8 and uint16 are scaled to [0, 1] (by 255 and 65535), other integer dtypes refused;
    float inputs keep their values. Rejects booleans, complex numbers, the wrong number of
    dimensions, empty axes and (unless ``finite=False``, for callees that check while they
    read the values anyway) non-finite values.
    """
    arr = _array(image, name)
    if arr.dtype == np.bool_ or not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise TypeError(f"{name}: expected a real-valued image array, got dtype {arr.dtype}")
    if np.issubdtype(arr.dtype, np.integer) and arr.dtype not in (np.uint8, np.uint16):
        raise TypeError(f"{name}: expected dtype uint8, uint16 or float, got {arr.dtype}")
    if arr.ndim not in (2, 3):
        raise ValueError(f"{name}: expected shape (H, W) or (H, W, C), got {arr.shape}")
    if 0 in arr.shape:
        raise ValueError(f"{name}: expected a non-empty image, got shape {arr.shape}")
    if arr.ndim == 2:
        arr = arr[:, :, None]
    if np.issubdtype(arr.dtype, np.integer):
        info = np.iinfo(arr.dtype)
        out = arr.astype(np.float32) / np.float32(info.max)
    else:
        with np.errstate(over="ignore"):  # float64 beyond float32 becomes inf, refused below in our words
            out = np.ascontiguousarray(arr, dtype=np.float32)
        bad = ~np.isfinite(out) if finite else np.zeros((), bool)
        if bad.any():
            y, x, c = np.argwhere(bad)[0]
            raise ValueError(f"{name}: expected finite values, found {arr[y, x, c]} at (row {y}, col {x}, channel {c})")
    return np.ascontiguousarray(out)


def restore_ndim(out: NDArray[np.float32], like: Any) -> NDArray[np.float32]:
    """Drop the channel axis again if the user passed a 2-D image."""
    return out[:, :, 0] if np.ndim(like) == 2 else out


def as_labels(labels: Any, name: str) -> NDArray[np.int32]:
    """Return ``labels`` as a C-contiguous ``(H, W)`` int32 label map."""
    arr = _array(labels, name)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[:, :, 0]
    if arr.ndim != 2:
        raise ValueError(f"{name}: expected an (H, W) label map, got shape {arr.shape}")
    if 0 in arr.shape:
        raise ValueError(f"{name}: expected a non-empty label map, got shape {arr.shape}")
    if arr.dtype == np.bool_:
        arr = arr.astype(np.int32)
    if not np.issubdtype(arr.dtype, np.integer):
        raise TypeError(f"{name}: expected an integer label map, got dtype {arr.dtype}")
    if arr.min() < np.iinfo(np.int32).min or arr.max() > np.iinfo(np.int32).max:
        raise ValueError(f"{name}: label values must fit in int32")
    return np.ascontiguousarray(arr, dtype=np.int32)


def as_mask(mask: Any, name: str, shape: tuple[int, int]) -> NDArray[np.bool_]:
    """Return ``mask`` as a C-contiguous ``(H, W)`` bool array of the given shape.

    Accepts bool arrays and integer or float arrays of 0 and 1 (any non-zero counts as set).
    A trailing channel axis of length 1 is dropped.
    """
    arr = _array(mask, name)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[:, :, 0]
    if arr.ndim != 2:
        raise ValueError(f"{name}: expected a 2-D mask of shape {shape}, got shape {arr.shape}")
    if arr.shape != tuple(shape):
        raise ValueError(f"{name}: expected shape {tuple(shape)} to match the image, got {arr.shape}")
    if arr.dtype != np.bool_:
        if not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
            raise TypeError(f"{name}: expected a boolean mask, got dtype {arr.dtype}")
        if np.issubdtype(arr.dtype, np.floating) and not np.isfinite(arr).all():
            raise ValueError(f"{name}: expected finite values in the mask")
        arr = arr != 0
    return np.ascontiguousarray(arr)


def check_patch_size(patch_size: Any, name: str = "patch_size") -> int:
    """Return ``patch_size`` as an int, checking it is odd and at least 1."""
    if isinstance(patch_size, bool) or not isinstance(patch_size, numbers.Integral):
        raise TypeError(f"{name}: expected an odd integer, got {patch_size!r}")
    p = int(patch_size)
    if p < 1 or p % 2 == 0:
        raise ValueError(f"{name}: expected an odd size >= 1, got {p}")
    return p


def check_int(value: Any, name: str, minimum: int) -> int:
    """Return ``value`` as an int, checking it is at least ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name}: expected an integer, got {value!r}")
    if int(value) < minimum:
        raise ValueError(f"{name}: expected an integer >= {minimum}, got {value}")
    return int(value)


def check_float(value: Any, name: str, minimum: float, *, inclusive: bool = True) -> float:
    """Return ``value`` as a finite float, checking it is at least (or above) ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name}: expected a number, got {value!r}")
    v = float(value)
    if not np.isfinite(v) or v < minimum or (not inclusive and v == minimum):
        bound = "" if minimum == -math.inf else f" {'>=' if inclusive else '>'} {minimum}"
        raise ValueError(f"{name}: expected a finite value{bound}, got {value}")
    return v


def check_seed(seed: Any) -> int:
    """Return a u64 seed from an int ``>= 0`` or a ``numpy.random.Generator``.

    Seeds below ``2**64`` are kept as they are; larger ones are mapped into that range by a
    stable hash. Derived seeds of later stages go through :func:`derive_seed`, which wraps.
    """
    if isinstance(seed, np.random.Generator):
        return int(seed.integers(0, 2**63))
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise TypeError(f"seed: expected an integer or a numpy.random.Generator, got {seed!r}")
    s = int(seed)
    if s < 0:
        raise ValueError(f"seed: expected an integer >= 0, got {s}")
    if s < 2**64:
        return s
    digest = hashlib.blake2b(s.to_bytes((s.bit_length() + 7) // 8, "little"), digest_size=8).digest()
    return int.from_bytes(digest, "little")


def derive_seed(seed: int, k: int) -> int:
    """Return the seed of stage ``k`` from a checked seed, ``seed + 7919 * k`` wrapped to u64."""
    return (seed + 7919 * k) % 2**64


def check_threads(threads: Any) -> int | None:
    """Return ``threads`` (None or a positive int)."""
    return None if threads is None else check_int(threads, "threads", 1)


def check_size(size: Any, name: str = "size") -> tuple[int, int]:
    """Return ``size`` as ``(height, width)``; an int means a square."""
    if isinstance(size, numbers.Integral) and not isinstance(size, bool):
        size = (int(size), int(size))
    try:
        h, w = size
    except (TypeError, ValueError):
        raise TypeError(f"{name}: expected (height, width) or an int, got {size!r}") from None
    return check_int(h, f"{name}[0] (height)", 1), check_int(w, f"{name}[1] (width)", 1)


def check_convex_weights(weights: Any, count: int, name: str = "weights") -> NDArray[np.float64]:
    """``count`` real, finite, non-negative weights summing to 1 (within 1e-6), as float64."""
    arr = _array(weights, name)
    if arr.dtype == np.bool_ or not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise TypeError(f"{name}: expected real numbers, got dtype {arr.dtype}")
    if arr.shape != (count,):
        raise ValueError(f"{name}: expected {count} weights, one per source, got shape {arr.shape}")
    out = np.ascontiguousarray(arr, dtype=np.float64)
    if not (np.isfinite(out).all() and (out >= 0).all()):
        raise ValueError(f"{name}: expected finite non-negative weights, got {out.tolist()}")
    if abs(float(out.sum()) - 1.0) > 1e-6:
        raise ValueError(f"{name}: expected weights summing to 1, got sum {float(out.sum()):.6g}")
    return out
