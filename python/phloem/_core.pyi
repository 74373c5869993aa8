# Hand-written stub of the native module; checked with `python -m mypy.stubtest phloem._core`.
# Every option is explicit: the defaults live in the Python modules that call these.
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

__version__: str
__all__ = [
    "__version__",
    "_after_fork_in_child",
    "by_numbers",
    "coherence_candidates",
    "default_threads",
    "density_stamp",
    "dist_columns",
    "emd",
    "emd_map",
    "fragment_maps",
    "grid_maxflow",
    "growth_choose",
    "guided_quilt",
    "histogram_moves",
    "interpolate_field",
    "knn",
    "mvc_combine",
    "mvc_warp",
    "mvc_weights",
    "nearest_colour",
    "nnf",
    "polyline_resample",
    "polylines_crossing",
    "seam",
    "seamless",
    "shape_layer_order",
    "shape_similarity",
    "shape_synthesize",
    "shape_synthesize_labels",
    "stroke_pair_energies",
    "stroke_pieces",
    "tbn_downsample",
    "tbn_upsample",
    "tps_register",
    "tps_sample",
    "turn_bins",
    "vote",
]

def nnf(
    source: NDArray[np.float32],
    target: NDArray[np.float32],
    *,
    patch_size: int,
    iterations: int,
    levels: int,
    exact: bool,
    seed: int,
    weights: NDArray[np.float32] | None,
    source_mask: NDArray[np.bool_] | None,
    target_mask: NDArray[np.bool_] | None,
    init: NDArray[np.int32] | None,
    source_knn: NDArray[np.int32] | None,
    source_cost: NDArray[np.float32] | None,
    threads: int | None,
    kdtree: bool,
    tileable: bool = False,
) -> tuple[NDArray[np.int32], NDArray[np.float32], int]: ...
def knn(
    exemplar: NDArray[np.float32],
    *,
    k: int,
    patch_size: int,
    iterations: int,
    exact: bool,
    exclude: int,
    seed: int,
    weights: NDArray[np.float32] | None,
    threads: int | None,
) -> tuple[NDArray[np.int32], NDArray[np.float32]]: ...
def coherence_candidates(
    refs: NDArray[np.int32],
    exemplar_shape: tuple[int, int],
    *,
    patch_size: int,
    wrap: bool,
    knn_idx: NDArray[np.int32] | None,
    threads: int | None,
) -> NDArray[np.int32]: ...
def by_numbers(
    exemplar: NDArray[np.float32],
    labels_in: NDArray[np.int32],
    labels_out: NDArray[np.int32],
    *,
    patch_size: int,
    k: int,
    label_weight: float,
    levels: int | None,
    iterations: int,
    init: str,
    wrap: bool,
    tileable: bool,
    seed: int,
    selection: str,
    composite: int,
    stand_in_weight: float,
    seam_channels: int,
    weights: NDArray[np.float32] | None,
    threads: int | None,
    progress: Callable[[int, int], object] | None,
) -> NDArray[np.int32]: ...
def tbn_upsample(
    refs: NDArray[np.int32], out_shape: tuple[int, int], exemplar_shape: tuple[int, int], *, wrap: bool
) -> NDArray[np.int32]: ...
def tbn_downsample(refs: NDArray[np.int32], exemplar_shape: tuple[int, int]) -> NDArray[np.int32]: ...
def vote(
    source: NDArray[np.float32],
    field: NDArray[np.int32],
    *,
    patch_size: int,
    weights: NDArray[np.float32] | None,
    threads: int | None,
    mean_shift: int,
    pixels: NDArray[np.bool_] | None,
    tileable: bool = False,
) -> tuple[NDArray[np.float32], NDArray[np.float32]]: ...
def seamless(
    src: NDArray[np.float32],
    dst: NDArray[np.float32],
    mask: NDArray[np.bool_],
    offset: tuple[int, int],
    *,
    mixed: bool,
    tol: float,
    max_iterations: int,
    fixed: NDArray[np.bool_] | None,
    threads: int | None,
    labels: NDArray[np.int32] | None = None,
) -> tuple[NDArray[np.float32], int, float]: ...
def interpolate_field(
    region: NDArray[np.bool_],
    points: NDArray[np.int64],
    values: NDArray[np.float64],
    *,
    tol: float,
    max_iterations: int,
    threads: int | None,
) -> tuple[NDArray[np.float32], int, float]: ...
def fragment_maps(
    disk: NDArray[np.bool_],
    origin: tuple[int, int],
    centre: tuple[float, float],
    points: NDArray[np.float64],
    displacement: NDArray[np.float64],
    radius: float,
    rigid: NDArray[np.float64],
    source_centre: tuple[float, float],
) -> tuple[NDArray[np.float32], NDArray[np.float32], float]: ...
def mvc_weights(
    polygon: NDArray[np.float64], points: NDArray[np.float64], *, threads: int | None
) -> NDArray[np.float64]: ...
def mvc_warp(
    sources: Sequence[NDArray[np.float32]],
    source_contours: Sequence[NDArray[np.float64]],
    target_contour: NDArray[np.float64],
    size: tuple[int, int],
    *,
    region: NDArray[np.bool_] | None,
    threads: int | None,
) -> list[NDArray[np.float32]]: ...
def mvc_combine(
    sources: Sequence[NDArray[np.float32]],
    source_contours: Sequence[NDArray[np.float64]],
    target_contour: NDArray[np.float64],
    weights: NDArray[np.float64],
    size: tuple[int, int],
    *,
    region: NDArray[np.bool_] | None,
    threads: int | None,
) -> NDArray[np.float32]: ...
def emd_map(
    labels: NDArray[np.int32],
    ground: NDArray[np.float64],
    target: NDArray[np.float64],
    *,
    window: int,
    threads: int | None,
) -> NDArray[np.float32]: ...
def dist_columns(cols: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]: ...
def histogram_moves(
    u: NDArray[np.float64], uu: float, now: float, n: float, bins: NDArray[np.int64]
) -> NDArray[np.float64]: ...
def turn_bins(turns: NDArray[np.float64], bins: int) -> NDArray[np.int64]: ...
def polyline_resample(
    points: NDArray[np.float64], cum: NDArray[np.float64], count: int, h: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...
def polylines_crossing(paths: NDArray[np.float64], segments: NDArray[np.float64]) -> NDArray[np.bool_]: ...
def growth_choose(
    quality: NDArray[np.float64],
    relative: NDArray[np.float64],
    ray_of: NDArray[np.int64],
    tip: tuple[float, float],
    cos: float,
    sin: float,
    height: int,
    width: int,
    directions: NDArray[np.float64],
    length: float,
    samples: int,
    density: tuple[NDArray[np.float32], NDArray[np.int32], NDArray[np.int32]] | None,
    skip: tuple[int, int, int, float] | None,
    border_rho: float | None,
    guide: NDArray[np.float64] | None,
    segments: NDArray[np.float64],
    count: int,
    eps: float,
) -> tuple[NDArray[np.int64], NDArray[np.float64]]: ...
def density_stamp(
    density: NDArray[np.float32],
    owner_branch: NDArray[np.int32],
    owner_vertex: NDArray[np.int32],
    points: NDArray[np.float64],
    thickness: NDArray[np.float64],
    branch: int,
    first: int,
    rho: float,
) -> float: ...
def emd(hist_a: NDArray[np.float64], hist_b: NDArray[np.float64], ground: NDArray[np.float64]) -> float: ...
def nearest_colour(
    points: NDArray[np.float32],
    centres: NDArray[np.float32],
    norms: NDArray[np.float32],
    *,
    threads: int | None,
) -> NDArray[np.int32]: ...
def tps_register(
    fixed_points: NDArray[np.float64],
    moving_points: NDArray[np.float64],
    fixed_mask: NDArray[np.bool_],
    moving_mask: NDArray[np.bool_],
    *,
    rate: float,
    iterations: int,
    final_ratio: float,
    lambda1: float,
    lambda2: float,
    step: int,
    threads: int | None,
) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.int64], NDArray[np.float64], int, float]: ...
def tps_sample(
    image: NDArray[np.float32], field: NDArray[np.float32], *, threads: int | None
) -> NDArray[np.float32]: ...

# correction
def guided_quilt(
    target: NDArray[np.float32],
    source: NDArray[np.float32],
    hole: NDArray[np.bool_],
    field: NDArray[np.float32],
    *,
    block: int,
    rim: int,
    radius: int,
    bias: float,
    alpha_known: bool,
) -> NDArray[np.int32]: ...
def default_threads() -> int: ...
def _after_fork_in_child() -> None: ...
def grid_maxflow(
    source: NDArray[np.float32],
    sink: NDArray[np.float32],
    edges: NDArray[np.float32],
    *,
    connectivity: int,
    directed: bool,
    threads: int | None,
    method: str,
) -> tuple[float, NDArray[np.bool_], str]: ...
def seam(
    a: NDArray[np.float32],
    b: NDArray[np.float32],
    region: NDArray[np.bool_],
    *,
    cost: str,
    connectivity: int,
    border_weight: float | None,
    a_mask: NDArray[np.bool_] | None,
    b_mask: NDArray[np.bool_] | None,
    seeds: NDArray[np.uint8] | None,
    edges: NDArray[np.float32] | None,
    threads: int | None,
) -> tuple[NDArray[np.bool_], float, tuple[int, int]]: ...
def shape_synthesize(
    shape: NDArray[np.uint8],
    *,
    height: int,
    width: int,
    patch_size: int,
    levels: int,
    iterations: int,
    rotations: int,
    tileable: bool,
    seed: int,
    mask: NDArray[np.bool_] | None,
    threads: int | None,
    progress: Callable[[int, int], object] | None,
) -> NDArray[np.uint8]: ...
def shape_synthesize_labels(
    labels: NDArray[np.uint8],
    *,
    k: int,
    height: int,
    width: int,
    method: str,
    patch_size: int,
    levels: int,
    iterations: int,
    rotations: int,
    tileable: bool,
    seed: int,
    order: Sequence[int] | None,
    threads: int | None,
    progress: Callable[[int, int], object] | None,
) -> NDArray[np.uint8]: ...
def shape_similarity(
    a: NDArray[np.uint8], b: NDArray[np.uint8], *, patch_size: int, rotations: int, threads: int | None
) -> float: ...
def shape_layer_order(labels: NDArray[np.uint8], *, k: int) -> list[int]: ...
def stroke_pieces(
    source: NDArray[np.float32],
    specs: NDArray[np.float64],
    *,
    threads: int | None,
) -> list[tuple[tuple[int, int], NDArray[np.float32], NDArray[np.bool_], tuple[float, float]]]: ...
def stroke_pair_energies(
    source: NDArray[np.float32],
    specs: NDArray[np.float64],
    pairs: NDArray[np.int64],
    *,
    threads: int | None,
) -> list[float]: ...
