"""Fragment-based image synthesis along a branching structure (Sibbing, Pavić, Kobbelt 2010, §5).

Given an input image with its (source) skeleton and a new (target) skeleton, :func:`render`
paints the target structure with disk-shaped fragments of the input:

1. The source and the target skeleton are covered with fragments (:mod:`.fragments`, §5.1).
2. Branch by branch (parents first) each target fragment takes the source fragment minimising
   ``S + ω_C C`` (§5.2): ``S`` is the shape distance after the closed-form rigid alignment
   (:func:`~phloem.branching.rigid_align`), ``C`` the colour difference with what is already
   painted in the overlap; one of the ``c`` best is drawn with probability inversely
   proportional to its objective.
3. The chosen fragment is deformed by the smooth displacement field that carries its skeleton
   samples onto the target's (the energy of :func:`phloem.blend.interpolate_field`, solved
   directly on a grid of ~8 cells per radius and upsampled; scaled down where it would fold
   the fragment; the sampling maps come from the core, ``phloem_core::deform``), cut against
   the painted pixels along a minimum-cost seam (:func:`phloem.seams.seam`) and pasted in the
   gradient domain with its colours held fixed where it borders unpainted pixels
   (:func:`phloem.blend.seamless` with ``fixed``, §5.3).
   Before a sub-branch starts, the disk of its furcation fragment is deleted from the output
   and repainted by a furcation fragment (Fig. 6).
4. The gaps between the branches are completed (§5.4, :mod:`.gaps`); where step 5 follows,
   the whole canvas is completed without the structure as context.
5. The whole structure is pasted into the completed gaps in the gradient domain
   (``paste_structure``, not two-level inputs): each fragment keeps its own gradients, with
   none between fragments or towards the gaps, so fragments from differently lit or high
   parts of the input meet each other and the background without a disk-shaped step. The
   structure is then lifted (or lowered) until it stands out from the gaps as much as the
   input's does, the lift fading to nothing at the fragments' rims, and where it would leave
   the input's range in a blot (a deep valley on low ground) its relief is scaled into the
   range rather than clipped flat.

Beyond the paper (each needed for clean junctions, see the tests):

- a sub-branch crosses the banks its parent's fragments painted; there the seam must give
  the sub-branch's own structure pixels to the new fragment, and the Poisson paste keeps
  their colours (a colour seam cut the sub-branch off, the Poisson boundary faded it out);
- source branch fragments that hold part of another branch (a sub-branch's start) are left
  to the furcation fragments: pasted along a plain target branch they left stubs;
- a two-level output keeps only the pieces of structure that the target touches: fragment
  disks carry pieces of neighbouring channels, which stood as islands;
- furcation fragments are also offered mirrored (``mirror=True``), since with rotations only
  a target sub-branch on the other side of its parent may have no match;
- source fragments whose surroundings are an outlier among all fragments' (by colour or by
  slope, a modified z-score over 3.5) are not used, photos and fields only: a branch start or
  end has no painted neighbour to hold its colour, and stamped the place its source lay in
  (a fundus photo's optic disc, its rim's shading) into the output;
- nor are source fragments whose structure is far blurrier than the rest (its edge width an
  outlier, the same z-score): a dish's out-of-focus rim, traced as the thickest vessel,
  painted the brain's thick branches as smears;
- the structure is pasted into the completed gaps as a whole (``paste_structure``, step 5):
  §5.3's per-fragment paste keeps each fragment's level where it borders the unpainted gaps,
  so on a terrain or an unevenly lit photo every disk showed; without the structure paste the
  completed gaps are instead pasted against the structure (``match_borders``), which leaves
  large steps alone;
- before that paste the background is completed blind to the structure: its patches come
  from the input's background only, and partly known patches holding a bolt or a valley
  matched the background's few high-contrast places, copied beside the structure as halos;
- a fragment whose disk holds a free end of its branch (a tip, or a root's start) paints
  only the branch's tube, 1.5 times its thickness plus 2 px (photos and fields; a mask's
  foreign pieces are dropped at the end). Such a fragment is taken from a source branch's
  end, and what lies past that end is whatever stopped the trace: on the mouse brain a
  tangle of finer vessels, stamped at every tip as a star.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, field, replace
from typing import Any, Literal, overload

import cv2
import numpy as np
from numpy.typing import NDArray

from .. import _core, _memory
from .._api import Seed, renamed
from .._distance import euclidean_distance
from .._progress import Progress
from .._validate import as_image, as_mask, check_float, check_int, check_patch_size, check_seed, check_threads
from ..blend import seamless
from ..seams import seam
from ._elements import _free_ends
from ._pixels import F32, F64, _by_channels, _check_skeleton, _clip_channels, _paste, _pt, _robust_z, _rot, two_level
from .fragments import DEFAULT_SAMPLES, Fragment, FragmentLibrary, check_params, cover, foreign_fragments
from .frame import _keep_frame, _kept_inside
from .gaps import fill_gaps, gap_diversity_default
from .measures import END_TUBE, END_TUBE_ADD, structure_contrast
from .skeleton import MAX_THICKNESS, Branch, Skeleton

__all__ = ["RenderResult", "render"]


@dataclass
class RenderResult:
    """Everything :func:`render` computed.

    Attributes
    ----------
    image : ndarray of float32, shape (H, W, C), or (H, W) for a 2-D input
        The synthesised image.
    labels : ndarray of int32, shape (H, W)
        Index into ``targets`` of the fragment each pixel came from; ``-1`` for pixels filled
        by the gap completion.
    sources, targets : list of Fragment
        The source fragments and the target fragments, in synthesis order.
    choice : ndarray of int64
        ``sources`` index chosen for each target fragment.
    mirrored : ndarray of bool
        Whether that source fragment was used mirrored (furcations only, see ``mirror``).
    structure : ndarray of float32, shape (H, W, C), or (H, W) for a 2-D input
        The image before gap completion (unpainted pixels are 0).
    """

    image: F32
    labels: NDArray[np.int32]
    sources: list[Fragment]
    targets: list[Fragment]
    choice: NDArray[np.int64]
    mirrored: NDArray[np.bool_]
    structure: F32 = field(repr=False)


@overload
def render(
    image: Any,
    source_skeleton: Skeleton,
    target_skeleton: Skeleton,
    *,
    seed: Seed = ...,
    n_best: int = ...,
    omega_s: float = ...,
    omega_c: float = ...,
    lam: float = ...,
    radius_factor: float = ...,
    samples: int = ...,
    deform: bool = ...,
    photometric: bool = ...,
    seams: bool = ...,
    mirror: bool = ...,
    complete: bool = ...,
    match_borders: bool | None = ...,
    paste_structure: bool | None = ...,
    valid: Any = ...,
    keep_frame: bool = ...,
    patch_size: int = ...,
    completion_iterations: int = ...,
    gap_diversity: float | None = ...,
    threads: int | None = ...,
    progress: Progress = ...,
    max_memory: int | None = ...,
    full_output: Literal[False] = ...,
) -> F32: ...
@overload
def render(
    image: Any,
    source_skeleton: Skeleton,
    target_skeleton: Skeleton,
    *,
    seed: Seed = ...,
    n_best: int = ...,
    omega_s: float = ...,
    omega_c: float = ...,
    lam: float = ...,
    radius_factor: float = ...,
    samples: int = ...,
    deform: bool = ...,
    photometric: bool = ...,
    seams: bool = ...,
    mirror: bool = ...,
    complete: bool = ...,
    match_borders: bool | None = ...,
    paste_structure: bool | None = ...,
    valid: Any = ...,
    keep_frame: bool = ...,
    patch_size: int = ...,
    completion_iterations: int = ...,
    gap_diversity: float | None = ...,
    threads: int | None = ...,
    progress: Progress = ...,
    max_memory: int | None = ...,
    full_output: Literal[True],
) -> RenderResult: ...


@renamed(c="n_best")
def render(
    image: Any,
    source_skeleton: Skeleton,
    target_skeleton: Skeleton,
    *,
    seed: Seed = 0,
    n_best: int = 2,
    omega_s: float = 2.0,
    omega_c: float = 1.0,
    lam: float = 0.75,
    radius_factor: float = 3.0,
    samples: int = DEFAULT_SAMPLES,
    deform: bool = True,
    photometric: bool = True,
    seams: bool = True,
    mirror: bool = True,
    complete: bool = True,
    match_borders: bool | None = None,
    paste_structure: bool | None = None,
    valid: Any = None,
    keep_frame: bool = True,
    patch_size: int = 7,
    completion_iterations: int = 4,
    gap_diversity: float | None = None,
    threads: int | None = None,
    progress: Progress = None,
    max_memory: int | None = None,
    full_output: bool = False,
) -> F32 | RenderResult:
    """Synthesise an image of ``target_skeleton`` from fragments of ``image`` (§5).

    See the module docstring for the steps. The colour term is
    ``C = k r² · mean_overlap ‖colour difference‖² / s²`` with ``s²`` the input's squared range
    averaged over its channels: the paper's sum over the overlap, rescaled so that it grows
    with the fragment like ``S`` does and a default ``ω_C = 1`` balances the two whatever the
    input's contrast (an image spanning [0, 1] has ``s = 1``). ``C`` is evaluated for the
    ``max(4c, 8)`` fragments of smallest ``S`` only.

    Parameters
    ----------
    image : (H, W[, C]) array_like
        The input image; integer images are scaled to [0, 1].
    source_skeleton : Skeleton
        The structure in ``image`` (every vertex inside it).
    target_skeleton : Skeleton
        The structure to paint; its ``shape`` gives the output size.
    seed : int or numpy.random.Generator, optional
        Seed of the random choice among the ``n_best`` best and of the completion (default 0).
    n_best : int, optional
        Number of best candidates to choose from (the paper's ``c``: default 2, as in §4.2; 1 is
        deterministic). ``c`` before (deprecated).
    omega_s : float, optional
        Weight ω_S of the thickness term of the shape distance (default 2).
    omega_c : float, optional
        Weight ω_C of colour consistency against shape (default 1).
    lam : float, optional
        Fragment spacing factor λ (default 0.75).
    radius_factor : float, optional
        Fragment radius over thickness (default 3; capped as in :func:`fragments`).
    samples : int, optional
        Samples ``k`` per skeleton segment of a fragment's shape (default 9).
    deform : bool, optional
        Deform fragments by the interpolated displacement field (default True).
    photometric : bool, optional
        Gradient-domain pasting with boundary constraints (default True).
    seams : bool, optional
        Graph-cut seams between overlapping fragments (default True).
    mirror : bool, optional
        Also offer every source furcation fragment mirrored (default True). An extension: the
        paper aligns by rotation only, so with few source furcations a target sub-branch on the
        other side of its parent finds no match and is painted with a stub on the wrong side.
        ``False`` is the paper's behaviour.
    complete : bool, optional
        Fill the gaps between the branches (§5.4, default True); without it they stay 0.
        On photos and fields (not two-level masks) the filled gaps then take the input
        background's large-scale brightness, where the input has it (an eighth of its
        shorter side and coarser; a terrain's plateau, a photo's lighting), with the steps
        between its regions kept (a fundus's macula, a terrain's scarp), except the light
        that surrounds the whole structure (a lightning bolt's glow, within ten of its median
        radii), which is laid round the new structure instead.
    match_borders : bool, optional
        Shift the completed gaps in the gradient domain so that they meet the painted
        structure without a colour step (only the smooth part of the step, made of small
        steps: a branch cut off at a disk's edge is left alone). Without it every fragment
        disk of an unevenly lit photo or a terrain shows as a lighter or darker circle.
        Default (None): on where ``paste_structure`` is off, except for two-level images
        such as masks, which have no lighting to match. Needs ``photometric``.
    paste_structure : bool, optional
        After the gap completion, paste the whole painted structure into the completed gaps
        in the gradient domain: one Poisson solve over every fragment pixel whose guidance is
        each fragment's own gradients, zero between two fragments and at the structure's
        border, with the completed gaps as boundary values. Fragments from differently lit
        parts of a photo or from different heights of a terrain then meet each other and the
        background without steps: no disks show, and the structure keeps its own relief.
        The structure's contrast against the gaps is then set to the input's (see
        :func:`phloem.metrics.structure_contrast`): a harmonic ramp from the structure to
        the fragments' rims, so that bolts whose glow the gaps do not continue stay as
        bright as the input's. Where the structure would then leave the input's range over
        an area (not a line, and not at an end the input itself saturates), its relief above
        the gaps is scaled down locally until it fits, instead of being clipped into a flat
        blot. The completion then fills the whole canvas from the
        background without the structure as context, so nothing structure-like is copied
        beside it.
        Default (None): on, except for two-level images (a mask has no ramps to blend and stays
        two-level). Needs ``photometric`` and ``complete``.
    valid : (H, W) array_like of bool, optional
        Where ``image`` shows real content (default everywhere), e.g. the photo inside the
        frame of :func:`rectify` or a fundus photo's disc: only fragments that lie wholly
        inside it are pasted, and the gap completion copies only from there. A fragment whose
        disk comes within its radius of the outside (a fundus rim's shading) paints only
        target fragments as near the new image's frame (the input's stretched, where it is
        kept), unless no other source fits.
    keep_frame : bool, optional
        With ``valid``: the new image shows ``image``'s frame, the pixels outside ``valid``,
        stretched to its size (default True), so a fundus photo stays a disc in its black
        frame and a lightning photo keeps its tree line. Only a frame that runs along at
        least a sixth of the image's border is kept (a side's worth; a flat patch of dark
        ground is not). Its rim is smoothed over 3 px (a JPEG's noise leaves teeth along it)
        and faded in over 4 px. False: the gaps fill it too.
    patch_size : int, optional
        Patch side of the gap completion (default 7, odd).
    completion_iterations : int, optional
        Search-and-vote iterations per pyramid level of the completion (default 4); the
        full-resolution level searches once and copies each pixel from its match (a
        two-level mask's only copies the upsampled half-resolution field).
    gap_diversity : float, optional
        Weight of Kaspar et al.'s occurrence penalty in the gap completion (see ``diversity``
        of :func:`phloem.texture.complete`). Default: :func:`gap_diversity_default`, 1 on a
        grainy surface (asphalt: where :func:`trace`'s default threshold climbs above Otsu's,
        :func:`threshold_climb`) and 0 elsewhere (plain completion, the paper's). Large gaps filled
        from a small background settle on its smoothest patches and read as a blurred photo
        or a smoothed terrain; 1 keeps about twice the background's fine grain there. The
        grain may hold faint structure the trace left out, so the painted branches stand out
        a little less from it, and a fill that was already coherent gets softer. Above 0 the
        completion also starts from random background blocks and skips pyramid levels with
        too few background patches for their gaps (``start="blocks"`` of
        :func:`phloem.texture.complete`); at 0 a small background's gaps repeat a few of its
        2×2 blocks, a fine striped pattern at full size.
    threads : int, optional
        Worker threads (default: all cores). Fragments that do not overlap are painted at
        the same time, one per thread, each waiting only for the earlier fragments whose
        crops meet its own, so the image is the same for any count. (Each fragment's seam and
        Poisson solve runs on one thread: on crops of a few 10⁴ pixels more threads per
        solve only add overhead.) The gap completion uses all of them.
    progress : callable, optional
        Called as ``progress(done, total)`` after each target fragment (and once at the end).
    max_memory : int, optional
        Refuse the job with :class:`phloem.MemoryLimitError` if its estimated peak memory is
        over this many bytes (default None: 75% of the machine's memory; see ``docs/hardening/memory.md``).
    full_output : bool, optional
        Return a :class:`RenderResult` (with the fragment map) instead of the image.

    Returns
    -------
    image : (H, W[, C]) ndarray of float32, or RenderResult
        ``H, W`` from ``target_skeleton.shape``; ``C`` as in ``image`` (2-D for a 2-D ``image``).

    References
    ----------
    .. [1] D. Sibbing, D. Pavić, L. Kobbelt, "Image Synthesis for Branching Structures",
       Computer Graphics Forum 29(7), 2010, §5.

    Examples
    --------
    >>> import numpy as np
    >>> from phloem.branching import Branch, Skeleton, render
    >>> img = np.full((64, 96), 0.8, np.float32); img[29:35, :] = 0.1     # a dark horizontal river
    >>> src = Skeleton([Branch([[2, 31.5], [93, 31.5]], 3.0)], (64, 96))
    >>> tgt = Skeleton([Branch([[31.5, 2], [31.5, 61]], 3.0)], (64, 64))  # the same, vertical
    >>> out = render(img, src, tgt, seed=0)
    >>> out.shape, bool(out[30, 29:35].mean() < 0.3), bool(out[30, 5].mean() > 0.6)
    ((64, 64), True, True)
    """
    flat = np.ndim(image) == 2  # a 2-D input gives a 2-D output, as everywhere else in phloem
    img = as_image(image, "image")
    H0, W0 = img.shape[:2]
    src_sk = _check_skeleton(source_skeleton, "source_skeleton", (H0, W0))
    if not isinstance(target_skeleton, Skeleton):
        raise TypeError(f"target_skeleton: expected a phloem.branching.Skeleton, got {type(target_skeleton).__name__}")
    if target_skeleton.shape is None:
        raise ValueError("target_skeleton: its shape (the output size) must be set")
    tgt_sk = _check_skeleton(target_skeleton, "target_skeleton", target_skeleton.shape)
    _memory.check_size(
        _memory.branching(target_skeleton.shape, img.shape), max_memory, target_skeleton.shape, "target_skeleton"
    )
    lam_f, rf, k = check_params(lam, radius_factor, samples)
    c_n = check_int(n_best, "n_best", 1)
    w_s = check_float(omega_s, "omega_s", 0.0)
    w_c = check_float(omega_c, "omega_c", 0.0)
    p = check_patch_size(patch_size)
    c_iters = check_int(completion_iterations, "completion_iterations", 1)
    gap_div = None if gap_diversity is None else check_float(gap_diversity, "gap_diversity", 0.0)
    s = check_seed(seed)
    t = check_threads(threads)
    rng = np.random.default_rng(s)
    opts = _Options(c_n, w_s, w_c, k, deform, photometric, seams, n_eval=max(4 * c_n, 8))

    ok = None if valid is None else as_mask(valid, "valid", (H0, W0))
    if gap_div is None:
        gap_div = gap_diversity_default(img, valid=ok) if complete else 0.0
    lo, hi = _channel_range(img)
    # A mask stays a mask: no gradient-domain paste (its ramps are grey), levels snapped at the end.
    mask_like = two_level(img, lo, hi)
    if mask_like:
        opts = replace(opts, photometric=False)
    whole = photometric and not mask_like and complete if paste_structure is None else bool(paste_structure)
    if whole and not (photometric and complete):
        raise ValueError(
            "paste_structure: needs photometric=True and complete=True (it pastes into the completed gaps)"
        )
    sources, targets, lib = _cover_both(
        img, src_sk, tgt_sk, ok, lam_f, rf, k, mirror=mirror, keep=max(3, c_n), lighting=None if mask_like else (lo, hi)
    )
    frame_near = None
    if ok is not None:
        # the target's frame: the input's stretched, where a frame that long is kept (whether
        # or not this call keeps it, which only puts it back at the end); else none at all
        assert tgt_sk.shape is not None  # checked above
        frame_near = (_near_frame(sources, ok), _near_frame(targets, _kept_inside(ok, tgt_sk.shape)))
    painter = _Painter(
        img, (lo, hi), tgt_sk, targets, lib, opts, draws=rng.random(len(targets)), frame_near=frame_near,
        trim_ends=not mask_like,
    )  # fmt: skip
    _in_order(painter.boxes, painter.paint, workers=t if t is not None else _core.default_threads(), progress=progress)

    canvas = painter.canvas
    structure = canvas.copy() if full_output else canvas
    if complete and (~painter.filled).any():
        # The structure is pasted afterwards, so the completion sees none of it: its patches are
        # background only, and partly known patches holding a bolt copied halos beside it.
        known = np.zeros_like(painter.filled) if whole else painter.filled
        radius = float(np.median([g.radius for g in targets]))
        canvas = fill_gaps(
            canvas, known, img, src_sk, target_skeleton=tgt_sk, valid=ok, radius_factor=rf,
            radius=radius, lo=painter.lo, hi=painter.hi,
            match_borders=match_borders if match_borders is not None else not whole, photometric=photometric and not mask_like,
            patch_size=p, iterations=c_iters, seed=s, threads=t, diversity=gap_div,
        )  # fmt: skip
        if whole:
            gaps = canvas.copy()
            _paste(canvas, painter.canvas, painter.filled)  # the structure over the completed background
            canvas = _paste_structure(canvas, painter.filled, painter.labels, threads=t)
            canvas = _keep_contrast(canvas, painter.filled, img, src_sk, tgt_sk, threads=t)
            canvas = _fit_range(canvas, gaps, painter.filled, img, painter.lo, painter.hi, reach=radius, threads=t)
    if mask_like:
        canvas = _drop_foreign(
            np.where(canvas >= 0.5 * (lo + hi), hi, lo).astype(np.float32), img, src_sk, tgt_sk, lo, hi
        )
    if ok is not None and keep_frame:
        _keep_frame(canvas, img, ok)
    if progress is not None:
        progress(len(targets) + 1, len(targets) + 1)
    if flat:
        canvas, structure = canvas[..., 0], structure[..., 0]
    if full_output:
        return RenderResult(canvas, painter.labels, sources, targets, painter.choice, painter.mirrored, structure)
    return canvas


@dataclass(frozen=True)
class _Options:
    """The checked options of the fragment stage."""

    c: int  # candidates to draw from
    omega_s: float
    omega_c: float
    k: int  # samples per skeleton segment of a shape
    deform: bool
    photometric: bool
    seams: bool
    n_eval: int  # candidates of smallest S whose colour term is evaluated


def _cover_both(
    image: F32,
    source: Skeleton,
    target: Skeleton,
    valid: NDArray[np.bool_] | None,
    lam: float,
    rf: float,
    k: int,
    *,
    mirror: bool,
    keep: int,
    lighting: tuple[F32, F32] | None,
) -> tuple[list[Fragment], list[Fragment], FragmentLibrary]:
    """Source fragments, target fragments in synthesis order, and the library of usable sources
    (``lighting``: the image's channel range, None for a mask, whose fragments are not compared)."""
    sources = cover(source, lam, rf, k, order=False)
    # Fragments that reach outside the valid region would paste its outside (a fundus
    # photo's black frame) into the output.
    outside = np.array([valid is not None and _reaches_out(f, valid) for f in sources], bool)
    if all(outside[i] for i, f in enumerate(sources) if not f.furcation):
        raise ValueError("valid: every source branch fragment reaches outside it; nothing is left to paint with")
    if lighting is not None:
        outside |= _unusual_surroundings(image, lighting, source, sources, outside, keep=keep)
        outside |= _blurred_structure(image, sources, outside, keep=keep)
    # Without furcation fragments in the source a target furcation is painted by branch fragments.
    furcations = any(f.furcation and not out for f, out in zip(sources, outside, strict=True))
    targets = cover(target, lam, rf, k, order=True, furcations=furcations)
    lib = FragmentLibrary(sources, mirror=mirror, exclude=foreign_fragments(source, sources, keep=keep) | outside)
    return sources, targets, lib


def _leaves_image(f: Fragment, shape: tuple[int, int]) -> bool:
    """Whether the disk of ``f`` reaches more than a pixel beyond the image's border."""
    (x, y), r = f.center, f.radius
    return bool(x - r < -1.0 or y - r < -1.0 or x + r > shape[1] or y + r > shape[0])


def _near_frame(frs: list[Fragment], inside: NDArray[np.bool_] | None) -> NDArray[np.bool_]:
    """Whether each fragment's disk comes within its radius of the frame outside ``inside``
    (the image's own border does not count; None: no frame, none is near)."""
    if inside is None or inside.all():
        return np.zeros(len(frs), bool)
    if not frs:
        return np.zeros(0, bool)
    dist = euclidean_distance(np.pad(inside, 1, constant_values=True))[1:-1, 1:-1]
    h, w = inside.shape
    centres = np.rint([f.center for f in frs]).astype(np.int64)
    x, y = np.clip(centres[:, 0], 0, w - 1), np.clip(centres[:, 1], 0, h - 1)
    return np.asarray(dist[y, x] < 2.0 * np.array([f.radius for f in frs]))


def _channel_range(img: F32) -> tuple[F32, F32]:
    """Per-channel minimum and maximum (reducing over rows first, which is much faster)."""
    H0, C = img.shape[0], img.shape[2]
    lo = img.reshape(H0, -1).min(axis=0).reshape(-1, C).min(axis=0)
    hi = img.reshape(H0, -1).max(axis=0).reshape(-1, C).max(axis=0)
    return lo, hi


class _Painter:
    """The output while the target fragments are painted into it (§5.2-§5.3).

    :meth:`paint` handles one fragment: choose its source (:meth:`_choose`), warp it onto the
    target (:meth:`_warp`), cut it against the painted pixels (:meth:`_cut`) and paste it
    (:meth:`_blend`). Fragment ``j`` reads and writes only inside ``boxes[j]``, so fragments
    whose boxes do not meet can be painted at the same time (:func:`_in_order`).
    """

    def __init__(
        self,
        image: F32,
        levels: tuple[F32, F32],
        target: Skeleton,
        targets: list[Fragment],
        lib: FragmentLibrary,
        opts: _Options,
        draws: F64,
        frame_near: tuple[NDArray[np.bool_], NDArray[np.bool_]] | None = None,
        trim_ends: bool = False,
    ) -> None:
        assert target.shape is not None
        H, W = target.shape
        self.image = image
        self.targets = targets
        self.lib = lib
        self.opts = opts
        # One uniform per fragment, drawn up front: the same pick whatever order they are painted in.
        self.draws = draws
        self.canvas = np.zeros((H, W, image.shape[2]), np.float32)
        self.filled = np.zeros((H, W), bool)
        self.labels = np.full((H, W), -1, np.int32)
        # Which target branch's structure each pixel lies on, and which branch painted it: a
        # sub-branch must cross its parent's already painted banks (Fig. 6), where a colour seam
        # would cut it off and the Poisson boundary would fade it into the bank.
        self.struct = _branch_map(target, (H, W))
        self.owner = np.full((H, W), -1, np.int32)
        self.choice = np.zeros(len(targets), np.int64)
        self.mirrored = np.zeros(len(targets), bool)
        self.lo, self.hi = levels  # the image's per-channel range
        # Colour differences in units of the input's range (C's weight is set for a full one):
        # on a terrain spanning 1 % of [0, 1] the colour term would otherwise be off.
        span2 = float(np.mean((self.hi - self.lo).astype(np.float64) ** 2))
        self.contrast = 1.0 / span2 if span2 > 0 else 1.0
        self.clipped = np.array([_leaves_image(f, image.shape[:2]) for f in lib.frs], bool)
        # (sources, targets) whose disks come within a radius of their image's frame
        self.frame_near = frame_near
        self.crops: list[tuple[slice, slice, NDArray[np.bool_], int, int]] = []
        self.boxes = np.zeros((len(targets), 4), np.int64)
        for j, g in enumerate(targets):
            crop = _disk((H, W), g.center, g.radius)
            if trim_ends and not g.furcation and _past_free_end(target, g):
                ys, xs, disk, y0, x0 = crop
                crop = ys, xs, disk & _own_tube(target.branches[g.branch], disk.shape, (x0, y0)), y0, x0
            self.crops.append(crop)
            self.boxes[j] = crop[0].start, crop[0].stop, crop[1].start, crop[1].stop

    def paint(self, j: int) -> None:
        """Paint target fragment ``j``."""
        g = self.targets[j]
        ys, xs, disk, _, _ = self.crops[j]
        # Colour consistency is measured against what is painted, including the parent's
        # pixels a furcation fragment is about to replace: they are the best colour reference.
        over = disk & self.filled[ys, xs]
        if g.furcation:
            # Fig. 6: the parent's fragments are deleted where the furcation fragment goes.
            self.filled[ys, xs] &= ~disk
        fill_c = self.filled[ys, xs]
        e, theta = self._choose(j, over)
        warped = self._warp(j, e, theta)
        new = self._cut(j, warped, fill_c)
        if not new.any():
            return
        self._blend(j, warped, new, fill_c)
        self.filled[ys, xs] |= new
        np.copyto(self.labels[ys, xs], j, where=new)
        np.copyto(self.owner[ys, xs], g.branch, where=new)

    def _choose(self, j: int, over: NDArray[np.bool_]) -> tuple[int, float]:
        """The library entry and rotation for fragment ``j``: one of the ``c`` best by ``S + ω_C C``."""
        g, lib, o = self.targets[j], self.lib, self.opts
        idx, S, theta = lib.shape_distance(g, o.omega_s)
        if not _leaves_image(g, self.filled.shape):
            # A source disk that leaves its image carries the reflected border; inside the
            # output (at a branch end: a blob) only when nothing else is left.
            out = self.clipped[lib.frag[idx]]
            if not out.all():
                S = np.where(out, np.inf, S)
        if self.frame_near is not None and not self.frame_near[1][j]:
            # Likewise a source disk by the frame (a fundus photo's rim) carries the frame's
            # shading: away from the target's frame only when nothing else is left.
            out = self.frame_near[0][lib.frag[idx]]
            if not out.all():
                S = np.where(out, np.inf, S)
        order = np.argsort(S, kind="stable")[: o.n_eval]
        obj = S[order].copy()
        if o.omega_c > 0 and over.any():
            obj += self._colour_term(j, over, idx[order], theta[order])
        best = np.argsort(obj, kind="stable")[: o.c]
        wts = 1.0 / np.maximum(obj[best], 1e-9)
        # Inverse-CDF draw from this fragment's own uniform.
        cdf = np.cumsum(wts)
        pick = int(best[min(int(np.searchsorted(cdf, self.draws[j] * cdf[-1], side="right")), len(best) - 1)])
        cand = int(order[pick])
        e = int(idx[cand])
        self.choice[j] = int(lib.frag[e])
        self.mirrored[j] = bool(lib.flip[e])
        return e, float(theta[cand])

    def _colour_term(self, j: int, over: NDArray[np.bool_], ents: NDArray[np.int64], thetas: F64) -> F64:
        """``ω_C C`` of each candidate entry: the colour difference with the painted overlap."""
        g, lib, o = self.targets[j], self.lib, self.opts
        ys, xs, _, y0, x0 = self.crops[j]
        oy, ox = np.nonzero(over)
        step = max(1, int(math.sqrt(len(oy) / 400)))
        oy, ox = oy[::step], ox[::step]
        rel = np.stack([ox + x0 - g.center[0], oy + y0 - g.center[1]], axis=1)
        painted = self.canvas[ys, xs][oy, ox]
        # The overlap as seen through every candidate, sampled in one remap.
        maps = np.stack([lib.to_source(int(e), float(a)) for e, a in zip(ents, thetas, strict=True)])
        centres = np.stack([lib.frs[int(lib.frag[e])].center for e in ents])
        # Written out: a stacked matmul calls BLAS (see render's threads), an einsum is slower.
        rx, ry = rel[:, 0], rel[:, 1]
        mx = maps[:, 0, 0, None] * rx + maps[:, 0, 1, None] * ry + centres[:, 0, None]
        my = maps[:, 1, 0, None] * rx + maps[:, 1, 1, None] * ry + centres[:, 1, None]
        vals = _sample(self.image, mx.astype(np.float32), my.astype(np.float32))
        diff = (vals - painted[None]).reshape(len(ents), -1)
        w = o.omega_c * o.k * g.radius**2 * self.contrast
        return np.asarray(w * np.einsum("ij,ij->i", diff, diff) / len(oy))  # (channel sums over a trailing axis: slow)

    def _warp(self, j: int, e: int, theta: float) -> F32:
        """Library entry ``e`` rotated by ``theta`` and deformed onto fragment ``j``'s crop (§5.3)."""
        g, lib = self.targets[j], self.lib
        _, _, disk, y0, x0 = self.crops[j]
        f = lib.frs[int(lib.frag[e])]
        R = _rot(theta)
        M = lib.to_source(e, theta)  # target offsets → source offsets
        # Target pixel → source position: rigid inverse of (p + d(p)), d the displacement field.
        if self.opts.deform:
            # The displacement field, its fold-free scale and the maps in the core, without the GIL.
            d = lib.points[e] @ R.T - g.points
            mapx, mapy, _ = _core.fragment_maps(
                np.ascontiguousarray(disk), (y0, x0), (float(g.center[0]), float(g.center[1])),
                np.ascontiguousarray(g.points + g.center, np.float64), np.ascontiguousarray(d, np.float64),
                float(g.radius), np.ascontiguousarray(M, np.float64), (float(f.center[0]), float(f.center[1])),
            )  # fmt: skip
            return _sample(self.image, mapx, mapy)
        hh, ww = disk.shape
        gy, gx = np.mgrid[y0 : y0 + hh, x0 : x0 + ww].astype(np.float64)
        px, py = gx - g.center[0], gy - g.center[1]
        mapx = (M[0, 0] * px + M[0, 1] * py + f.center[0]).astype(np.float32)
        mapy = (M[1, 0] * px + M[1, 1] * py + f.center[1]).astype(np.float32)
        return _sample(self.image, mapx, mapy)

    def _cut(self, j: int, warped: F32, fill_c: NDArray[np.bool_]) -> NDArray[np.bool_]:
        """The crop pixels fragment ``j`` takes: its disk, cut against the painted overlap by a seam."""
        g = self.targets[j]
        ys, xs, disk, _, _ = self.crops[j]
        region = disk & fill_c
        if not (self.opts.seams and region.any() and (disk & ~fill_c).any()):
            whole: NDArray[np.bool_] = disk.copy()
            return whole
        # The cut only needs the overlap and its 1-pixel ring (where the border ties live).
        ry, rx = np.nonzero(region)
        sub = (slice(max(0, ry.min() - 1), ry.max() + 2), slice(max(0, rx.min() - 1), rx.max() + 2))
        cross = region & (self.struct[ys, xs] == g.branch) & (self.owner[ys, xs] != g.branch)
        seeds = np.where(cross, 2, 0).astype(np.uint8)[sub] if cross.any() else None
        take = seam(
            self.canvas[ys, xs][sub], warped[sub], region[sub], a_mask=fill_c[sub], b_mask=disk[sub], seeds=seeds,
            border_weight=None if seeds is None else 1e4, threads=1,
        )  # fmt: skip
        new = disk & ~fill_c
        new[sub] |= region[sub] & take
        return new

    def _fixed(self, j: int, new: NDArray[np.bool_], fill_c: NDArray[np.bool_]) -> NDArray[np.bool_]:
        """The new pixels whose colours the gradient-domain paste keeps (§5.3's added constraints)."""
        g = self.targets[j]
        ys, xs, _, _, _ = self.crops[j]
        known = new | (fill_c & ~new)
        pad = np.pad(known, 1, constant_values=True)
        nb_ok = pad[:-2, 1:-1] & pad[2:, 1:-1] & pad[1:-1, :-2] & pad[1:-1, 2:]
        fixed = new & ~nb_ok
        # Where this branch's own structure meets what another branch painted, keep its
        # colours too: that border is structure against bank, not a colour mismatch.
        foreign = np.pad(fill_c & ~new & (self.owner[ys, xs] != g.branch), 1, constant_values=False)
        touch = foreign[:-2, 1:-1] | foreign[2:, 1:-1] | foreign[1:-1, :-2] | foreign[1:-1, 2:]
        fixed |= new & touch & (self.struct[ys, xs] == g.branch)
        return fixed

    def _blend(self, j: int, warped: F32, new: NDArray[np.bool_], fill_c: NDArray[np.bool_]) -> None:
        """Paste the ``new`` pixels of ``warped``, in the gradient domain where they meet painted ones."""
        ys, xs, _, _, _ = self.crops[j]
        if not (self.opts.photometric and (fill_c & ~new).any()):
            _paste(self.canvas[ys, xs], warped, new)
            return
        fixed = self._fixed(j, new, fill_c)
        # Solve on the box of the new pixels and their 1-pixel ring only (the same system).
        ny, nx = np.nonzero(new)
        bx = (slice(max(0, ny.min() - 1), ny.max() + 2), slice(max(0, nx.min() - 1), nx.max() + 2))
        dst = self.canvas[ys, xs][bx].copy()
        _paste(dst, warped[bx], ~fill_c[bx])
        # tol 1e-3: within a third of an 8-bit level of the exact solve, and faster.
        res = seamless(warped[bx], dst, new[bx], (0, 0), fixed=fixed[bx], tol=1e-3, max_iterations=100, threads=1)
        # The gradient-domain paste can overshoot where a border mismatches strongly; keep
        # the output within the input's range. (Basic slices: views of canvas.)
        res = _clip_channels(res.reshape(*dst.shape), self.lo, self.hi)
        _paste(self.canvas[ys, xs][bx], res, new[bx])


def _paste_structure(canvas: F32, filled: NDArray[np.bool_], labels: NDArray[np.int32], *, threads: int | None) -> F32:
    """Gradient-domain paste of the whole structure into the completed gaps (``paste_structure``).

    A custom guidance field on the Poisson engine (:func:`phloem.blend.seamless` with
    ``labels``): each fragment's gradients inside it, none across fragments or towards the
    gaps, so every level difference between fragments and against the background is spread
    over the fragments instead of showing as a step at a disk's rim. Not clipped to the
    image's range: :func:`_fit_range` does that after the contrast step.
    """
    if not filled.any():
        return canvas
    lab = np.where(filled, labels, -1).astype(np.int32)
    # tol 1e-4 as for the gaps: the levels move by up to the image's range, far above that.
    out = seamless(canvas, canvas, filled, (0, 0), labels=lab, tol=1e-4, threads=threads)
    res: F32 = canvas.copy()
    _paste(res, np.asarray(out, np.float32).reshape(canvas.shape), filled)
    return res


def _keep_contrast(
    canvas: F32,
    filled: NDArray[np.bool_],
    image: F32,
    source: Skeleton,
    target: Skeleton,
    *,
    threads: int | None,
) -> F32:
    """``canvas`` with its structure standing out from the gaps as much as ``image``'s does.

    The whole-structure paste moves every fragment to the gaps' level at its rim, so a bolt
    whose glow the gaps do not continue comes out grey, a vessel pale. The difference between
    the input's and the canvas's :func:`~phloem.branching.measures.structure_contrast` is
    added to the target's structure (its tube at one thickness), the same in every channel,
    and fades to nothing at the fragments' rims as the smoothest (harmonic) ramp between
    them: a glow or a shadow round the structure, the gaps untouched.
    """
    try:
        step = structure_contrast(image, source) - structure_contrast(canvas, target)
    except ValueError:  # a structure with no surroundings in the image has no contrast to keep
        return canvas
    core = _tube(target, 1.0, 0.0) & filled
    if step == 0.0 or not core.any():
        return canvas
    # Laplace's equation over the fragments less the core: the step on the core, 0 in the gaps.
    ends = np.where(core, np.float32(step), np.float32(0.0))
    ramp = seamless(np.zeros_like(ends), ends, filled & ~core, (0, 0), tol=1e-4, threads=threads)
    res: F32 = canvas.copy()
    lifted = canvas + np.asarray(ramp, np.float32).reshape(filled.shape)[..., None]
    _paste(res, lifted, filled)
    return res


#: An end of the input's range counts as saturated (lightning's white cores, a sky's black)
#: when at least this share of its pixels lie within 1/1000 of the range of it.
SATURATED_SHARE = 1e-3

#: The least share of its relief the structure keeps where it is fitted into the range; what
#: is still out of range then is clipped (structure whose rim lies at the range's end has no
#: room at all, and would otherwise lose its relief).
MIN_RELIEF_SCALE = 0.25

#: Out-of-range areas narrower than this (px) are clipped, not fitted: a bolt's saturated
#: core is a line, an elevation model's flattened valley floor a blot.
BLOT_WIDTH = 5


def _fit_range(
    canvas: F32,
    gaps: F32,
    filled: NDArray[np.bool_],
    image: F32,
    lo: F32,
    hi: F32,
    *,
    reach: float,
    threads: int | None,
) -> F32:
    """``canvas`` clipped to ``[lo, hi]``, the structure's relief first scaled into that range
    where clipping would flatten it into a blot.

    The structure's paste and contrast keep each fragment's depth below (or height above)
    its surroundings, so a deep valley landing on low ground goes beyond the input's range,
    and clipping flattened it into a blot of the extreme value. The relief is measured from
    the membrane that the completed ``gaps`` span over the structure (the harmonic
    interpolation of their values at its rim) and scaled, the same in every channel, by the
    factor each out-of-range pixel needs to reach the range, spread over ``reach`` px (the
    fragments' radius: the smallest factor within a square that far, then smoothed by a
    Gaussian of half that) so the relief fades instead of stepping, at least
    :data:`MIN_RELIEF_SCALE`. Only out-of-range areas at least :data:`BLOT_WIDTH` px wide are
    fitted, and only at an end of the range the input itself does not saturate
    (:data:`SATURATED_SHARE`): a bolt's white core and whatever the input shows saturated are
    clipped as before.
    """
    res: F32 = canvas.copy()
    if not filled.any():
        return _clip_channels(res, lo, hi)
    near = 1e-3 * np.maximum(hi - lo, 1e-12)
    low_ok = (image <= lo + near).mean(axis=(0, 1)) >= SATURATED_SHARE  # per channel
    high_ok = (image >= hi - near).mean(axis=(0, 1)) >= SATURATED_SHARE
    under = (canvas < lo) & ~low_ok
    over = (canvas > hi) & ~high_ok
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (BLOT_WIDTH, BLOT_WIDTH))
    out = ((under | over).any(axis=2) & filled).astype(np.uint8)
    blots = cv2.morphologyEx(out, cv2.MORPH_OPEN, kernel).astype(bool)
    if not blots.any():
        return _clip_channels(res, lo, hi)
    # the factor is 1 beyond reach + the blur's 4 sigma of every blot: work in their box only
    r = max(1, round(reach))
    box = _padded_box(blots, 3 * r + 2)
    # The membrane on a box 2 reach wider still: where that box cuts the structure, the
    # completed gaps under it stand in for the rim, and their effect fades within it.
    wide = _padded_box(blots, 5 * r + 2)
    spanned = seamless(np.zeros_like(gaps[wide]), gaps[wide], filled[wide], (0, 0), tol=1e-4, threads=threads)
    inner = tuple(slice(b.start - w.start, b.stop - w.start) for b, w in zip(box, wide, strict=True))
    base = np.asarray(spanned, np.float32).reshape(gaps[wide].shape)[inner]
    relief = canvas[box] - base
    with np.errstate(divide="ignore", invalid="ignore"):
        room = np.where(under[box], (base - lo) / -relief, np.where(over[box], (hi - base) / relief, np.float32(1.0)))
    need = np.clip(np.nan_to_num(room, nan=1.0), MIN_RELIEF_SCALE, 1.0).min(axis=2)
    need = np.where(blots[box], need, np.float32(1.0)).astype(np.float32)
    # a square's minimum (separable, so fast at large reach), then smoothed
    spread = cv2.erode(need, np.ones((2 * r + 1, 2 * r + 1), np.uint8), borderType=cv2.BORDER_REPLICATE)
    factor = cv2.GaussianBlur(spread, (0, 0), r / 2.0, borderType=cv2.BORDER_REPLICATE)
    fitted = base + factor[..., None] * relief
    _paste(res[box], fitted, filled[box] & (factor < 1.0))
    return _clip_channels(res, lo, hi)


def _padded_box(mask: NDArray[np.bool_], pad: int) -> tuple[slice, slice]:
    """The bounding box of ``mask``'s pixels, ``pad`` px wider on every side (within the image)."""
    ys, xs = np.nonzero(mask)
    H, W = mask.shape
    return (
        slice(max(0, int(ys.min()) - pad), min(H, int(ys.max()) + pad + 1)),
        slice(max(0, int(xs.min()) - pad), min(W, int(xs.max()) + pad + 1)),
    )


def _drop_foreign(canvas: F32, image: F32, source: Skeleton, target: Skeleton, lo: F32, hi: F32) -> F32:
    """A ``canvas`` snapped to the two levels ``lo``, ``hi`` of ``image``, holding the target
    structure's channels and nothing else.

    A fragment disk holds whatever lay around its source branch: on a braided river or a delta
    mask, pieces of neighbouring channels and of a cut coastline. The structure's level is the
    one the source structure mostly has in ``image``. Structure farther from the target than
    ``BAND`` of its radius (plus a pixel) is background; the target's tube at ``CORE`` of its
    radius is structure, so that a channel never breaks where two fragments meet; and a
    connected piece (8-neighbours) that does not meet the target's own mask is dropped.
    """
    mid = 0.5 * (lo + hi)
    up = float((image[source.mask()] >= mid).all(axis=-1).mean()) >= 0.5
    fore, back = (hi, lo) if up else (lo, hi)
    out: F32 = canvas.copy()
    fg: NDArray[np.bool_] = np.asarray((canvas >= mid if up else canvas < mid).all(axis=-1))
    fg &= _tube(target, _BAND, 1.0)
    fg |= _tube(target, _CORE, 0.0)
    n, comp = cv2.connectedComponents(fg.astype(np.uint8), connectivity=8)
    keep = np.zeros(n, bool)
    keep[np.unique(comp[target.mask() & fg])] = True
    fg &= keep[comp]
    out[fg] = fore
    out[~fg] = back
    return out


# Structure beyond 1.25 target radii (+1 px) is a neighbour's; the tube at 0.8 radii is the
# target's own (docs/pipelines/branching/quality.md: re-trace F1 on the river masks).
_BAND, _CORE = 1.25, 0.8


def _past_free_end(target: Skeleton, g: Fragment) -> bool:
    """Whether target fragment ``g``'s disk holds its branch's tip, or its start where the
    branch is a root (a child starts on its parent)."""
    b = target.branches[g.branch]
    return any(float(np.hypot(*(b.points[v] - g.center))) < g.radius for v in _free_ends(b))


def _own_tube(b: Branch, shape: tuple[int, int], origin: tuple[int, int]) -> NDArray[np.bool_]:
    """Branch ``b``'s tube (:data:`END_TUBE` times its thickness plus :data:`END_TUBE_ADD`) in
    the ``shape`` crop whose top-left pixel is ``origin`` (x, y).

    What lies past a source branch's end is whatever stopped its trace (a tangle of finer
    vessels, a crossing, the image's border); pasted at a target end, where the target has
    nothing, it stamped a star or a blob there.
    """
    h, w = shape
    off = np.asarray(origin, np.float64)
    r = np.minimum(END_TUBE * 0.5 * (b.thickness[:-1] + b.thickness[1:]) + END_TUBE_ADD, MAX_THICKNESS)
    p = b.points - off
    # Only the segments that can reach the crop: a branch is often far longer than a disk.
    lo, hi = np.minimum(p[:-1], p[1:]) - r[:, None], np.maximum(p[:-1], p[1:]) + r[:, None]
    near = np.nonzero((hi[:, 0] >= 0) & (hi[:, 1] >= 0) & (lo[:, 0] <= w) & (lo[:, 1] <= h))[0]
    m = np.zeros((h, w), np.uint8)
    for i in near:
        cv2.line(m, _pt(p[i]), _pt(p[i + 1]), 1, thickness=max(1, round(2 * r[i])), lineType=cv2.LINE_8, shift=4)
    return m.astype(bool)


def _tube(skeleton: Skeleton, factor: float, add: float) -> NDArray[np.bool_]:
    """``skeleton``'s mask with every radius ``r`` drawn as ``factor * r + add``."""
    wide = Skeleton(
        [
            Branch(b.points, np.minimum(b.thickness * factor + add, MAX_THICKNESS), parent=b.parent)
            for b in skeleton.branches
        ],
        skeleton.shape,
    )
    return wide.mask()


def _disk(shape: tuple[int, int], c: F64, r: float) -> tuple[slice, slice, NDArray[np.bool_], int, int]:
    """Crop around a disk (clipped to ``shape``) and the disk mask inside it."""
    h, w = shape
    x0, x1 = max(0, math.floor(c[0] - r)), min(w, math.ceil(c[0] + r) + 1)
    y0, y1 = max(0, math.floor(c[1] - r)), min(h, math.ceil(c[1] + r) + 1)
    yy, xx = np.mgrid[y0:y1, x0:x1]
    disk = (xx - c[0]) ** 2 + (yy - c[1]) ** 2 <= r * r
    return slice(y0, y1), slice(x0, x1), disk, y0, x0


def _reaches_out(f: Fragment, ok: NDArray[np.bool_]) -> bool:
    """Whether the disk of source fragment ``f`` holds a pixel outside ``ok``."""
    ys, xs, disk, _, _ = _disk(ok.shape, f.center, f.radius)
    return bool((disk & ~ok[ys, xs]).any())


#: Modified z-score above which a fragment's surroundings are an outlier (Iglewicz and Hoaglin).
SURROUNDINGS_Z = 3.5


def _unusual_surroundings(
    image: F32,
    channel_range: tuple[F32, F32],
    skeleton: Skeleton,
    frs: list[Fragment],
    excluded: NDArray[np.bool_],
    *,
    keep: int,
) -> NDArray[np.bool_]:
    """Source fragments whose surroundings are outliers among all fragments' surroundings.

    A fragment's surroundings are its disk's pixels off the structure (beyond ``1.5 r + 1`` of
    every branch). Two features, per channel: their median colour, and their slope (a plane
    fitted by least squares, as the change across the disk's radius). Each is compared with
    the other fragments' by the modified z-score ``(v − median) / (1.4826 MAD)``, the MAD at
    least 1 % of the channel's range: the colour both ways, the slope only upwards. A fragment
    above ``SURROUNDINGS_Z`` lies in a place unlike where the structure usually runs (on a
    fundus photo's optic disc, in its rim's shading, across another vessel): pasted at a
    branch start or end, where nothing painted yet constrains it, it stamps that place into the
    output. None are excluded if fewer than ``keep`` branch fragments would remain beside
    those ``excluded`` already.
    """
    if not frs:
        return np.zeros(0, bool)
    off = ~_tube(skeleton, 1.5, 1.0)
    h, w = image.shape[:2]
    n, c = len(frs), image.shape[2]
    level = np.empty((n, c), np.float64)
    slope = np.empty((n, c), np.float64)
    for i, f in enumerate(frs):
        ys, xs, disk, _, _ = _disk((h, w), f.center, f.radius)
        # about 16 samples across the disk are enough for a median and a plane
        st = max(1, int(f.radius) // 8)
        ys, xs, disk = slice(ys.start, ys.stop, st), slice(xs.start, xs.stop, st), disk[::st, ::st]
        m = disk & off[ys, xs]
        if m.sum() < 6:  # a plane needs a few pixels
            m = disk
        yy, xx = np.nonzero(m)
        yy, xx = yy * st, xx * st
        px = image[ys, xs][m].astype(np.float64)
        level[i] = np.median(px, axis=0)
        a = np.stack([xx - xx.mean(), yy - yy.mean(), np.ones(len(xx))], axis=1)
        coef = np.linalg.lstsq(a, px, rcond=None)[0]
        slope[i] = np.hypot(coef[0], coef[1]) * f.radius
    lo, hi = channel_range
    floor = 0.01 * (hi - lo).astype(np.float64)
    z_level, z_slope = _robust_z(level, floor), _robust_z(slope, floor)
    out = np.asarray((np.abs(z_level).max(axis=1) > SURROUNDINGS_Z) | (z_slope.max(axis=1) > SURROUNDINGS_Z))
    if sum(1 for f, o in zip(frs, out | excluded, strict=True) if not (o or f.furcation)) < keep:
        out[:] = False
    return out


#: How far past a fragment's thickness its cross-sections reach, in px: the background either
#: side of its edges.
EDGE_MARGIN = 4.0
#: Edge widths within this many pixels of each other are alike, however uniform the rest.
EDGE_FLOOR = 0.25


def _blurred_structure(image: F32, frs: list[Fragment], excluded: NDArray[np.bool_], *, keep: int) -> NDArray[np.bool_]:
    """Source fragments whose structure is far blurrier than the structure's usual.

    Across each sample of a fragment's own centre line, the profile from ``thickness +
    EDGE_MARGIN`` px on one side to as far on the other gives the structure's depth (the ends'
    mean against the middle) and its steepest slope; their ratio is the edge's width in pixels.
    A fragment whose median width is an outlier upwards (modified z-score over
    ``SURROUNDINGS_Z``, the spread at least ``EDGE_FLOOR`` px) shows something out of focus
    that the trace took for structure (a dish's blurred rim beside crisp vessels): pasted
    where the new structure is thick, it paints a smear. None are excluded if fewer than
    ``keep`` branch fragments would remain beside those ``excluded`` already.
    """
    if not frs:
        return np.zeros(0, bool)
    width = np.full(len(frs), np.nan)
    for i, f in enumerate(frs):
        n = len(f.points) // 2 if f.furcation else len(f.points)  # its own segment, not the child's
        if n < 3:
            continue
        p = f.points[:n] + f.center
        tan = np.gradient(p, axis=0)
        tan /= np.maximum(np.linalg.norm(tan, axis=1, keepdims=True), 1e-12)
        normal = np.stack([-tan[:, 1], tan[:, 0]], axis=1)
        reach = float(f.thickness[:n].max()) + EDGE_MARGIN
        steps = np.arange(-reach, reach + 1e-9, 0.5)
        pts = p[:, None, :] + steps[None, :, None] * normal[:, None, :]
        # the profiles' own channels averaged: a grey copy of the whole image costs more than this loop
        prof = cv2.remap(image, pts[..., 0].astype(np.float32), pts[..., 1].astype(np.float32),
                         cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101)  # fmt: skip
        prof = prof.reshape(*pts.shape[:2], -1).mean(axis=2)
        depth = np.abs((prof[:, 0] + prof[:, -1]) / 2 - prof[:, len(steps) // 2])
        slope = np.abs(np.diff(prof, axis=1)).max(axis=1) / 0.5
        ok = slope > 0
        if ok.any():
            width[i] = float(np.median(depth[ok] / slope[ok]))
    known = np.isfinite(width)
    out = np.zeros(len(frs), bool)
    if known.sum() >= 3:
        out[known] = _robust_z(width[known], EDGE_FLOOR) > SURROUNDINGS_Z
    if sum(1 for f, o in zip(frs, out | excluded, strict=True) if not (o or f.furcation)) < keep:
        out[:] = False
    return out


def _sample(img: F32, mapx: F32, mapy: F32) -> F32:
    # Bicubic: a vessel or a crack a pixel or two wide keeps its sharpness in a rotated fragment,
    # where bilinear sampling spreads it over its neighbours (docs/pipelines/branching/quality.md).
    out = _by_channels(
        lambda part: cv2.remap(part, mapx, mapy, interpolation=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT_101),
        img,
    )
    return np.ascontiguousarray(out, dtype=np.float32)


def _in_order(boxes: NDArray[np.int64], work: Callable[[int], None], *, workers: int, progress: Progress) -> None:
    """Run ``work(j)`` for every fragment ``j`` with the result of running them in order.

    ``work(j)`` reads and writes only inside ``boxes[j]`` (``y0, y1, x0, x1``, half-open), so
    it need only wait for the earlier fragments whose boxes meet its own; fragments that do not
    overlap (far apart on one branch, or on different branches) are painted at the same time
    on ``workers`` threads. The seam, Poisson and remap calls release the GIL.
    ``progress(done, n + 1)`` is called after each fragment, from the calling thread.
    """
    n = len(boxes)
    if workers <= 1 or n < 2:
        for j in range(n):
            work(j)
            if progress is not None:
                progress(j + 1, n + 1)
        return
    y0, y1, x0, x1 = boxes.T
    waiting = np.zeros(n, np.int64)
    after: list[list[int]] = [[] for _ in range(n)]
    for j in range(1, n):
        (before,) = np.nonzero((y0[:j] < y1[j]) & (y0[j] < y1[:j]) & (x0[:j] < x1[j]) & (x0[j] < x1[:j]))
        waiting[j] = len(before)
        for i in before.tolist():
            after[i].append(j)
    ready = [j for j in range(n) if waiting[j] == 0]  # ascending: already a heap
    running: dict[Future[None], int] = {}
    done = 0
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="phloem-render") as pool:
        while ready or running:
            # Lowest index first: the chain along a branch is the critical path.
            while ready and len(running) < workers:
                j = heapq.heappop(ready)
                running[pool.submit(work, j)] = j
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for fut in sorted(finished, key=running.__getitem__):
                j = running.pop(fut)
                fut.result()  # re-raises; the executor waits for the other running fragment
                done += 1
                if progress is not None:
                    progress(done, n + 1)
                for k in after[j]:
                    waiting[k] -= 1
                    if waiting[k] == 0:
                        heapq.heappush(ready, k)


def _branch_map(skeleton: Skeleton, shape: tuple[int, int]) -> NDArray[np.int32]:
    """Index of the branch whose structure (thickness plus 2 px) covers each pixel, else -1;
    children are drawn over their parents."""
    out = np.full(shape, -1, np.int32)
    h, w = shape
    for i, b in enumerate(skeleton.branches):
        r = np.maximum(0.5 * (b.thickness[:-1] + b.thickness[1:]), 0.5) + 2.0
        # Drawn in the branch's box only: a full-size mask per branch costs more than the lines.
        pad = float(r.max()) + 2.0
        x0, y0 = (max(0, math.floor(v - pad)) for v in b.points.min(axis=0))
        x1, y1 = math.ceil(b.points[:, 0].max() + pad) + 1, math.ceil(b.points[:, 1].max() + pad) + 1
        x1, y1 = min(w, x1), min(h, y1)
        m = np.zeros((y1 - y0, x1 - x0), np.uint8)
        off = np.array([x0, y0], np.float64)
        for a, bb, rr in zip(b.points[:-1] - off, b.points[1:] - off, r):
            cv2.line(m, _pt(a), _pt(bb), 1, thickness=min(max(1, round(2 * rr)), 32767), lineType=cv2.LINE_8, shift=4)
        out[y0:y1, x0:x1][m > 0] = i
    return out
