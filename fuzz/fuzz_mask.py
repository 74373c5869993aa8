"""Fuzz target: mask decoding, from a mask image file (``phloem complete IN MASK``) and from raw arrays.

The first byte picks the path:

- 0: the bytes are a mask file, read as ``cli/texture.py``'s ``complete`` reads it (``read_image``,
  alpha or the colour channels' maximum, the 0.5 threshold) and checked with ``_validate.as_mask``;
- 1: the bytes are an array of a chosen dtype and shape, given to ``as_mask`` (what
  ``texture.complete(image, mask)`` and the other mask-taking functions call);
- 2: the same arrays given to ``bark.decode_labels`` (``_validate.as_image``'s checks).

Expected: ``ValueError`` other than ``UnicodeDecodeError``, and ``TypeError`` for arrays
(documented for a dtype that is not a mask or image). Results must be bool masks / int32 labels of the shape asked.
"""

from __future__ import annotations

import numpy as np
from _common import fuzz, instrumented, target, temp_file

with instrumented():
    from phloem import bark, io
    from phloem._validate import as_mask
    from phloem.cli.texture import hole_from_mask

MAX_PIXELS = 4096
DTYPES = [np.bool_, np.uint8, np.uint16, np.int8, np.int32, np.int64, np.float16, np.float32, np.float64, np.complex64]


def _mask_file(data: bytes, alpha: bool) -> None:
    try:
        m = io.read_image(temp_file(data, ".png"), max_pixels=MAX_PIXELS)
    except UnicodeDecodeError:
        raise
    except ValueError:
        return
    try:
        hole = hole_from_mask(m, "mask.png", alpha=alpha, invert=False)
    except ValueError:
        return
    out = as_mask(hole, "mask", hole.shape)
    assert out.dtype == np.bool_ and out.shape == m.shape[:2]


def _array(data: bytes) -> tuple[np.ndarray, tuple[int, int]]:
    if len(data) < 4:
        raise EOFError
    dtype = np.dtype(DTYPES[data[0] % len(DTYPES)])
    h, w, c = 1 + data[1] % 16, 1 + data[2] % 16, data[3] % 5  # c == 0: a 2-D array
    shape = (h, w) if c == 0 else (h, w, c)
    count = int(np.prod(shape))
    raw = data[4 : 4 + count * dtype.itemsize].ljust(count * dtype.itemsize, b"\0")
    return np.frombuffer(raw, dtype).reshape(shape), (h, w)


def _raw(data: bytes, labels: bool) -> None:
    try:
        arr, hw = _array(data)
    except EOFError:
        return
    try:
        out = bark.decode_labels(arr) if labels else as_mask(arr, "mask", hw)
    except UnicodeDecodeError:
        raise
    except (ValueError, TypeError):
        return
    if labels:
        assert out.dtype == np.int32 and out.shape == hw, (out.dtype, out.shape)
    else:
        assert out.dtype == np.bool_ and out.shape == hw, (out.dtype, out.shape)


@target
def TestOneInput(data: bytes) -> None:
    if not data:
        return
    mode, rest = data[0] % 4, data[1:]
    if mode in (0, 3):
        _mask_file(rest, alpha=mode == 3)
    else:
        _raw(rest, labels=mode == 2)


if __name__ == "__main__":
    fuzz(TestOneInput)
