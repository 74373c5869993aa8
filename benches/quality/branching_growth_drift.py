"""How the skeletons that ``phloem.branching.synthesize`` grows turn and hold together, without rendering.

    PYTHONPATH=python python benches/quality/branching_growth_drift.py [--inputs DIR] [--only NAME ...]
        [--seeds 0 1 2 3] [--set NAME=VALUE ...]

For every image of ``--inputs`` (default: ``branching`` of the real-image collection) the
first three steps of ``synthesize`` with its defaults: ``trace`` (with ``valid_region``), the
models fitted as ``synthesize`` fits them (``source_defaults``) and ``grow`` at every seed,
giving the skeleton that ``synthesize(image, seed=seed).target`` is. Each row: the drift of
every seed against the input's skeleton (issue 19's mark is 0.25), their mean, how many are
at or under the mark, the input's own ``drift_noise``, the largest-tree share in → out and how
many seeds keep the angle and thickness histograms within the acceptance bench's spread.

Growth takes a second or two where ``synthesize`` with its rendering takes up to a minute, so
the heading terms can be compared over many seeds: ``--set course=0 --set turn_histogram=6``
overrides ``fit_models``' and ``grow``'s keyword arguments (numbers, ``true``/``false``,
``none``), the way ``synthesize`` would pass them on. The rendered output's measures are
``branching_quality.py``'s.
"""

from __future__ import annotations

import argparse
import importlib.util
import inspect
import math
import sys
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from phloem.branching import Skeleton, fit_models, grow, source_defaults, trace, valid_region
from phloem.branching.frame import _kept_inside
from phloem.metrics import drift, drift_noise, largest_tree_share
from phloem.testing import shared_path

_here = Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location("_branching_quality", _here / "branching_quality.py")
assert _spec is not None and _spec.loader is not None
quality = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = quality  # its dataclasses look their module up by name
_spec.loader.exec_module(quality)

#: ``source_defaults``' options: an override of one of these is resolved as ``synthesize`` does.
_DEFAULTED = set(inspect.signature(source_defaults).parameters) - {"skeleton", "guided"}
_FIT = set(inspect.signature(fit_models).parameters) - {"skeleton"}
_GROW = {"generations", "max_length", "colonize", "repel_border"}


@dataclass
class Row:
    """One input over its seeds."""

    input: str
    drifts: list[float]
    noise: float
    share_in: float
    shares: list[float]
    histograms: int

    def mean(self) -> float:
        ok = [d for d in self.drifts if not math.isnan(d)]
        return float(np.mean(ok)) if ok else math.nan

    def passing(self) -> int:
        return sum(d <= quality.DRIFT_MAX for d in self.drifts)


def parse_set(items: Sequence[str]) -> dict[str, Any]:
    """``NAME=VALUE`` pairs as keyword arguments: numbers, ``true``/``false``, ``none``."""
    out: dict[str, Any] = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name:
            raise SystemExit(f"--set: expected NAME=VALUE, got {item!r}")
        if name not in _FIT and name not in _GROW:
            raise SystemExit(f"--set: {name!r} is not an option of fit_models or grow")
        low = text.strip().lower()
        value: Any
        if low in ("true", "false"):
            value = low == "true"
        elif low == "none":
            value = None
        else:
            try:
                value = int(text)
            except ValueError:
                try:
                    value = float(text)
                except ValueError:
                    value = text  # e.g. max_length="input"
        out[name] = value
    return out


def grown(image: np.ndarray, seeds: Sequence[int], options: dict[str, Any]) -> tuple[Skeleton, list[Skeleton], Any]:
    """The input's skeleton, the skeletons ``synthesize`` grows from it at ``seeds`` (with
    ``options`` for ``fit_models`` and ``grow``) and the bending model."""
    ok = valid_region(image)
    ok = None if ok.all() else ok
    source = trace(image, valid=ok)
    d = source_defaults(source, **{k: options[k] for k in _DEFAULTED if k in options})
    # every resolved option but repel_border is fit_models'
    fit = {k: v for k, v in options.items() if k in _FIT} | {k: v for k, v in asdict(d).items() if k in _FIT}
    bending, furcation = fit_models(source, **fit)
    kw = {"max_length": "input"} | {k: v for k, v in options.items() if k in _GROW} | {"repel_border": d.repel_border}
    shape = image.shape[:2]
    domain = None if ok is None else _kept_inside(ok, shape)
    targets = [grow(bending, furcation, size=shape, seed=s, domain=domain, **kw) for s in seeds]
    return source, targets, bending


def measure(name: str, image: np.ndarray, seeds: Sequence[int], options: dict[str, Any]) -> Row:
    """The row of one input."""
    source, targets, bending = grown(image, seeds, options)
    drifts = []
    for t in targets:
        try:
            drifts.append(drift(source, t))
        except ValueError:  # no branch spans the arc
            drifts.append(math.nan)
    try:
        noise = drift_noise(source)
    except ValueError:
        noise = math.nan
    hist = 0
    for t in targets:
        da, sa, dt, st = quality._hist_distances(bending, t)
        hist += not (da >= 1.5 * sa or dt >= st)
    return Row(name, drifts, noise, largest_tree_share(source), [largest_tree_share(t) for t in targets], hist)


def _f(v: float) -> str:
    return "—" if math.isnan(v) else f"{v:.2f}"


def table(rows: Sequence[Row]) -> str:
    """The rows as a Markdown table."""
    lines = [
        "| input | drift per seed | mean | ≤ mark | input's noise | tree share in → out | histograms |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r.input} | {' / '.join(_f(d) for d in r.drifts)} | {_f(r.mean())} | {r.passing()}/{len(r.drifts)} "
            f"| {_f(r.noise)} | {_f(r.share_in)} → {' / '.join(_f(s) for s in r.shares)} "
            f"| {r.histograms}/{len(r.drifts)} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--inputs", type=Path, default=None, help="folder of images (default: shared branching set)")
    ap.add_argument("--only", nargs="*", default=None, help="file names to run (default: all)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    ap.add_argument("--set", dest="sets", action="append", default=[], metavar="NAME=VALUE",
                    help="an option of fit_models or grow (repeatable)")  # fmt: skip
    args = ap.parse_args(argv)
    options = parse_set(args.sets)
    folder = args.inputs if args.inputs is not None else shared_path("branching")
    paths = [p for p in quality.inputs(folder) if not args.only or p.name in args.only] if folder.is_dir() else []
    if not paths:
        print(f"no images in {folder}", file=sys.stderr)
        return 1
    rows = []
    for p in paths:
        image, _ = quality.load(p)
        rows.append(measure(p.name, image, args.seeds, options))
        print(table(rows[-1:]).splitlines()[-1], flush=True)
    print()
    print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
