"""Fuzz target: the trunk model JSON of ``phloem trees --trunk-model``, read as the CLI reads it.

``cli/trees.py`` reads the file with ``phloem._json.read_json`` (before that reader existed:
``json.loads`` of the UTF-8 text) and hands the result to
:meth:`phloem.trees.TrunkClassifier.from_dict`; this target does the same.
Expected: ``ValueError`` other than ``UnicodeDecodeError``. ``KeyError``, ``TypeError``,
``RecursionError`` and the rest are crashes. A model that loads must survive
``to_dict`` → ``from_dict``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from _common import fuzz, instrumented, target, temp_file

with instrumented():
    from phloem import trees

    try:
        from phloem._json import read_json
    except ImportError:  # before issue 16's JSON reader: what cli/trees.py did then

        def read_json(path: str | Path, name: str) -> Any:
            return json.loads(Path(path).read_text(encoding="utf-8"))


@target
def TestOneInput(data: bytes) -> None:
    path = temp_file(data, ".json")
    try:
        clf = trees.TrunkClassifier.from_dict(read_json(path, "trunk_model"))
    except UnicodeDecodeError:
        raise
    except ValueError:
        return
    again = trees.TrunkClassifier.from_dict(json.loads(json.dumps(clf.to_dict())))
    assert json.dumps(again.to_dict()) == json.dumps(clf.to_dict()), "to_dict/from_dict round trip changed the model"


if __name__ == "__main__":
    fuzz(TestOneInput)
