"""The output label map (thesis §3.6): the shape engine with the bark pipeline's defaults."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from .. import shapes
from .._api import Seed, Size
from .._progress import Progress
from ..shapes import Rotations

__all__ = ["synthesize_labels"]


def synthesize_labels(
    labels: Any,
    size: Size,
    *,
    method: Literal["layered", "joint"] = "joint",
    order: Sequence[int] | None = None,
    rotations: Rotations = "half",
    tileable: bool = False,
    seed: Seed = 0,
    threads: int | None = None,
    progress: Progress = None,
    max_memory: int | None = None,
    **options: Any,
) -> NDArray[np.int32]:
    """A new label map of any size with the shapes of ``labels`` (thesis §3.6).

    The bark-pipeline name of :func:`phloem.shapes.synthesize_labels` (Rosenberger et al. 2009
    boundary-patch shape synthesis) with the bark pipeline's defaults: the joint method, and only
    half turns of the photo's shapes (bark grows along the trunk). See there for ``method``,
    ``order``, ``rotations``, ``max_memory`` and ``options`` (``patch_size``, ``levels``, ``iterations``).

    Examples
    --------
    >>> import numpy as np, phloem
    >>> lab = phloem.bark.input_labels(phloem.data.bark(), 2)
    >>> new = phloem.bark.synthesize_labels(lab, (96, 128), seed=1)
    >>> new.shape, sorted(np.unique(new).tolist())
    ((96, 128), [0, 1])
    """
    return shapes.synthesize_labels(
        labels, size, method=method, order=order, rotations=rotations, tileable=tileable, seed=seed, threads=threads,
        progress=progress, max_memory=max_memory, **options,
    )  # fmt: skip
