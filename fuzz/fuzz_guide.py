"""Fuzz target: the guide points JSON of ``phloem branching ... --guide PTS.json``, read by the CLI's own ``_guide``.

Expected: ``ValueError`` (the CLI turns it into its one-line error), except ``UnicodeDecodeError``,
whose message is the codec's and names no file. ``TypeError`` and everything else are crashes:
they are numpy's words or a traceback. A result must be an (n >= 2, 2) float64 array.
"""

from __future__ import annotations

import argparse

import numpy as np
from _common import fuzz, instrumented, target, temp_file

with instrumented():
    from phloem.cli.branching import _guide

_ARGS = argparse.Namespace(max_pixels=4096)


@target
def TestOneInput(data: bytes) -> None:
    try:
        pts = _guide(str(temp_file(data, ".json")), _ARGS)
    except UnicodeDecodeError:
        raise
    except ValueError:
        return
    assert isinstance(pts, np.ndarray) and pts.dtype == np.float64, type(pts)
    assert pts.ndim == 2 and pts.shape[1] == 2 and len(pts) >= 2, pts.shape


if __name__ == "__main__":
    fuzz(TestOneInput)
