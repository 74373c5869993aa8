"""The API dialect (docs/conventions.md): old spellings warn, name the new one and give the same output."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import phloem
from phloem import _api, bark, blend, metrics, seams, shapes


def _old(call, new_name):
    """Run ``call`` expecting one DeprecationWarning that names ``new_name``, pointed at this file."""
    with pytest.warns(DeprecationWarning, match=new_name) as record:
        out = call()
    assert len(record) == 1 and record[0].filename == __file__, [(w.filename, str(w.message)) for w in record]
    return out


# -- the helper -------------------------------------------------------------------------------------


@_api.renamed(old="new", return_extra=_api.old_flag(lambda r: (r, "legacy")))
def _f(x, *, new=1, full_output=False):
    return (x, new, full_output)


def test_renamed_passes_old_spelling_on_under_the_new_name():
    assert _old(lambda: _f(0, old=5), "use new=") == (0, 5, False)
    assert _old(lambda: _f(0, return_extra=True), "full_output=True") == ((0, 1, True), "legacy")
    assert _old(lambda: _f(0, return_extra=False), "full_output=True") == (0, 1, False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _f(0, new=2) == (0, 2, False)  # the new spelling is silent


def test_renamed_refuses_old_and_new_together():
    with pytest.raises(TypeError, match="^old: deprecated spelling of new"):
        _f(0, old=1, new=2)
    with pytest.raises(TypeError, match="^return_extra: deprecated spelling of full_output"):
        _f(0, return_extra=True, full_output=True)


def test_renamed_keeps_the_new_signature_and_doc():
    import inspect

    assert list(inspect.signature(bark.generate).parameters)[:3] == ["image", "size", "n_labels"]
    assert bark.generate.__doc__ is not None and "n_labels" in bark.generate.__doc__


# -- full_output replaces return_info, return_energy, return_intermediates -------------------------


def test_seamless_return_info():
    src = phloem.data.bark()[:32, :32, :3]
    dst = np.full((48, 48, 3), 0.5, np.float32)
    mask = np.ones((32, 32), bool)
    res = blend.seamless(src, dst, mask, (8, 8), full_output=True)
    assert isinstance(res, blend.SeamlessResult) and res.iterations >= 1 and res.residual < 1e-6
    np.testing.assert_array_equal(res.image, blend.seamless(src, dst, mask, (8, 8)))
    out, info = _old(lambda: blend.seamless(src, dst, mask, (8, 8), return_info=True), "full_output=True")
    np.testing.assert_array_equal(out, res.image)
    assert info == {"iterations": res.iterations, "residual": res.residual}


def test_interpolate_field_return_info():
    region = np.ones((12, 16), bool)
    pts, vals = [(2, 2), (9, 13)], [(1.0, 0.0), (0.0, 1.0)]
    res = blend.interpolate_field(region, pts, vals, full_output=True)
    assert isinstance(res, blend.FieldResult)
    np.testing.assert_array_equal(res.field, blend.interpolate_field(region, pts, vals))
    field, info = _old(lambda: blend.interpolate_field(region, pts, vals, return_info=True), "full_output=True")
    np.testing.assert_array_equal(field, res.field)
    assert info == {"iterations": res.iterations, "residual": res.residual}


def test_seam_return_energy():
    a, b = np.zeros((4, 8)), np.ones((4, 8))
    b[:, 4:6] = 0
    cols = np.arange(8)
    am, bm = np.broadcast_to(cols < 6, (4, 8)), np.broadcast_to(cols >= 2, (4, 8))
    res = seams.seam(a, b, am & bm, a_mask=am, b_mask=bm, full_output=True)
    assert isinstance(res, seams.SeamResult) and res.energy == 0.0
    take_b, energy = _old(
        lambda: seams.seam(a, b, am & bm, a_mask=am, b_mask=bm, return_energy=True), "full_output=True"
    )
    np.testing.assert_array_equal(take_b, res.take_b)
    assert energy == res.energy


@pytest.fixture(scope="module")
def photo():
    return phloem.data.bark()[:64, :64, :3].copy()


def test_bark_generate_labels_and_return_intermediates(photo):
    res = bark.generate(photo, 32, n_labels=3, seed=1, full_output=True)
    assert isinstance(res, bark.BarkResult) and int(res.labels_in.max()) == 2
    old = _old(lambda: bark.generate(photo, 32, labels=3, seed=1), "use n_labels=")
    np.testing.assert_array_equal(old, res.texture)
    old_res = _old(lambda: bark.generate(photo, 32, n_labels=3, seed=1, return_intermediates=True), "full_output")
    assert isinstance(old_res, bark.BarkResult)
    np.testing.assert_array_equal(old_res.labels_out, res.labels_out)


def test_bark_input_labels_k(photo):
    new = bark.input_labels(photo, n_labels=3, seed=2)
    np.testing.assert_array_equal(_old(lambda: bark.input_labels(photo, k=3, seed=2), "use n_labels="), new)
    np.testing.assert_array_equal(bark.input_labels(photo, 3, seed=2), new)  # positional is unchanged


# -- one vocabulary for rotations: "all" / "half" / "none" in Python and on the CLI ------------------


@pytest.mark.parametrize(("old", "new"), [(True, "all"), (False, "none"), (np.bool_(True), "all")])
def test_rotations_bools_are_old_spellings(old, new):
    yy, xx = np.mgrid[:32, :32]
    a = yy > 2 * xx
    want = shapes.shape_similarity(a, np.rot90(a), rotations=new)
    assert _old(lambda: shapes.shape_similarity(a, np.rot90(a), rotations=old), repr(new)) == want
    assert _old(lambda: metrics.shape_similarity(a, np.rot90(a), rotations=old), repr(new)) == want
    disk = (yy - 16) ** 2 + (xx - 16) ** 2 < 64
    want_shape = shapes.synthesize(disk, 24, patch_size=5, rotations=new, seed=1)
    np.testing.assert_array_equal(
        _old(lambda: shapes.synthesize(disk, 24, patch_size=5, rotations=old, seed=1), repr(new)), want_shape
    )
    lab = disk.astype(int) + (xx > 20)
    want_lab = shapes.synthesize_labels(lab, 24, patch_size=5, rotations=new, seed=1)
    np.testing.assert_array_equal(
        _old(lambda: shapes.synthesize_labels(lab, 24, patch_size=5, rotations=old, seed=1), repr(new)), want_lab
    )


def test_rotations_default_is_all():
    import inspect

    for f in (shapes.synthesize, shapes.synthesize_labels, shapes.shape_similarity, metrics.shape_similarity):
        assert inspect.signature(f).parameters["rotations"].default == "all", f
    assert shapes.ROTATIONS == ("all", "half", "none")


# -- seeds: an int or a Generator everywhere ----------------------------------------------------------


def test_coherence_map_takes_a_generator(photo):
    a = metrics.coherence_map(photo[:24, :24], photo, seed=np.random.default_rng(5))
    b = metrics.coherence_map(photo[:24, :24], photo, seed=np.random.default_rng(5))
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("seed", [2**63, 2**64 - 1, 2**64, 10**30])
def test_any_non_negative_seed_is_accepted(photo, seed):
    from phloem import texture

    a = texture.synthesize(photo[:16, :16], 16, patch_size=5, seed=seed)
    np.testing.assert_array_equal(a, texture.synthesize(photo[:16, :16], 16, patch_size=5, seed=seed))
    assert phloem._validate.check_seed(seed) < 2**64
    assert phloem._validate.check_seed(2**64 - 1) == 2**64 - 1  # every u64 seed is kept as it is
    hole = np.zeros((16, 16), bool)
    hole[6:10, 6:10] = True
    texture.complete(photo[:16, :16], hole, patch_size=5, seed=seed)


@pytest.mark.parametrize("seed", [-1, True])
def test_negative_and_bool_seeds_are_refused(seed):
    with pytest.raises((ValueError, TypeError), match=r"^seed: "):
        phloem._validate.check_seed(seed)


def test_shape_similarity_takes_threads():
    yy, xx = np.mgrid[:40, :40]
    a, b = yy > 2 * xx, (yy - 20) ** 2 + (xx - 18) ** 2 < 120
    one = shapes.shape_similarity(a, b, threads=1)
    assert shapes.shape_similarity(a, b, threads=2) == one == metrics.shape_similarity(a, b, threads=2)


# -- texture, branching, trees ------------------------------------------------------------------------


def test_quilt_return_sources(photo):
    from phloem import texture

    res = texture.quilt(photo, 48, block=24, seed=1, full_output=True)
    assert isinstance(res, texture.QuiltResult)
    np.testing.assert_array_equal(res.texture, texture.quilt(photo, 48, block=24, seed=1))
    out, src = _old(lambda: texture.quilt(photo, 48, block=24, seed=1, return_sources=True), "full_output=True")
    np.testing.assert_array_equal(out, res.texture)
    np.testing.assert_array_equal(src, res.sources)


def test_by_numbers_return_sources_and_k(photo):
    from phloem import texture

    a = (photo.mean(axis=2) > 0.3).astype(np.int32)
    b = np.zeros((32, 40), np.int32)
    b[:, 10:30] = 1
    res = texture.by_numbers(photo, a, b, coherence_k=2, seed=1, full_output=True)
    assert isinstance(res, texture.ByNumbersResult)
    np.testing.assert_array_equal(res.image, texture.by_numbers(photo, a, b, coherence_k=2, seed=1))
    out, src = _old(lambda: texture.by_numbers(photo, a, b, coherence_k=2, seed=1, return_sources=True), "full_output")
    np.testing.assert_array_equal(out, res.image)
    np.testing.assert_array_equal(src, res.sources)
    np.testing.assert_array_equal(
        _old(lambda: texture.by_numbers(photo, a, b, k=2, seed=1), "use coherence_k="), res.image
    )


@pytest.fixture(scope="module")
def models():
    from phloem import branching

    sk = branching.synthetic_skeleton(0, length=120.0)
    return sk, branching.fit_models(sk)


def test_fit_models_k_and_c(models):
    from phloem import branching

    sk, _ = models
    new_bend, _ = branching.fit_models(sk, order=2, n_best=1)
    old_bend, _ = _old(lambda: branching.fit_models(sk, order=2, c=1), "use n_best=")
    assert (old_bend.k, old_bend.c) == (new_bend.k, new_bend.c) == (2, 1)
    old_bend, _ = _old(lambda: branching.fit_models(sk, k=2, n_best=1), "use order=")
    assert (old_bend.k, old_bend.c) == (2, 1)


def test_synthesize_k_and_c():
    import cv2
    import numpy as np

    from phloem import branching

    img = np.full((64, 96), 0.8, np.float32)
    cv2.line(img, (5, 58), (90, 8), 0.1, 4)
    opts = {"kind": "dark", "sigmas": (1.5, 2.5)}
    new = branching.synthesize(img, trace_options=opts, order=2, n_best=1, seed=0)
    old = _old(lambda: branching.synthesize(img, trace_options=opts, order=2, c=1, seed=0), "use n_best=")
    assert (old.bending.k, old.bending.c) == (new.bending.k, new.bending.c) == (2, 1)
    assert np.array_equal(old.image, new.image)


def test_grow_and_extend_shape(models):
    from phloem import branching

    _, (bend, fur) = models
    new = branching.grow(bend, fur, size=(96, 96), seed=0)
    assert _old(lambda: branching.grow(bend, fur, shape=(96, 96), seed=0), "use size=") == new
    assert branching.grow(bend, fur, size=96, seed=0) == new  # an int is a square
    longer = branching.extend(new, 0, bend, steps=1, seed=0, size=(96, 96))
    assert _old(lambda: branching.extend(new, 0, bend, steps=1, seed=0, shape=(96, 96)), "use size=") == longer


def test_skeleton_draw_and_mask_shape(models):
    sk, _ = models
    mask = sk.mask(size=(90, 110))
    assert mask.shape == (90, 110)
    np.testing.assert_array_equal(_old(lambda: sk.mask(shape=(90, 110)), "use size="), mask)
    np.testing.assert_array_equal(sk.mask((90, 110)), mask)  # positional, as before: no warning
    drawn = sk.draw(size=(90, 110), width=2)
    assert drawn.shape == (90, 110, 3)
    np.testing.assert_array_equal(_old(lambda: sk.draw(shape=(90, 110), width=2), "use size="), drawn)
    np.testing.assert_array_equal(sk.draw(size=64), sk.draw(size=(64, 64)))  # an int is a square


def test_render_c(models):
    from phloem import branching

    sk, _ = models
    img = np.where(sk.mask(), 0.2, 0.8).astype(np.float32)
    new = branching.render(img, sk, sk, n_best=1, seed=0, complete=False)
    np.testing.assert_array_equal(
        _old(lambda: branching.render(img, sk, sk, c=1, seed=0, complete=False), "n_best="), new
    )


def test_unrectify_shape():
    from phloem import branching

    img = np.random.default_rng(0).random((20, 30)).astype(np.float32)
    hm = np.eye(3)
    new = branching.unrectify(img, hm, size=(20, 30))
    np.testing.assert_array_equal(_old(lambda: branching.unrectify(img, hm, shape=(20, 30)), "use size="), new)


def _tree_rgba(seed):
    img = np.zeros((120, 80, 4), np.float32)
    img[..., 1] = 0.5
    img[10 + seed : 70, 10 : 70 - seed, 3] = 1.0
    img[70:110, 35:45, 3] = 1.0
    return img


@pytest.fixture(scope="module")
def library():
    from phloem import trees

    return trees.Library.from_images([_tree_rgba(s) for s in range(3)], size=128)


def test_variation_sources_and_generator_seed(library):
    from phloem import trees

    new = trees.variation(library, n_sources=3, seed=2)
    old = _old(lambda: trees.variation(library, sources=3, seed=2), "use n_sources=")
    np.testing.assert_array_equal(old.image, new.image)
    a = trees.variation(library, seed=np.random.default_rng(7))
    b = trees.variation(library, seed=np.random.default_rng(7))
    np.testing.assert_array_equal(a.image, b.image)


def test_vary_n_and_sources(library):
    from phloem import trees

    new = trees.vary(_tree_rgba(4), library, n_variations=2, n_sources=2, seed=1)
    old = _old(lambda: trees.vary(_tree_rgba(4), library, n=2, n_sources=2, seed=1), "use n_variations=")
    assert [v.sources for v in old] == [v.sources for v in new]
    old = _old(lambda: trees.vary(_tree_rgba(4), library, n_variations=2, sources=2, seed=1), "use n_sources=")
    assert [v.sources for v in old] == [v.sources for v in new]


@pytest.mark.parametrize(("old", "new"), [(None, "auto"), (True, "yes"), (False, "no")])
def test_library_atlas_words(tmp_path, old, new):
    from phloem import io, trees

    io.write_image(tmp_path / "t.png", _tree_rgba(0))
    want = trees.Library.load(tmp_path, size=96, atlas=new)
    got = _old(lambda: trees.Library.load(tmp_path, size=96, atlas=old), repr(new))
    assert got.names == want.names and len(got) == len(want)


def test_fill_contour_and_cages_shape(library):
    from phloem import trees

    poly = [(10, 10), (60, 12), (50, 70), (12, 60)]
    np.testing.assert_array_equal(
        _old(lambda: trees.fill_contour(poly, shape=(80, 80)), "use size="), trees.fill_contour(poly, (80, 80))
    )
    t = library[0]
    new = trees.cages(t.resampled, [t], (128, 128), m=20)
    old = _old(lambda: trees.cages(t.resampled, [t], shape=(128, 128), m=20), "use size=")
    np.testing.assert_array_equal(old[0], new[0])


@pytest.mark.parametrize("dtype", ["int8", "int16", "int32", "int64", "uint32", "uint64"])
def test_images_of_other_integer_dtypes_are_refused(dtype):
    img = np.full((8, 8, 3), 100, dtype=dtype)
    with pytest.raises(TypeError, match=r"^image: expected dtype uint8, uint16 or float, got " + dtype):
        phloem._validate.as_image(img, "image")
    with pytest.raises(TypeError, match=r"^exemplar: expected dtype uint8, uint16 or float"):
        phloem.texture.synthesize(img, 8, patch_size=3)
