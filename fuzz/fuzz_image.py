"""Fuzz target: image headers and decoding, :func:`phloem.io.read_image` on arbitrary bytes with a small pixel limit.

Expected: ``ValueError`` (``ImageReadError`` included) other than ``UnicodeDecodeError``.
Everything else is a crash (``cv2.error``, Pillow's and tifffile's own exceptions, ``MemoryError``
from a tiny file, a hang). An image that is read must be float32, (H, W) or (H, W, C) with
C in 1..4, within the pixel limit, finite and in [0, 1].
"""

from __future__ import annotations

import warnings

import numpy as np
from _common import fuzz, instrumented, target, temp_file

with instrumented():
    import tifffile  # noqa: F401 (io imports it lazily; imported here so that it is instrumented too)

    from phloem import io

MAX_PIXELS = 4096


@target
def TestOneInput(data: bytes) -> None:
    warnings.simplefilter("ignore", io.RescaledImageWarning)  # documented: a float image outside [0, 1]
    try:
        img = io.read_image(temp_file(data, ".png"), max_pixels=MAX_PIXELS)
    except UnicodeDecodeError:
        raise
    except ValueError:
        return
    assert isinstance(img, np.ndarray) and img.dtype == np.float32, type(img)
    assert img.ndim in (2, 3) and (img.ndim == 2 or 1 <= img.shape[2] <= 4), img.shape
    assert 0 < img.shape[0] * img.shape[1] <= MAX_PIXELS, img.shape
    assert np.isfinite(img).all() and img.min() >= 0 and img.max() <= 1, (img.min(), img.max())


if __name__ == "__main__":
    fuzz(TestOneInput)
