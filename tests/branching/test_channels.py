"""Any channel count through every branching step (issue 16: 5 channels failed with a cv2.error,
OpenCV's INTER_AREA resize takes at most 4; a 2-D input came back as (H, W, 1))."""

from __future__ import annotations

import numpy as np
import pytest

from phloem import branching
from phloem.branching import Branch, Skeleton


def _scene(c: int) -> tuple[np.ndarray, Skeleton]:
    # Thick (radius 10) so that the gap completion's border matching runs on a coarsened grid
    # (the resize that failed) and the fragments' displacement fields are upsampled.
    sk = Skeleton([Branch([[8, 60], [80, 50], [150, 64]], 10.0), Branch([[80, 50], [100, 8]], 8.0, parent=(0, 1))])
    sk = Skeleton(sk.branches, (120, 160))
    rng = np.random.default_rng(0)
    base = np.where(sk.mask(), 0.2, 0.75) + 0.03 * rng.normal(size=(120, 160))
    # Channel i is the base image shifted by 0.02 i, so a channel mixed up with another shows.
    img = np.clip(base[..., None] + 0.02 * np.arange(c), 0, 1).astype(np.float32)
    return img, sk


@pytest.mark.parametrize("c", [1, 2, 4, 5, 7])
def test_every_step_takes_any_channel_count(c):
    img, sk = _scene(c)
    tgt = Skeleton([Branch([[10, 20], [150, 100]], 10.0)], (110, 170))
    out = branching.render(img, sk, tgt, seed=0)
    assert out.shape == (110, 170, c) and np.isfinite(out).all()
    # Each output channel keeps its own level: means 0.02 apart, in order.
    step = np.diff(out.reshape(-1, c).mean(axis=0))
    np.testing.assert_allclose(step, 0.02, atol=0.01)
    res = branching.synthesize(img, sk, seed=0, size=(96, 128))
    assert res.image.shape == (96, 128, c)
    np.testing.assert_allclose(np.diff(res.image.reshape(-1, c).mean(axis=0)), 0.02, atol=0.01)
    assert branching.trace(img, kind="dark").branches
    hm = np.array([[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0005, 1.0]])
    rect, rsk, hs, _valid = branching.rectify(img, sk, hm)
    assert rect.shape[2] == c and rsk.shape == rect.shape[:2]
    back = branching.unrectify(rect, hs, (120, 160))
    assert back.shape == (120, 160, c)
    np.testing.assert_allclose(np.diff(back[40:80, 40:120].reshape(-1, c).mean(axis=0)), 0.02, atol=0.005)


def test_a_2d_image_gives_a_2d_result():
    img, sk = _scene(1)
    gray = img[..., 0]
    out = branching.render(gray, sk, sk, seed=0)
    assert out.shape == (120, 160)
    np.testing.assert_array_equal(out, branching.render(img, sk, sk, seed=0)[..., 0])
    res = branching.render(gray, sk, sk, seed=0, full_output=True)
    assert res.image.shape == res.structure.shape == (120, 160)
    assert branching.synthesize(gray, sk, seed=0).image.shape == (120, 160)


@pytest.mark.parametrize("c", [1, 3, 5])
def test_paste_writes_through_a_view_in_every_channel(c):
    from phloem.branching._pixels import _paste

    rng = np.random.default_rng(c)
    canvas = rng.random((40, 50, c), dtype=np.float32)
    src = rng.random((30, 60, c), dtype=np.float32)[::2, 10:40]  # a strided source
    mask = rng.random((30, 30)) > 0.5
    mask = mask[::2]  # and a strided mask
    want = canvas.copy()
    want[5:20, 12:42][mask] = src[mask]
    _paste(canvas[5:20, 12:42], src, mask)
    assert np.array_equal(canvas, want)
