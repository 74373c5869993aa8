"""Batches on Dask distributed: one ``phloem`` command per (input, seed), resumable.

``phloem.batch.run(spec, out_dir=...)`` (and ``phloem batch SPEC --out-dir DIR``) turns a spec
(a job, its inputs, options and seeds) into one Dask task per item, on a ``LocalCluster`` of
this machine or any running scheduler. Every task runs its item's single command line in the
worker, so the files are those the command writes alone; ``manifest.jsonl`` records each
item's outcome and output hashes, and a rerun makes only what is missing or does not verify
(``docs/pipelines/batch.md``). Needs the ``batch`` extra (``pip install 'phloem[batch]'``).
"""

from __future__ import annotations

from .manifest import MANIFEST, Manifest
from .schedule import Summary, local_cluster, run
from .spec import Item, Spec, load_spec

__all__ = ["MANIFEST", "Item", "Manifest", "Spec", "Summary", "load_spec", "local_cluster", "run"]
