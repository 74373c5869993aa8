"""Small example images embedded in the package (all CC0), like ``skimage.data``.

============  ===============================================  =====================================
function      content                                          source and licence
============  ===============================================  =====================================
``bark``      Douglas-fir bark, 256×256 RGBA (opaque)          VisiTrees ``assets/PSME_bark.png``, CC0
``brick``     brick wall, 512×512 gray                         scikit-image ``data/brick.png``, CC0
============  ===============================================  =====================================
"""

from __future__ import annotations

from importlib.resources import as_file, files

import numpy as np
from numpy.typing import NDArray

__all__ = ["bark", "brick", "path"]


def path(name: str) -> str:
    """Filesystem path of an embedded file, e.g. ``path("bark_douglas_fir.png")``."""
    res = files(__package__ or "phloem") / "data" / name
    if not res.is_file():
        raise ValueError(f"name: no embedded file {name!r}")
    with as_file(res) as p:
        return str(p)


def _read(name: str) -> NDArray[np.float32]:
    from .io import read_image

    return read_image(path(name))


def bark() -> NDArray[np.float32]:
    """Douglas-fir bark, ``(256, 256, 4)`` float32 RGBA in [0, 1], fully opaque (CC0)."""
    return _read("bark_douglas_fir.png")


def brick() -> NDArray[np.float32]:
    """A brick wall, ``(512, 512)`` float32 gray in [0, 1] (CC0)."""
    return _read("brick.png")
