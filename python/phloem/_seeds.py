"""Seeds of the outputs of a multi-output run, shared by the CLI, the studio and batches."""

from __future__ import annotations

import numpy as np


def sub_seed(seed: int, i: int) -> int:
    """The seed of output ``i`` of a run with ``--seed seed``, recorded in its sidecar, so that the
    output can be remade alone by the Python call the CLI makes for it (``count=1, seed=`` it)."""
    return int(np.random.SeedSequence([seed, i]).generate_state(1)[0])
