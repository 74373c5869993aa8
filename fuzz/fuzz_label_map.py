"""Fuzz target: a label map PNG (``phloem bark --labels-in/--labels-out``) decoded from arbitrary bytes.

The CLI reads the file with :func:`phloem.io.read_image` and decodes it with
:func:`phloem.bark.decode_labels`; this target does the same with a small pixel limit. Expected:
``ValueError`` (``ImageReadError`` included) other than ``UnicodeDecodeError``. A decoded map must
be int32 labels ``0 … n-1`` (n ≤ 16) of the image's size that survive ``encode_labels`` →
``decode_labels``.
"""

from __future__ import annotations

import numpy as np
from _common import fuzz, instrumented, target, temp_file

with instrumented():
    from phloem import bark, io

MAX_PIXELS = 4096


@target
def TestOneInput(data: bytes) -> None:
    try:
        img = io.read_image(temp_file(data, ".png"), max_pixels=MAX_PIXELS)
        labels = bark.decode_labels(img)
    except UnicodeDecodeError:
        raise
    except ValueError:
        return
    assert labels.dtype == np.int32 and labels.shape == img.shape[:2], (labels.dtype, labels.shape)
    n = int(labels.max()) + 1
    assert n <= 16 and labels.min() == 0 and len(np.unique(labels)) == n, "labels are not 0 … n-1"
    assert np.array_equal(bark.decode_labels(bark.encode_labels(labels)), labels), "encode/decode round trip"


if __name__ == "__main__":
    fuzz(TestOneInput)
