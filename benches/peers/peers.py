"""Side-by-side benchmark of phloem against peer tools, in one run on one machine.

What it measures
----------------
1. **Completion** (hole filling). A 512×512 RGB photo with a 96×96 square hole in the
   middle (``skimage_coffee.png`` centre-cropped and resized, and the embedded bark
   upscaled with ``cv2.INTER_CUBIC``), filled by

   * phloem      ``phloem.texture.complete(image, mask, seed=0)``  (mask True = fill)
   * PatchMatch  ``patchmatch.inpaint(image_u8, mask_u8, patch_size=3)``  (PyPI
     ``PyPatchMatch``; mask non-zero = fill; ``patch_size`` is a radius, so 3 gives the
     same 7×7 patches as phloem's default)
   * Resynthesizer  ``resynthesizer.resynthesize(pil_image, pil_mask, params)``  (PyPI
     ``resynthesizer``; mask non-zero = fill; default parameters with the seamless-tiling
     flags off, as GIMP's "Heal selection" does)

   Every tool gets the same 8-bit image with the hole blacked out. Reported: wall time
   (best of 3 runs, a single run when one takes over 20 s), mean absolute error inside
   the hole against the original (0–1 scale; a plausible fill need not match the original,
   so read it as a coarse guide), and the *local contrast ratio*: the mean gray standard
   deviation of 7×7 windows inside the hole (sampled on a grid) of the result divided by
   that of the original. About 1 is right; a blurred fill scores low.

2. **Synthesis**. A 512×512 texture from each exemplar (the embedded bark, 256×256;
   ``tests/data/water.jpg``, 300×300; ``skimage_gravel.png`` centre-cropped to 200×200,
   gray replicated to RGB), made by

   * phloem  ``phloem.texture.synthesize(exemplar, (512, 512), seed=0, threads=2)``
   * texture-synthesis (Embark, crates.io ``texture-synthesis-cli``)
     ``texture-synthesis --out OUT.png --out-size 512 --threads 2 --seed 0 --no-progress
     generate EXEMPLAR.png``; the timing includes process start and the CLI's own PNG
     reading and writing (best of 2 runs).

   Reported: wall time, ``phloem.metrics.repetition(output)`` (about 0.9 or more: the
   output tiles itself; compare with the exemplar's own) and
   ``phloem.metrics.patch_coherence(output, exemplar)`` (lower is
   better), the same metric for both tools. Both get the same 8-bit exemplar.

3. **Ratios**: ``t_phloem / t_peer`` per case and its geometric mean per workload
   (below 1: phloem is faster).

Peers are benchmark-only. A peer that is not installed is skipped with a message; install
them with ``pip install PyPatchMatch resynthesizer`` and ``cargo install
texture-synthesis-cli``. PatchMatch and Resynthesizer run single-threaded; phloem's
``complete`` uses its default thread count (``PHLOEM_NUM_THREADS`` or all cores).

Usage
-----
::

    python3 benches/peers/peers.py                 # full sizes (a few minutes on 2 cores)
    python3 benches/peers/peers.py --quick         # 256 images, 48 hole, fewer runs: a smoke test
    python3 benches/peers/peers.py --json out.json # also write every figure as JSON

Timings are only comparable within one run on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[2]
# The optional real-image collection, found as phloem.testing.shared_data() finds it.
SHARED = Path(os.environ.get("PHLOEM_SHARED_DATA") or REPO.parent / "shared" / "data")
COFFEE = SHARED / "strokes" / "skimage_coffee.png"
WATER = REPO / "tests" / "data" / "water.jpg"
GRAVEL = SHARED / "textures" / "skimage_gravel.png"

CompletionTool = Callable[[np.ndarray, np.ndarray], np.ndarray]  # (damaged u8, mask) -> float
SynthesisTool = Callable[[np.ndarray, int], Callable[[], np.ndarray]]  # (u8, side) -> job

SLOW_RUN_S = 20.0  # after a first run slower than this, don't repeat
CONTRAST_WINDOW = 7
CONTRAST_STRIDE = 4


@dataclasses.dataclass(frozen=True)
class Config:
    image_size: int  # completion images are image_size × image_size
    hole: int  # side of the square hole
    synth_size: int  # synthesis outputs are synth_size × synth_size
    complete_runs: int  # best of this many (fewer when a run is slow)
    synth_runs: int


FULL = Config(image_size=512, hole=96, synth_size=512, complete_runs=3, synth_runs=2)
QUICK = Config(image_size=256, hole=48, synth_size=256, complete_runs=2, synth_runs=1)


@dataclasses.dataclass
class Result:
    workload: str  # "completion" or "synthesis"
    case: str  # image or exemplar name
    tool: str
    time_s: float | None = None
    runs: int = 0
    metrics: dict[str, float] = dataclasses.field(default_factory=dict)
    error: str | None = None


# --------------------------------------------------------------------------- helpers


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def to_u8(image: np.ndarray) -> np.ndarray:
    return np.asarray((np.clip(image, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8))


def to_float(image: np.ndarray) -> np.ndarray:
    return image.astype(np.float32) / 255.0


def to_rgb(image: np.ndarray) -> np.ndarray:
    """Gray → 3 equal channels; drop alpha."""
    if image.ndim == 2:
        return np.repeat(image[..., None], 3, axis=2)
    return image[..., :3]


def resize(image: np.ndarray, size: int) -> np.ndarray:
    import cv2

    if image.shape[:2] == (size, size):
        return image
    interp = cv2.INTER_CUBIC if size > image.shape[0] else cv2.INTER_AREA
    out = cv2.resize(image, (size, size), interpolation=interp)
    return np.asarray(np.clip(out, 0.0, 1.0))


def center_crop(image: np.ndarray, side: int | None = None) -> np.ndarray:
    """The central side × side square (default: the largest square)."""
    h, w = image.shape[:2]
    side = min(h, w) if side is None else side
    top, left = (h - side) // 2, (w - side) // 2
    return image[top : top + side, left : left + side]


def time_best(fn: Callable[[], Any], runs: int) -> tuple[Any, float, int]:
    """Run ``fn`` up to ``runs`` times (once if a run is slow); first output, best time."""
    output, best, done = None, math.inf, 0
    for _ in range(runs):
        start = time.perf_counter()
        out = fn()
        elapsed = time.perf_counter() - start
        output = out if output is None else output
        best, done = min(best, elapsed), done + 1
        if elapsed > SLOW_RUN_S:
            break
    return output, best, done


def geomean(values: list[float]) -> float:
    return math.exp(sum(math.log(v) for v in values) / len(values))


# --------------------------------------------------------------------------- metrics


def hole_mae(result: np.ndarray, original: np.ndarray, mask: np.ndarray) -> float:
    return float(np.abs(result[mask] - original[mask]).mean())


def _gray(image: np.ndarray) -> np.ndarray:
    return image @ np.array([0.299, 0.587, 0.114], np.float32)


def _window_stds(gray: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Std of the 7×7 windows lying wholly inside ``mask``, on a stride-4 grid."""
    k, s = CONTRAST_WINDOW, CONTRAST_STRIDE
    ys, xs = np.nonzero(mask)
    top, left = ys.min(), xs.min()
    region = gray[top : ys.max() + 1, left : xs.max() + 1]
    inside = mask[top : ys.max() + 1, left : xs.max() + 1]
    win = np.lib.stride_tricks.sliding_window_view(region, (k, k))[::s, ::s]
    full = np.lib.stride_tricks.sliding_window_view(inside, (k, k))[::s, ::s].all(axis=(2, 3))
    return np.asarray(win[full].std(axis=(1, 2)))


def contrast_ratio(result: np.ndarray, original: np.ndarray, mask: np.ndarray) -> float:
    return float(_window_stds(_gray(result), mask).mean() / _window_stds(_gray(original), mask).mean())


# --------------------------------------------------------------------------- inputs


def completion_images(size: int) -> dict[str, np.ndarray]:
    """Name → (size, size, 3) uint8 RGB; missing sources are skipped with a message."""
    import phloem

    images = {}
    if COFFEE.exists():
        images["coffee"] = to_u8(resize(center_crop(phloem.io.read_image(COFFEE)[..., :3]), size))
    else:
        log(f"skipping image 'coffee': {COFFEE} not found")
    images["bark"] = to_u8(resize(phloem.data.bark()[..., :3], size))
    return images


def synthesis_exemplars() -> dict[str, np.ndarray]:
    """Name → (M, N, 3) uint8 RGB exemplar; missing sources are skipped with a message."""
    import phloem

    exemplars = {"bark": to_u8(phloem.data.bark()[..., :3])}
    for name, path, side in (("water", WATER, None), ("gravel", GRAVEL, 200)):
        if path.exists():
            image = phloem.io.read_image(path)
            exemplars[name] = to_u8(to_rgb(image if side is None else center_crop(image, side)))
        else:
            log(f"skipping exemplar {name!r}: {path} not found")
    return exemplars


def square_hole(size: int, hole: int) -> np.ndarray:
    mask = np.zeros((size, size), bool)
    top = (size - hole) // 2
    mask[top : top + hole, top : top + hole] = True
    return mask


# --------------------------------------------------------------------------- tools
#
# A completion tool maps (uint8 image with the hole blacked out, bool mask) to a float32
# RGB image in [0, 1]. A synthesis tool takes (uint8 exemplar, output side), does its
# untimed preparation and returns the job to time, which returns a float32 RGB image.


def _phloem_complete(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    import phloem

    return np.asarray(phloem.texture.complete(to_float(image), mask, seed=0))


def _patchmatch_complete(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    import patchmatch

    patchmatch.set_random_seed(0)
    # non-zero mask = hole; patch_size is the radius: 3 → 7×7 patches
    out = patchmatch.inpaint(image, mask.astype(np.uint8) * 255, patch_size=3)
    return to_float(out)


def _resynthesizer_complete(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    import resynthesizer
    from PIL import Image

    params = resynthesizer.getDefaultParams()
    params.isMakeSeamlesslyTileableHorizontally = 0
    params.isMakeSeamlesslyTileableVertically = 0
    # the mask is a selection: non-zero (white) = synthesise, zero = keep and sample from
    out = resynthesizer.resynthesize(Image.fromarray(image), Image.fromarray(mask.astype(np.uint8) * 255), params)
    return to_float(np.asarray(out.convert("RGB")))


def _patchmatch_missing() -> str | None:
    try:
        import patchmatch
    except ImportError as exc:
        return f"not installed ({exc}); pip install PyPatchMatch"
    if not patchmatch.patchmatch_available:
        return "its native library did not load"
    return None


def _resynthesizer_missing() -> str | None:
    try:
        import resynthesizer  # noqa: F401  (only probing whether it imports)
    except (ImportError, OSError) as exc:
        return f"not available ({exc}); pip install resynthesizer"
    return None


def completion_tools() -> dict[str, CompletionTool]:
    """Name → tool for phloem and the completion peers that are available."""
    tools: dict[str, CompletionTool] = {"phloem": _phloem_complete}
    for name, fn, missing in (
        ("patchmatch", _patchmatch_complete, _patchmatch_missing),
        ("resynthesizer", _resynthesizer_complete, _resynthesizer_missing),
    ):
        reason = missing()
        if reason is None:
            tools[name] = fn
        else:
            log(f"skipping {name}: {reason}")
    return tools


def find_texture_synthesis(explicit: str | None) -> str | None:
    if explicit:
        return explicit if Path(explicit).is_file() else None
    found = shutil.which("texture-synthesis")
    fallback = Path.home() / ".cargo" / "bin" / "texture-synthesis"
    return found or (str(fallback) if fallback.is_file() else None)


def texture_synthesis_command(binary: str, exemplar: Path, out: Path, size: int) -> list[str]:
    return [
        binary,
        "--out", str(out),
        "--out-size", str(size),
        "--threads", "2",
        "--seed", "0",
        "--no-progress",
        "generate", str(exemplar),
    ]  # fmt: skip


def make_texture_synthesis(binary: str, workdir: Path) -> SynthesisTool:
    """A synthesis tool running the CLI; the exemplar PNG is written before timing starts."""

    def tool(exemplar: np.ndarray, size: int) -> Callable[[], np.ndarray]:
        from PIL import Image

        import phloem

        src, out = workdir / "exemplar.png", workdir / "out.png"
        Image.fromarray(exemplar).save(src)
        command = texture_synthesis_command(binary, src, out, size)

        def run() -> np.ndarray:
            out.unlink(missing_ok=True)
            proc = subprocess.run(command, check=False, capture_output=True, text=True, timeout=1800)
            if proc.returncode != 0:
                tail = (proc.stderr or proc.stdout).strip()[-500:]
                raise RuntimeError(f"exit {proc.returncode}: {tail}")
            return to_rgb(phloem.io.read_image(out))  # the CLI writes RGBA

        return run

    return tool


def _phloem_synthesize(exemplar: np.ndarray, size: int) -> Callable[[], np.ndarray]:
    import phloem

    src = to_float(exemplar)
    return lambda: phloem.texture.synthesize(src, (size, size), seed=0, threads=2)


# --------------------------------------------------------------------------- workloads


def run_completion(config: Config) -> list[Result]:
    mask = square_hole(config.image_size, config.hole)
    tools = completion_tools()
    results = []
    for case, image in completion_images(config.image_size).items():
        original = to_float(image)
        damaged = image.copy()
        damaged[mask] = 0
        for tool, fn in tools.items():
            log(f"completion  {case:<8} {tool} ...")
            result = Result("completion", case, tool)
            try:
                out, result.time_s, result.runs = time_best(functools.partial(fn, damaged, mask), config.complete_runs)
                result.metrics = {
                    "hole_mae": hole_mae(out, original, mask),
                    "contrast_ratio": contrast_ratio(out, original, mask),
                    "outside_changed": float(np.abs(out[~mask] - original[~mask]).max()),
                }
            except Exception as exc:
                result.error = f"{type(exc).__name__}: {exc}"
                log(f"  failed: {result.error}")
            results.append(result)
    return results


def run_synthesis(config: Config, texsyn_binary: str | None) -> list[Result]:
    import phloem

    tools: dict[str, SynthesisTool] = {"phloem": _phloem_synthesize}
    results = []
    with tempfile.TemporaryDirectory(prefix="phloem-peers-") as tmp:
        if texsyn_binary:
            tools["texture-synthesis"] = make_texture_synthesis(texsyn_binary, Path(tmp))
        else:
            log("skipping texture-synthesis: CLI not found; cargo install texture-synthesis-cli")
        for case, exemplar in synthesis_exemplars().items():
            reference = to_float(exemplar)
            for tool, make in tools.items():
                log(f"synthesis   {case:<8} {tool} ...")
                result = Result("synthesis", case, tool)
                try:
                    out, result.time_s, result.runs = time_best(make(exemplar, config.synth_size), config.synth_runs)
                    if out.shape[:2] != (config.synth_size, config.synth_size):
                        raise RuntimeError(f"output has shape {out.shape}")
                    result.metrics = {
                        "patch_coherence": phloem.metrics.patch_coherence(out, reference),
                        # Coherence rewards verbatim copying; repetition shows tiling.
                        "repetition": phloem.metrics.repetition(out),
                    }
                except Exception as exc:
                    result.error = f"{type(exc).__name__}: {exc}"
                    log(f"  failed: {result.error}")
                results.append(result)
    return results


def time_ratios(results: list[Result]) -> list[dict[str, Any]]:
    """t_phloem / t_peer per (workload, case, peer), plus a geometric mean per workload."""
    times = {(r.workload, r.case, r.tool): r.time_s for r in results if r.time_s}
    rows: list[dict[str, Any]] = []
    grouped: dict[tuple[str, str], list[float]] = {}
    for (workload, case, tool), t in times.items():
        base = times.get((workload, case, "phloem"))
        if tool == "phloem" or base is None:
            continue
        rows.append({"workload": workload, "case": case, "peer": tool, "ratio": base / t})
        grouped.setdefault((workload, tool), []).append(base / t)
    for (workload, tool), ratios in grouped.items():
        rows.append({"workload": workload, "case": "geomean", "peer": tool, "ratio": geomean(ratios)})
    return rows


# --------------------------------------------------------------------------- report


def format_table(headers: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(headers)]

    def line(cells: list[str]) -> str:
        return "  ".join(c.ljust(w) for c, w in zip(cells, widths)).rstrip()

    return "\n".join([line(headers), line(["-" * w for w in widths]), *map(line, rows)])


def _fmt(value: float | None, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def report(results: list[Result], ratios: list[dict[str, Any]], config: Config) -> str:
    parts = []
    completion = [r for r in results if r.workload == "completion"]
    if completion:
        parts.append(
            f"Completion: {config.image_size}x{config.image_size} RGB, "
            f"{config.hole}x{config.hole} hole (MAE inside the hole, 0-1; contrast ~1 is right)"
        )
        rows = [
            [r.case, r.tool, _fmt(r.time_s, ".3f"), str(r.runs),
             _fmt(r.metrics.get("hole_mae"), ".4f"), _fmt(r.metrics.get("contrast_ratio"), ".3f"),
             r.error or ""]
            for r in completion
        ]  # fmt: skip
        parts.append(format_table(["image", "tool", "time_s", "runs", "hole_mae", "contrast", ""], rows))
    synthesis = [r for r in results if r.workload == "synthesis"]
    if synthesis:
        parts.append(
            f"\nSynthesis: {config.synth_size}x{config.synth_size} output "
            "(patch coherence to the exemplar, lower is better)"
        )
        rows = [
            [r.case, r.tool, _fmt(r.time_s, ".3f"), str(r.runs),
             _fmt(r.metrics.get("patch_coherence"), ".5f"), _fmt(r.metrics.get("repetition"), ".3f"), r.error or ""]
            for r in synthesis
        ]  # fmt: skip
        parts.append(format_table(["exemplar", "tool", "time_s", "runs", "coherence", "repetition", ""], rows))
    if ratios:
        parts.append("\nTime ratios t_phloem / t_peer (below 1: phloem faster)")
        rows = [[r["workload"], r["case"], r["peer"], f"{r['ratio']:.3f}"] for r in ratios]
        parts.append(format_table(["workload", "case", "peer", "ratio"], rows))
    return "\n".join(parts)


def _version(dist: str) -> str | None:
    from importlib import metadata

    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def environment(texsyn_binary: str | None) -> dict[str, Any]:
    texsyn = None
    if texsyn_binary:
        proc = subprocess.run([texsyn_binary, "--version"], check=False, capture_output=True, text=True)
        texsyn = proc.stdout.strip() or None
    return {
        "python": platform.python_version(),
        "platform": platform.platform(),
        "cpus": os.cpu_count(),
        "loadavg": os.getloadavg() if hasattr(os, "getloadavg") else None,
        "phloem": _version("phloem"),
        "PyPatchMatch": _version("PyPatchMatch"),
        "resynthesizer": _version("resynthesizer"),
        "texture-synthesis": texsyn,
        "PHLOEM_NUM_THREADS": os.environ.get("PHLOEM_NUM_THREADS"),
    }


# --------------------------------------------------------------------------- main


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="small sizes and fewer runs")
    parser.add_argument("--json", metavar="OUT.json", help="also write the figures as JSON")
    parser.add_argument("--only", choices=["completion", "synthesis"], help="run only one workload")
    parser.add_argument("--texture-synthesis", metavar="PATH", help="the CLI binary to use")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    config = QUICK if args.quick else FULL
    texsyn = find_texture_synthesis(args.texture_synthesis)
    env = environment(texsyn)
    log(f"{env['cpus']} CPUs, load average {env['loadavg']}; config {config}")

    results: list[Result] = []
    if args.only in (None, "completion"):
        results += run_completion(config)
    if args.only in (None, "synthesis"):
        results += run_synthesis(config, texsyn)
    ratios = time_ratios(results)
    print(report(results, ratios, config))

    if args.json:
        payload = {
            "config": dataclasses.asdict(config) | {"quick": args.quick},
            "environment": env,
            "results": [dataclasses.asdict(r) for r in results],
            "time_ratios": ratios,
        }
        Path(args.json).write_text(json.dumps(payload, indent=2) + "\n")
        log(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
