"""The gaps between the branches (Sibbing et al. 2010, §5.4): the gradient-domain paste against the structure."""

from __future__ import annotations

import cv2
import numpy as np

from phloem.branching.gaps import _match_borders


def _texture(shape: tuple[int, int], seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (0.5 + 0.1 * cv2.GaussianBlur(rng.normal(size=shape).astype(np.float32), (0, 0), 2.0) / 0.15)[..., None]


def test_match_borders_removes_a_lighting_step_and_keeps_the_gaps_gradients() -> None:
    # Structure on the left, 0.1 brighter than the completion that continues its texture on
    # the right: the Poisson solution with the step as Dirichlet data on one side and free
    # borders elsewhere is the texture plus the constant 0.1.
    tex = _texture((80, 90), 0)
    hole = np.zeros((80, 90), bool)
    hole[:, 20:] = True
    canvas = np.where(hole[..., None], tex, tex + 0.1).astype(np.float32)
    out = _match_borders(canvas, hole, np.float32([-1.0]), np.float32([2.0]), radius=10.0, threads=1)
    assert np.array_equal(out[~hole], canvas[~hole])
    corr = (out - canvas)[..., 0][hole]
    assert abs(float(corr.mean()) - 0.1) < 0.005 and float(np.abs(corr - 0.1).max()) < 0.01


def test_match_borders_leaves_content_steps_alone() -> None:
    # A white branch cut off at the structure's edge (rows 35-44) is content, not lighting:
    # away from it the dark completion must not be brightened. A border that is all large
    # steps (a white structure) gets no correction at all.
    hole = np.zeros((80, 90), bool)
    hole[:, 20:] = True
    canvas = np.zeros((80, 90, 1), np.float32)
    canvas[35:45, :20] = 1.0
    lo, hi = np.float32([0.0]), np.float32([1.0])
    out = _match_borders(canvas, hole, lo, hi, radius=10.0, threads=1)
    far = hole.copy()
    far[25:55, :40] = False
    assert float(np.abs(out[far]).max()) < 0.02
    white = np.where(hole[..., None], 0.0, 1.0).astype(np.float32)
    assert np.array_equal(_match_borders(white, hole, lo, hi, radius=10.0, threads=1), white)
