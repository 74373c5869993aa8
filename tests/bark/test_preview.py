"""phloem.bark.preview: the texture wrapped round a lit trunk."""

from __future__ import annotations

import numpy as np

from phloem import bark


def test_cylinder_preview_geometry():
    h, w = 8, 64
    tex = np.tile(np.arange(w, dtype=np.float32)[None, :, None] / w, (h, 1, 3))
    prev = bark.cylinder_preview(tex, light=(0.0, 0.0, 1.0), ambient=0.0)
    radius = w / (2 * np.pi)
    assert prev.shape == (h, round(2 * radius) + 2, 3)
    xs = (np.arange(prev.shape[1]) + 0.5 - prev.shape[1] / 2) / radius
    inside = np.abs(xs) < 1
    assert (prev[:, ~inside] == 0).all()
    # head-on light, no ambient: brightness = texture column at u(θ) times cos θ
    theta = np.arcsin(xs[inside])
    u = (theta / (2 * np.pi) + 0.25) * w - 0.5
    np.testing.assert_allclose(prev[0, inside, 0], u / w * np.cos(theta), atol=1e-5)
