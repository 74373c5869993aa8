"""``phloem batch``: many runs of one sub-command on Dask (:mod:`phloem.batch`)."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from .._progress import Bar
from ._common import positive


def _cmd_batch(args: argparse.Namespace) -> None:
    try:
        from .. import batch
    except ImportError as e:  # dask is an optional dependency
        raise ValueError(f"batch: needs Dask distributed ({e.name} is missing): pip install 'phloem[batch]'") from None
    spec = batch.load_spec(args.spec)
    bar = Bar("batch", enabled=not args.quiet)
    try:
        if args.scheduler is not None:
            from distributed import Client

            try:
                client = Client(args.scheduler, timeout="10s")  # type: ignore[no-untyped-call]
            except OSError as e:
                raise ValueError(f"scheduler: cannot connect to {args.scheduler}: {e}") from None
            with client:
                summary = batch.run(spec, out_dir=args.out_dir, client=client, progress=bar)
        else:
            summary = batch.run(spec, out_dir=args.out_dir, workers=args.workers, progress=bar)
    finally:
        bar.close()
    if not summary.ok:
        raise ValueError(summary.line())
    if not args.quiet:
        print(f"batch: {summary.line()}", file=sys.stderr)


def add_parsers(sub: Any) -> None:
    p = sub.add_parser("batch", help="run one sub-command over many inputs and seeds on Dask, resumably",
                       description="Reads SPEC (YAML or JSON: job, inputs, params, seeds) and runs the job once per "
                                   "(input, seed) as a Dask task, each exactly the single 'phloem JOB ...' run, writing "
                                   "DIR/INPUT-JOB-HASH-sSEED.png (and .json), or a folder of that name for jobs with "
                                   "--out-dir. DIR/manifest.jsonl records each item's arguments, status, time, output "
                                   "hashes and error; a rerun makes only the items whose files are missing or do not "
                                   "match. A failed item is retried once, then recorded, and the batch goes on; the exit "
                                   "status is 2 if any item failed. See docs/pipelines/batch.md.")  # fmt: skip
    p.add_argument("spec", metavar="SPEC", help="the batch spec (.yaml, .yml or .json); its paths are relative to it")
    p.add_argument("--out-dir", required=True, metavar="DIR",
                   help="folder of the outputs and manifest.jsonl (created if missing); rerun into it to resume")  # fmt: skip
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=positive, default=None, metavar="N",
                       help="worker processes of the local Dask cluster (default: one per core); each task gets "
                            "cores/N threads and 1/N of the memory budget")  # fmt: skip
    where.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="run on a running Dask scheduler, e.g. tcp://10.0.0.5:8786, instead of a local cluster; "
                            "its workers must see the inputs and DIR at the same paths")  # fmt: skip
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar and no summary line")
    # finished items stay on disk, each written whole
    p.set_defaults(func=_cmd_batch, interrupted="finished items are kept; run it again to go on")
