"""phloem.bark.pipeline: the whole bark pipeline end to end, resumable from its own maps."""

from __future__ import annotations

import numpy as np
import pytest

import phloem
from phloem import bark


@pytest.fixture(scope="module")
def small_run():
    photo = phloem.data.bark()[:128, :128, :3].copy()
    height = photo.mean(axis=2)
    res = bark.generate(photo, (72, 88), n_labels=2, height_map=height, seed=5, full_output=True)
    return photo, height, res


def test_generate_paints_each_label_from_its_region(small_run):
    photo, height, res = small_run
    assert res.texture.shape == (72, 88, 3) and res.texture.dtype == np.float32
    assert res.labels_out.shape == (72, 88) and res.sources.shape == (72, 88, 2)
    sy, sx = res.sources[..., 0], res.sources[..., 1]
    assert (sy >= 0).all() and (sy < 128).all() and (sx >= 0).all() and (sx < 128).all()
    # every output pixel is the photo pixel it names, from a region with the same label
    np.testing.assert_array_equal(res.texture, photo[sy, sx])
    np.testing.assert_array_equal(res.labels_in[sy, sx], res.labels_out)
    # the height map went along with the colours
    np.testing.assert_array_equal(res.height, height[sy, sx])


def test_generate_keeps_label_areas(small_run):
    _, _, res = small_run
    k = int(res.labels_in.max()) + 1
    frac_in = np.bincount(res.labels_in.ravel(), minlength=k) / res.labels_in.size
    frac_out = np.bincount(res.labels_out.ravel(), minlength=k) / res.labels_out.size
    assert np.abs(frac_in - frac_out).max() <= 0.03


def test_generate_resumes_from_its_own_maps(small_run):
    """§3.2: stop, edit a map, resume. Given the maps it made, the pipeline repeats itself."""
    photo, height, res = small_run
    again = bark.generate(photo, labels_in=res.labels_in, labels_out=res.labels_out, height_map=height, seed=5)
    np.testing.assert_array_equal(again[..., :3], res.texture)
    # an edited output map is painted as edited
    edited = res.labels_out.copy()
    edited[:, :30] = 0
    out = bark.generate(photo, labels_in=res.labels_in, labels_out=edited, seed=5, full_output=True)
    np.testing.assert_array_equal(res.labels_in[out.sources[..., 0], out.sources[..., 1]], edited)


def test_generate_is_deterministic_across_threads():
    photo = phloem.data.bark()[:96, :96, :3].copy()
    a = bark.generate(photo, (48, 64), seed=9, threads=1)
    b = bark.generate(photo, (48, 64), seed=9, threads=2)
    np.testing.assert_array_equal(a, b)
    c = bark.generate(photo, (48, 64), seed=10, threads=2)
    assert not np.array_equal(a, c)


def test_generate_errors():
    photo = phloem.data.bark()[:64, :64, :3].copy()
    lab = bark.input_labels(photo, 2)
    with pytest.raises(ValueError, match="^size: required unless labels_out"):
        bark.generate(photo)
    with pytest.raises(ValueError, match="^labels_in: expected shape"):
        bark.generate(photo, 32, labels_in=lab[:40])
    with pytest.raises(ValueError, match="^size: .* does not match labels_out"):
        bark.generate(photo, 32, labels_out=lab[:40, :40])
    with pytest.raises(ValueError, match="^labels_out"):
        bark.generate(photo, labels_in=lab, labels_out=np.full((32, 32), 7, np.int32))
    with pytest.raises(ValueError, match="^height_map: expected shape"):
        bark.generate(photo, 32, height_map=np.zeros((10, 10), np.float32))
    with pytest.raises(ValueError, match="^n_labels: "):
        bark.generate(np.zeros((64, 64, 3), np.float32), 32)
    with pytest.raises(ValueError, match="size"):
        bark.generate(photo, (2, 2))
