"""The fragment map of a rendered branching image, as the CLI and the studio draw it."""

from __future__ import annotations

import numpy as np


def fragment_map(labels: np.ndarray) -> np.ndarray:
    """The ``--fragment-map`` image: each fragment's pixels in a colour of its own, black where
    no fragment painted (``labels`` -1); the studio's render job writes the same."""
    rng = np.random.default_rng(0)
    colours = rng.uniform(0.25, 1.0, (int(labels.max()) + 2, 3)).astype(np.float32)
    colours[0] = 0.0
    out: np.ndarray = colours[labels + 1]
    return out
