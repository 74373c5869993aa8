"""Stroke-based editing against Ebsynth (issue 18): one object re-drawn along three new strokes.

What it measures
----------------
A bark "branch" (a 48 px wide strip of the embedded Douglas-fir bark, shaded like a cylinder,
on a transparent background, 256×96) is re-drawn in a 512×512 output along three target
strokes: a bent main branch (483 px, fed by the whole 244 px source stroke) and two side
branches leaving it (221 and 187 px, each fed by the top 60% of the source stroke).

* phloem  ``phloem.strokes.edit(source_rgba, sources, targets, size=(512, 512), threads=T)``
* Ebsynth (github.com/jamriska/ebsynth, CPU backend, built from source for this benchmark only)
  ``ebsynth -style source.png -guide src_guide.png tgt_guide.png -output out.png -backend cpu``
  with its default weights, patch size 5 and uniformity, threads through ``OMP_NUM_THREADS``.
  The style is the RGBA source, so Ebsynth synthesises the alpha too.

Ebsynth knows nothing of strokes, so it is driven by guide images in stroke coordinates, as
one would drive it for this task: in the source, each object pixel holds (R) its arc-length
fraction along the strip's centre line, (G) its signed distance across it divided by the
half width, and (B) 255; in the target, each pixel within the half width of a target stroke
holds the same for its nearest target stroke, its arc fraction mapped to the source position
that stroke pair uses (the same linear mapping phloem's ``sampling="uniform"`` uses), and
everything else, in both, is the background guide (0, 0, 0). Building the guides is not timed.

Reported per tool and thread count: wall time (best over the rounds, and the range; for
Ebsynth it includes process start and its PNG reading and writing), the least CPU time of a
run (all threads; less sensitive to a busy machine than wall time), and, all on the colour
over black:

* patch coherence ``phloem.metrics.patch_coherence(out_rgb, source_rgb, mask=...)`` (lower:
  more of the output's 7×7 patches occur in the source) on the tool's own object pixels
  (alpha > 0.5), and on the pixels both tools cover inside the target mask; the latter also
  against the source turned every 15° from −90° to 90° (a turned patch is what a stroke that
  bends asks for, so that variant does not count turning as incoherence);
* alignment: how far the texture's lines (structure tensor of the gray image) run along the
  nearest target stroke, 1 along, 0 no preference, −1 across (the source strip scores its
  own value against its centre line);
* stroke coverage (the target centre-line points where alpha ≥ 0.5), mask coverage (the same
  over the target mask: pixels within the half width of a target stroke, cut flat at its
  ends) and spill (the share of the object pixels outside that mask).

Rounds run the configurations one after another, so a change of load hits every tool; the
load average is logged per round. ``--ebsynth-args`` passes extra options (e.g. fewer
iterations) to Ebsynth. ``--out-dir`` saves the source, both guides, each result (RGBA and on
black) and ``side_by_side.png``.

Usage
-----
::

    python3 benches/peers/strokes_ebsynth.py --ebsynth /tmp/ebsynth/bin/ebsynth --out-dir /tmp/strokes-vs-ebsynth
    PHLOEM_EBSYNTH=/path/to/ebsynth python3 benches/peers/strokes_ebsynth.py --rounds 5

Ebsynth is found through ``--ebsynth``, ``PHLOEM_EBSYNTH`` or ``ebsynth`` on the PATH;
without it only phloem runs. Build it with its ``build-linux-cpu_only.sh`` (g++ -fopenmp).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

SIZE = 512
HALF_WIDTH = 24.0  # the source strip's half width, px
F32 = NDArray[np.float32]


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def loadavg() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "?"


# --------------------------------------------------------------------------- the case


def source_branch() -> tuple[F32, NDArray[np.float64]]:
    """The RGBA bark strip (256×96, opaque inside columns 24..71) and its centre line, bottom to top."""
    import phloem

    bark = phloem.data.bark()[:, :, :3]
    h, w, x0 = 256, 96, 24
    img = np.zeros((h, w, 4), np.float32)
    strip = bark[:, 104 : 104 + 2 * int(HALF_WIDTH)]
    # Cylinder shading gives the strip an across-structure a synthesis has to keep.
    s = (np.arange(strip.shape[1]) + 0.5 - HALF_WIDTH) / HALF_WIDTH
    shade = 0.45 + 0.55 * np.sqrt(1.0 - s**2)
    img[2:-2, x0 : x0 + strip.shape[1], :3] = strip[2:-2] * shade[None, :, None]
    img[2:-2, x0 : x0 + strip.shape[1], 3] = 1.0
    # Pixel centres sit at integer coordinates, so columns x0 .. x0 + 47 are centred on x0 + 23.5.
    mid = x0 + HALF_WIDTH - 0.5
    centre = np.array([[mid, h - 6.0], [mid, 6.0]])
    return img, centre


def bezier(p0: Any, p1: Any, p2: Any, n: int = 40) -> NDArray[np.float64]:
    t = np.linspace(0.0, 1.0, n)[:, None]
    a, b, c = (np.asarray(p, np.float64) for p in (p0, p1, p2))
    return np.asarray((1 - t) ** 2 * a + 2 * (1 - t) * t * b + t**2 * c)


def strokes(centre: NDArray[np.float64]) -> tuple[list[NDArray[np.float64]], list[NDArray[np.float64]]]:
    """Source and target strokes: the whole strip along a bent main branch, and its top 60% along
    two side branches that start on the main one."""
    main = bezier((250, 500), (150, 300), (300, 40))
    fork_a, fork_b = main[16], main[24]
    side_a = bezier(fork_a, fork_a + (90, -30), fork_a + (190, -110), 24)
    side_b = bezier(fork_b, fork_b + (-60, -30), fork_b + (-120, -140), 24)
    top = np.array([centre[0] + 0.4 * (centre[1] - centre[0]), centre[1]])
    return [centre, top, top], [main, side_a, side_b]


# --------------------------------------------------------------------------- stroke coordinates


def _dense(stroke: NDArray[np.float64], step: float = 0.5) -> tuple[NDArray[np.float64], ...]:
    """Points every ``step`` px along a polyline, their arc fractions and unit tangents."""
    seg = np.diff(stroke, axis=0)
    cum = np.r_[0.0, np.cumsum(np.hypot(seg[:, 0], seg[:, 1]))]
    arc = np.linspace(0.0, cum[-1], max(2, math.ceil(cum[-1] / step) + 1))
    pts = np.c_[np.interp(arc, cum, stroke[:, 0]), np.interp(arc, cum, stroke[:, 1])]
    tan = np.gradient(pts, axis=0)
    tan /= np.hypot(tan[:, 0], tan[:, 1])[:, None]
    return pts, arc / cum[-1], tan


@dataclasses.dataclass(frozen=True)
class Coordinates:
    """Per pixel, about its nearest point on a set of strokes."""

    frac: F32  # arc-length fraction along that stroke
    across: F32  # signed distance across it, px
    dist: F32  # distance to it, px
    capped: NDArray[np.bool_]  # the nearest point is an end and the pixel lies beyond it
    owner: NDArray[np.int32]  # which stroke
    tangent: F32  # (..., 2) its unit direction (x, y)


def stroke_coordinates(shape: tuple[int, int], lines: list[NDArray[np.float64]]) -> Coordinates:
    from scipy.spatial import cKDTree

    parts = [_dense(s) for s in lines]
    pts = np.concatenate([p for p, _, _ in parts])
    frac = np.concatenate([f for _, f, _ in parts])
    tan = np.concatenate([t for _, _, t in parts])
    owner = np.concatenate([np.full(len(p), i) for i, (p, _, _) in enumerate(parts)])
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]]
    pix = np.c_[xx.ravel() + 0.0, yy.ravel() + 0.0]
    dist, k = cKDTree(pts).query(pix)
    rel = pix - pts[k]
    across = tan[k, 0] * rel[:, 1] - tan[k, 1] * rel[:, 0]
    along = tan[k, 0] * rel[:, 0] + tan[k, 1] * rel[:, 1]

    def grid(a: NDArray[Any], dtype: Any) -> NDArray[Any]:
        return np.asarray(a.reshape(shape).astype(dtype))

    return Coordinates(
        frac=grid(frac[k], np.float32),
        across=grid(across, np.float32),
        dist=grid(dist, np.float32),
        capped=grid(np.abs(along) > 1.0, bool),
        owner=grid(owner[k], np.int32),
        tangent=np.asarray(tan[k].reshape(*shape, 2).astype(np.float32)),
    )


def guides(
    source_alpha: F32, source: list[NDArray[np.float64]], target: Coordinates
) -> tuple[NDArray[np.uint8], NDArray[np.uint8], NDArray[np.bool_]]:
    """Ebsynth's source and target guides (RGB uint8) and the target mask (within the half
    width of a target stroke, cut flat at its ends)."""
    centre = source[0]
    length = float(np.hypot(*(centre[-1] - centre[0])))

    def encode(frac: F32, across: F32, inside: NDArray[np.bool_]) -> NDArray[np.uint8]:
        g = np.zeros((*frac.shape, 3), np.uint8)
        g[..., 0] = np.round(np.clip(frac, 0, 1) * 255)
        g[..., 1] = np.round(np.clip(128 + 127 * across / HALF_WIDTH, 0, 255))
        g[..., 2] = 255
        g[~inside] = 0
        return g

    sc = stroke_coordinates((source_alpha.shape[0], source_alpha.shape[1]), [centre])
    src = encode(sc.frac, sc.across, source_alpha > 0.5)
    # A target arc fraction stands for the point of the strip its pair's source stroke has there.
    starts = np.array([float(np.hypot(*(s[0] - centre[0]))) / length for s in source])
    ends = np.array([float(np.hypot(*(s[-1] - centre[0]))) / length for s in source])
    o = target.owner
    sfrac = (starts[o] + target.frac * (ends[o] - starts[o])).astype(np.float32)
    inside = (target.dist <= HALF_WIDTH) & ~target.capped
    return src, encode(sfrac, target.across, inside), inside


# --------------------------------------------------------------------------- tools


def find_ebsynth(given: str | None) -> str | None:
    for cand in (given, os.environ.get("PHLOEM_EBSYNTH"), shutil.which("ebsynth")):
        if cand and Path(cand).is_file() and os.access(cand, os.X_OK):
            return cand
    return None


def write_png(path: Path, image: NDArray[Any]) -> None:
    import cv2

    a = np.asarray(image)
    if a.dtype != np.uint8:
        a = np.round(np.clip(a, 0, 1) * 255).astype(np.uint8)
    code = {3: cv2.COLOR_RGB2BGR, 4: cv2.COLOR_RGBA2BGRA}[a.shape[2]]
    cv2.imwrite(str(path), cv2.cvtColor(a, code))


def read_png(path: Path) -> F32:
    import cv2

    a = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if a is None:
        raise RuntimeError(f"{path}: not written")
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=2)
    rgba = cv2.cvtColor(a, cv2.COLOR_BGRA2RGBA if a.shape[2] == 4 else cv2.COLOR_BGR2RGBA)
    return np.asarray(rgba, np.float32) / 255.0


def _cpu(who: int) -> float:
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


def run_phloem(src: F32, source: list[Any], target: list[Any], threads: int, sampling: str) -> F32:
    import phloem

    out = phloem.strokes.edit(src, source, target, size=(SIZE, SIZE), threads=threads, sampling=sampling)
    return np.asarray(out)


def run_ebsynth(binary: str, work: Path, threads: int, extra: list[str]) -> F32:
    out = work / f"ebsynth_t{threads}.png"
    cmd = [binary, "-style", str(work / "source.png"), "-guide", str(work / "src_guide.png"),
           str(work / "tgt_guide.png"), "-output", str(out), "-backend", "cpu", *extra]  # fmt: skip
    env = {**os.environ, "OMP_NUM_THREADS": str(threads)}
    proc = subprocess.run(cmd, check=False, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        raise RuntimeError(f"ebsynth exited {proc.returncode}: {(proc.stdout + proc.stderr).strip()[-300:]}")
    return read_png(out)


# --------------------------------------------------------------------------- scoring


@dataclasses.dataclass
class Row:
    tool: str
    threads: int
    variant: str = ""  # phloem's sampling, or Ebsynth's extra arguments
    times: list[float] = dataclasses.field(default_factory=list)
    cpu: list[float] = dataclasses.field(default_factory=list)  # CPU seconds, all threads
    output: F32 | None = None
    metrics: dict[str, float] = dataclasses.field(default_factory=dict)


def rotated_sources(src_rgb: F32, step: float = 15.0) -> F32:
    """The source turned by every ``step`` degrees from -90 to 90, side by side on black: an
    exemplar for coherence that does not count turning a patch as incoherence."""
    import cv2

    h, w = src_rgb.shape[:2]
    side = math.ceil(math.hypot(h, w)) + 8
    tiles = []
    for angle in np.arange(-90.0, 90.0 + 1e-6, step):
        canvas = np.zeros((side, side, 3), np.float32)
        y0, x0 = (side - h) // 2, (side - w) // 2
        canvas[y0 : y0 + h, x0 : x0 + w] = src_rgb
        rot = cv2.getRotationMatrix2D((side / 2, side / 2), float(angle), 1.0)
        tiles.append(cv2.warpAffine(canvas, rot, (side, side), flags=cv2.INTER_LINEAR))
    return np.ascontiguousarray(np.concatenate(tiles, axis=1))


def alignment(rgb: F32, mask: NDArray[np.bool_], tangent: F32) -> float:
    """How far the texture's lines run along the strokes: the mean over ``mask`` (eroded by 8 px,
    off the object's outline) of cos 2(θ_lines − θ_stroke), weighted by the structure tensor's
    anisotropy; 1 along, 0 no preference, −1 across."""
    import cv2
    from scipy import ndimage

    gray = cv2.GaussianBlur(rgb @ np.array([0.299, 0.587, 0.114], np.float32), (0, 0), 1.0)
    gx = cv2.Sobel(gray, cv2.CV_32F, 1, 0)
    gy = cv2.Sobel(gray, cv2.CV_32F, 0, 1)
    jxx, jyy, jxy = (cv2.GaussianBlur(a, (0, 0), 3.0) for a in (gx * gx, gy * gy, gx * gy))
    # Doubled angles: the gradient's is 2θ_g = atan2(2 jxy, jxx − jyy); lines run at θ_g + 90°.
    c_g, s_g = jxx - jyy, 2 * jxy
    tx, ty = tangent[..., 0], tangent[..., 1]
    c_t, s_t = tx * tx - ty * ty, 2 * tx * ty
    agree = -(c_g * c_t + s_g * s_t)  # anisotropy × cos 2(θ_lines − θ_stroke)
    weight = np.hypot(c_g, s_g)
    m = ndimage.binary_erosion(mask, iterations=8)
    return float(agree[m].sum() / max(float(weight[m].sum()), 1e-12))


def score(out: F32, ctx: dict[str, Any]) -> dict[str, float]:
    import phloem

    alpha = out[..., 3]
    rgb = np.ascontiguousarray(out[..., :3] * alpha[..., None])
    own = alpha > 0.5
    target_mask, ij = ctx["target_mask"], ctx["centre_ij"]
    return {
        "coherence_own": phloem.metrics.patch_coherence(rgb, ctx["src_rgb"], mask=own),
        "coherence_common": phloem.metrics.patch_coherence(rgb, ctx["src_rgb"], mask=ctx["common"]),
        "coherence_turned": phloem.metrics.patch_coherence(rgb, ctx["turned"], mask=ctx["common"]),
        "alignment": alignment(rgb, own & target_mask, ctx["tangent"]),
        "stroke_coverage": float((alpha[ij[:, 1], ij[:, 0]] >= 0.5).mean()),
        "mask_coverage": float((alpha[target_mask] >= 0.5).mean()),
        "spill": float((own & ~target_mask).sum() / max(1, own.sum())),
    }


COLUMNS = [("coherence_own", ".5f"), ("coherence_common", ".5f"), ("coherence_turned", ".5f"),
           ("alignment", ".3f"), ("stroke_coverage", ".3f"), ("mask_coverage", ".3f"), ("spill", ".3f")]  # fmt: skip


def markdown(rows: list[Row], reference_alignment: float) -> str:
    head = ("| tool | threads | best s | range s | CPU s | coherence (own) | coherence (common) | coherence "
            "(common, turned source) | alignment | stroke coverage | mask coverage | spill |")  # fmt: skip
    lines = [head, "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        t = f"{min(r.times):.3f} | {min(r.times):.3f}–{max(r.times):.3f} | {min(r.cpu):.3f}" if r.times else "- | - | -"
        q = " | ".join(format(r.metrics[k], f) if k in r.metrics else "-" for k, f in COLUMNS)
        name = f"{r.tool} ({r.variant})" if r.variant else r.tool
        lines.append(f"| {name} | {r.threads} | {t} | {q} |")
    lines.append(f"| source strip itself | | | | | 0 | | | {reference_alignment:.3f} | | | |")
    return "\n".join(lines)


# --------------------------------------------------------------------------- main


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--ebsynth", metavar="PATH", help="the ebsynth binary (default: PHLOEM_EBSYNTH, PATH)")
    parser.add_argument("--ebsynth-args", default="", metavar="ARGS", help="extra ebsynth options, one string")
    parser.add_argument("--rounds", type=int, default=3, help="timed runs per configuration (default 3)")
    parser.add_argument("--threads", type=int, nargs="+", default=[2, 1], help="thread counts (default 2 1)")
    parser.add_argument("--out-dir", metavar="DIR", help="save the inputs, guides and results as PNG here")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    src, centre = source_branch()
    source, target = strokes(centre)
    binary = find_ebsynth(args.ebsynth)
    if binary is None:
        log("skipping ebsynth: not found; pass --ebsynth PATH or set PHLOEM_EBSYNTH (build-linux-cpu_only.sh)")
    start = time.perf_counter()
    tc = stroke_coordinates((SIZE, SIZE), target)
    src_guide, tgt_guide, target_mask = guides(src[..., 3], source, tc)
    log(f"guides built in {time.perf_counter() - start:.2f} s (untimed)")
    extra = args.ebsynth_args.split()

    rows = [Row("phloem", t) for t in args.threads] + [Row("phloem", args.threads[0], "uniform")]
    if binary is not None:
        rows += [Row("ebsynth", t, " ".join(extra)) for t in args.threads]
    with tempfile.TemporaryDirectory(prefix="strokes-ebsynth-") as tmp:
        work = Path(tmp)
        write_png(work / "source.png", src)
        write_png(work / "src_guide.png", src_guide)
        write_png(work / "tgt_guide.png", tgt_guide)
        for k in range(args.rounds):
            log(f"round {k + 1}/{args.rounds}, load {loadavg()}")
            for row in rows:
                who = resource.RUSAGE_SELF if row.tool == "phloem" else resource.RUSAGE_CHILDREN
                c0, t0 = _cpu(who), time.perf_counter()
                if row.tool == "phloem":
                    out = run_phloem(src, source, target, row.threads, row.variant or "dp")
                else:
                    assert binary is not None
                    out = run_ebsynth(binary, work, row.threads, extra)
                row.times.append(time.perf_counter() - t0)
                row.cpu.append(_cpu(who) - c0)
                row.output = out if row.output is None else row.output
                log(f"  {row.tool} {row.variant} threads={row.threads}: {row.times[-1]:.3f} s, cpu {row.cpu[-1]:.3f} s")
        out_dir = Path(args.out_dir) if args.out_dir else None
        if out_dir is not None:
            out_dir.mkdir(parents=True, exist_ok=True)
            for name in ("source.png", "src_guide.png", "tgt_guide.png"):
                shutil.copy(work / name, out_dir / name)
    load_after = loadavg()

    src_rgb = np.ascontiguousarray(src[..., :3] * src[..., 3:])
    common = target_mask.copy()
    for row in rows:
        if row.tool != "phloem" or not row.variant:
            assert row.output is not None
            common &= row.output[..., 3] > 0.5
    ij = np.round(np.concatenate([_dense(s, 1.0)[0] for s in target])).astype(int)
    ij = ij[(ij[:, 0] >= 0) & (ij[:, 0] < SIZE) & (ij[:, 1] >= 0) & (ij[:, 1] < SIZE)]
    ctx = {"src_rgb": src_rgb, "turned": rotated_sources(src_rgb), "target_mask": target_mask,
           "common": common, "centre_ij": ij, "tangent": tc.tangent}  # fmt: skip
    for row in rows:
        assert row.output is not None
        row.metrics = score(row.output, ctx)
    vertical = np.zeros((*src.shape[:2], 2), np.float32)
    vertical[..., 1] = 1.0
    reference = alignment(src_rgb, src[..., 3] > 0.5, vertical)
    if out_dir is not None:
        for row in rows:
            if row.threads == args.threads[0] and row.output is not None:
                name = f"{row.tool}_{row.variant}" if row.tool == "phloem" and row.variant else row.tool
                write_png(out_dir / f"{name}.png", row.output)
                black = row.output[..., :3] * row.output[..., 3:]
                write_png(out_dir / f"{name}_on_black.png", black.astype(np.float32))
        shown = [r.output for r in rows if r.threads == args.threads[0] and r.output is not None]
        gap = np.ones((SIZE, 8, 3), np.float32)
        side = [x for o in shown for x in (o[..., :3] * o[..., 3:], gap)][:-1]
        write_png(out_dir / "side_by_side.png", np.concatenate(side, axis=1))
        log(f"images in {out_dir}")
    print(f"strokes: {SIZE}x{SIZE} output, 3 strokes, source 256x96 bark strip; load after {load_after}")
    print(f"ebsynth: {binary or 'not found'} {' '.join(extra)}")
    print(markdown(rows, reference))
    return 0


if __name__ == "__main__":
    sys.exit(main())
