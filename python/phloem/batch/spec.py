"""The batch spec: which ``phloem`` sub-command, on which inputs, with which options and seeds.

A spec is read from YAML or JSON and checked against the sub-command's own argument parser, so
a batch accepts exactly what the command line accepts and says what is wrong in one line naming
the key. Each (input, seed) pair becomes one :class:`Item`, whose output name is fixed by the
job, the input's stem, the seed and a short hash of the options: the same spec always writes
the same files.
"""

from __future__ import annotations

import argparse
import contextlib
import glob
import hashlib
import io
import json
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["Item", "Spec", "load_spec"]

#: Options the batch sets itself for every item: where it writes, its seed, its share of the
#: machine.
RESERVED = ("out", "out_dir", "prefix", "seed", "threads", "max_memory", "force", "quiet")

#: A command's extra output files (a contact sheet, a preview, an intermediate map): ``true`` in
#: ``params`` has each item write its own, named ``ITEM_OPTION`` + this suffix beside its output.
EXTRA_OUTPUTS = {
    "sheet": ".png",
    "labels_out": ".png",
    "model_out": "",
    "overlay": ".png",
    "preview": ".png",
    "histograms": ".png",
    "fragment_map": ".png",
}

#: Metavars of the options and positionals that name an input file or folder: a relative path
#: there is taken from the spec file's folder (when that file exists), like ``inputs``.
PATH_METAVARS = frozenset(
    {"IN", "IMAGE", "IMG", "MASK", "SKEL.json", "NEW.json", "JSON", "LEAF", "LIBRARY", "MODEL", "PNG", "SCAN",
     "SOURCE", "STROKES", "TARGET", "TREE", "EDGES", "HM", "PATH", "DIR"}
)  # fmt: skip

#: Jobs whose first item runs alone, so that the prepared model it caches (``--library-cache``)
#: is built once and every other item loads it.
CACHED_JOBS = {"trees": "library_cache"}

_KEYS = ("job", "inputs", "params", "seeds")


@dataclass(frozen=True)
class Item:
    """One task of a batch: one sub-command run on one input with one seed.

    Attributes
    ----------
    name : str
        ``STEM-JOB-HASH-sSEED``: the input's stem, the job, a hash of the options and the seed;
        the stem of the item's output files.
    job : str
        The sub-command, e.g. ``"synthesize"`` or ``"branching run"``.
    input : str
        The input file or folder (absolute).
    seed : int
    params : dict
        The options as given in the spec (long names without dashes, ``_`` or ``-``).
    """

    name: str
    job: str
    input: str
    seed: int
    params: dict[str, Any]
    options: tuple[str, ...] = field(repr=False)
    out_kind: str = field(repr=False)
    out_suffix: str = field(repr=False)
    extras: tuple[str, ...] = field(default=(), repr=False)

    def outputs(self, out_dir: str | os.PathLike[str]) -> Path:
        """The item's ``--out`` file, or its ``--out-dir`` folder, inside ``out_dir``."""
        return Path(out_dir).absolute() / f"{self.name}{self.out_suffix}"

    def extra_outputs(self, out_dir: str | os.PathLike[str]) -> dict[str, Path]:
        """The extra files the spec asked for (``sheet: true``...), by option, inside ``out_dir``."""
        root = Path(out_dir).absolute()
        return {dest: root / f"{self.name}_{dest}{EXTRA_OUTPUTS[dest]}" for dest in self.extras}

    def argv(self, out_dir: str | os.PathLike[str], *, extra: Sequence[str] = ()) -> list[str]:
        """The ``phloem`` arguments of the single command-line run that makes this item.

        A batch runs these arguments in its workers, with its share of the machine
        (``--threads``, ``--max-memory``; the manifest records the whole list) and ``--force
        --quiet``, so ``phloem`` run alone with them writes the same files, byte for byte.
        ``extra`` are options the batch adds (a shared cache folder).
        """
        out = str(self.outputs(out_dir))
        return [
            *self.job.split(),
            self.input,
            *self.options,
            *extra,
            *(a for dest, path in self.extra_outputs(out_dir).items() for a in (_dest_flag(dest), str(path))),
            f"--{self.out_kind}",
            out,
            "--seed",
            str(self.seed),
        ]


@dataclass(frozen=True)
class Spec:
    """A checked batch spec (see :func:`load_spec`).

    Attributes
    ----------
    job : str
    inputs : list of str
        The inputs matched by the spec's paths and globs, absolute, in order.
    params : dict
    seeds : list of int
    items : list of Item
        One per (input, seed), inputs outer.
    """

    job: str
    inputs: list[str]
    params: dict[str, Any]
    seeds: list[int]
    items: list[Item]

    @property
    def cache_option(self) -> str | None:
        """The option (dest) of the job's prepared-model cache, if it has one."""
        return CACHED_JOBS.get(self.job)

    def shared_cache(self, out_dir: Path) -> tuple[list[str], Path | None]:
        """The options a batch adds to every item so that all share the job's prepared-model
        cache (``--library-cache OUT_DIR/.phloem-cache`` unless ``params`` names one), and that
        cache's folder; ``([], None)`` for a job without one."""
        if self.cache_option is None:
            return [], None
        flag = f"--{self.cache_option.replace('_', '-')}"
        given = {k.lstrip("-").replace("-", "_") for k in self.params}
        extra = [] if self.cache_option in given else [flag, str(out_dir / ".phloem-cache")]
        argv = self.items[0].argv(out_dir, extra=extra) if self.items else []
        return extra, (Path(argv[argv.index(flag) + 1]) if flag in argv else None)


def _fail(key: str, what: str) -> ValueError:
    return ValueError(f"{key}: {what}")


def _read(path: Path) -> Any:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise _fail("spec", f"cannot read {path}: {e.strerror or e}") from None
    except UnicodeDecodeError:
        raise _fail("spec", f"{path} is not UTF-8 text") from None
    if path.suffix.lower() == ".json":
        try:
            return json.loads(text)
        except json.JSONDecodeError as e:
            raise _fail("spec", f"{path} is not valid JSON: {e.msg} at line {e.lineno} column {e.colno}") from None
    import yaml

    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1} column {mark.column + 1}" if mark is not None else ""
        raise _fail("spec", f"{path} is not valid YAML{where}") from None


def _command_parser(job: Any) -> argparse.ArgumentParser:
    """The parser of the sub-command named by ``job`` (``"trees"``, ``"branching run"``)."""
    from ..cli.parser import build_parser

    if not isinstance(job, str) or not job.strip():
        raise _fail("job", f"expected a phloem sub-command such as 'synthesize' or 'branching run', got {job!r}")
    if job.split()[0] == "batch":
        raise _fail("job", "a batch runs other sub-commands, not 'batch'")
    p: argparse.ArgumentParser = build_parser()
    for word in job.split():
        sub = next((a for a in p._actions if isinstance(a, argparse._SubParsersAction)), None)
        if sub is None or word not in sub.choices:
            known = sorted(sub.choices) if sub is not None else []
            raise _fail(
                "job", f"{job!r} is no phloem sub-command that writes files; expected one of {', '.join(known)}"
            )
        p = sub.choices[word]
    if any(isinstance(a, argparse._SubParsersAction) for a in p._actions):
        acts = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction)).choices
        raise _fail("job", f"{job!r} needs an action: one of {', '.join(f'{job} {a}' for a in acts)}")
    return p


def _seeds(value: Any) -> list[int]:
    if isinstance(value, bool):
        value = None
    if isinstance(value, int):
        return [value]
    if isinstance(value, str):
        m = re.fullmatch(r"\s*(-?\d+)\s*\.\.\s*(-?\d+)\s*", value)
        if m is None or int(m.group(1)) > int(m.group(2)):
            raise _fail("seeds", f"expected a list of integers or a range FIRST..LAST such as 0..99, got {value!r}")
        return list(range(int(m.group(1)), int(m.group(2)) + 1))
    if isinstance(value, list) and value and all(isinstance(v, int) and not isinstance(v, bool) for v in value):
        if len(set(value)) != len(value):
            raise _fail("seeds", "expected distinct seeds, got a repeated one")
        return list(value)
    raise _fail("seeds", f"expected a list of integers or a range FIRST..LAST such as 0..99, got {value!r}")


def _inputs(value: Any, base: Path) -> list[str]:
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not value or not all(isinstance(v, str) and v for v in value):
        raise _fail("inputs", f"expected a list of paths or globs (relative to the spec file), got {value!r}")
    found: list[str] = []
    for pattern in value:
        full = Path(pattern).expanduser()
        full = full if full.is_absolute() else base / full
        matches = sorted(glob.glob(str(full))) if glob.has_magic(pattern) else ([str(full)] if full.exists() else [])
        if not matches:
            raise _fail("inputs", f"{pattern!r} matches no file (looked in {base})")
        found += [str(Path(m).absolute()) for m in matches if str(Path(m).absolute()) not in found]
    return found


def _dest_of(p: argparse.ArgumentParser, key: str) -> argparse.Action | None:
    dest = key.lstrip("-").replace("-", "_")
    return next((a for a in p._actions if a.dest == dest and a.help != argparse.SUPPRESS), None)


def _flag(a: argparse.Action) -> str:
    return max(a.option_strings, key=len)


def _value_text(key: str, v: Any) -> str:
    if isinstance(v, bool) or not isinstance(v, (str, int, float)):
        raise _fail(f"params.{key}", f"expected a string or a number, got {v!r}")
    return str(v)


def _path_value(a: argparse.Action, text: str, base: Path) -> str:
    """An input path as the spec file's folder sees it, when it is one and exists there."""
    if a.metavar in PATH_METAVARS and not os.path.isabs(text) and (base / text).exists():
        return str((base / text).absolute())
    return text


def _options(
    p: argparse.ArgumentParser, job: str, params: Any, base: Path
) -> tuple[list[str], dict[str, str], list[str]]:
    """The option arguments of ``params``, the positionals other than the input by dest, and
    the extra outputs asked for (dests of :data:`EXTRA_OUTPUTS`)."""
    if params is None:
        params = {}
    if not isinstance(params, Mapping) or not all(isinstance(k, str) for k in params):
        raise _fail("params", f"expected a mapping of option names to values, got {params!r}")
    positionals = [a for a in p._actions if not a.option_strings and a.dest != "help"]
    known = sorted(_flag(a) for a in p._actions if a.option_strings and a.dest not in RESERVED and a.dest != "help")
    argv: list[str] = []
    extra: dict[str, str] = {}
    asked: list[str] = []
    for key, value in params.items():
        a = _dest_of(p, key)
        if a is None:
            raise _fail(f"params.{key}", f"not an option of 'phloem {job}'; expected one of {', '.join(known)}")
        if a.dest in RESERVED:
            raise _fail(
                f"params.{key}", "is set by the batch for each item (output, seed, threads, memory); leave it out"
            )
        if a.dest in EXTRA_OUTPUTS:
            if not isinstance(value, bool):
                raise _fail(
                    f"params.{key}", f"is named by the batch for each item; give true to write it, got {value!r}"
                )
            if value:
                asked.append(a.dest)
            continue
        if not a.option_strings:
            if a is positionals[0]:
                raise _fail(f"params.{key}", "is the item's input; list it under inputs")
            extra[a.dest] = _path_value(a, _value_text(key, value), base)
            continue
        if a.nargs == 0:
            if not isinstance(value, bool):
                raise _fail(f"params.{key}", f"expected true or false (a flag), got {value!r}")
            if value:
                argv.append(_flag(a))
            continue
        values = value if isinstance(value, list) else [value]
        if not values:
            raise _fail(f"params.{key}", "expected a value, got an empty list")
        texts = [_value_text(key, v) for v in values]
        if a.dest in CACHED_JOBS.values():  # a cache folder need not exist yet
            texts = [str((base / t).absolute()) for t in texts]
        argv += [_flag(a), *(_path_value(a, t, base) for t in texts)]
    for a in positionals[1:]:
        if a.dest not in extra and a.nargs not in ("?", "*"):
            raise _fail("params", f"'phloem {job}' needs {a.metavar}: give it as params.{a.dest}")
    return argv, extra, asked


def _dest_flag(dest: str) -> str:
    return "--" + dest.replace("_", "-")


def _check_argv(p: argparse.ArgumentParser, job: str, argv: list[str]) -> None:
    """Parse ``argv`` with the sub-command's parser; its complaint, if any, as one line."""
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            p.parse_args(argv)
    except SystemExit:
        line = err.getvalue().strip().splitlines()[-1] if err.getvalue().strip() else "invalid arguments"
        msg = line.split(" error: ", 1)[-1]
        m = re.match(r"argument ([-\w/]+): (.*)", msg)
        if m is not None:
            flag = m.group(1).split("/")[-1].lstrip("-").replace("-", "_")
            raise _fail(f"params.{flag}", m.group(2)) from None
        raise _fail("params", f"'phloem {job}' does not accept these options: {msg}") from None


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._]+", "_", text).strip("_") or "input"


def load_spec(spec: str | os.PathLike[str] | Mapping[str, Any], *, base: str | os.PathLike[str] | None = None) -> Spec:
    """Read and check a batch spec.

    Parameters
    ----------
    spec : path-like or mapping
        A YAML (``.yaml``/``.yml``) or JSON (``.json``) file, or the mapping it holds:
        ``job`` (a sub-command, e.g. ``synthesize`` or ``branching run``), ``inputs`` (paths
        or globs), ``params`` (the sub-command's options by their long names; flags take
        true/false, other positionals by their name) and ``seeds`` (a list, or a range
        ``FIRST..LAST`` with both ends included).
    base : path-like, optional
        The folder relative paths are read from (default: the spec file's folder, or the
        current folder for a mapping).

    Returns
    -------
    Spec

    Raises
    ------
    ValueError
        One line naming the key that is wrong and what was expected.

    Examples
    --------
    >>> import phloem.batch, phloem.data
    >>> spec = phloem.batch.load_spec({"job": "synthesize", "inputs": [str(phloem.data.path("bark_douglas_fir.png"))],
    ...                                "params": {"size": "64x64"}, "seeds": "0..2"})
    >>> [item.name for item in spec.items]  # doctest: +ELLIPSIS
    ['...-synthesize-...-s0', '...-synthesize-...-s1', '...-synthesize-...-s2']
    >>> phloem.batch.load_spec({"job": "synthesize", "inputs": ["*.nothing"], "seeds": [0]})
    Traceback (most recent call last):
    ...
    ValueError: inputs: '*.nothing' matches no file (looked in ...)
    """
    if isinstance(spec, Mapping):
        data: Any = spec
        folder = Path(base) if base is not None else Path.cwd()
    else:
        path = Path(spec)
        if path.suffix.lower() not in (".yaml", ".yml", ".json"):
            raise _fail("spec", f"expected a .yaml, .yml or .json file, got {path.name}")
        data = _read(path)
        folder = Path(base) if base is not None else path.absolute().parent
    if not isinstance(data, Mapping):
        raise _fail("spec", f"expected a mapping with keys {', '.join(_KEYS)}, got {type(data).__name__}")
    unknown = [k for k in data if k not in _KEYS]
    if unknown:
        raise _fail(str(unknown[0]), f"unknown key; a spec has {', '.join(_KEYS)}")
    for key in ("job", "inputs", "seeds"):
        if key not in data:
            raise _fail(key, "missing; a spec needs job, inputs and seeds (params is optional)")
    job = " ".join(str(data["job"]).split()) if isinstance(data["job"], str) else data["job"]
    p = _command_parser(job)
    inputs = _inputs(data["inputs"], folder)
    seeds = _seeds(data["seeds"])
    params = dict(data.get("params") or {})
    options, extra, asked = _options(p, job, params, folder)
    outs = [a for a in p._actions if a.dest in ("out", "out_dir") and a.option_strings]
    if not outs:
        raise _fail("job", f"'phloem {job}' writes no --out or --out-dir; a batch cannot run it")
    out = outs[0]
    suffix = {"OUT": ".png", "OUT.npz": ".npz", "SKEL.json": ".json", "NEW.json": ".json"}.get(str(out.metavar), "")
    # the other positionals go right after the input, in the parser's order
    positionals = [a for a in p._actions if not a.option_strings and a.dest != "help"][1:]
    options = [extra[a.dest] for a in positionals if a.dest in extra] + options
    probe = [inputs[0], *options, *(a for d in asked for a in (_dest_flag(d), "x")), _flag(out), f"probe{suffix}"]
    _check_argv(p, job, probe)
    digest = hashlib.sha256(json.dumps({"job": job, "params": params}, sort_keys=True).encode()).hexdigest()[:8]
    slug = job.replace(" ", "-")
    items: list[Item] = []
    names: dict[str, str] = {}
    for inp in inputs:
        stem = _slug(Path(inp).stem if Path(inp).is_file() else Path(inp).name)
        if stem in names and names[stem] != inp:
            raise _fail("inputs", f"{names[stem]} and {inp} give the same output name {stem!r}; rename one")
        names[stem] = inp
        for s in seeds:
            name = f"{stem}-{slug}-{digest}-s{s}"
            items.append(Item(name, job, inp, s, params, tuple(options), out.dest.replace("_", "-"), suffix,
                              tuple(asked)))  # fmt: skip
    return Spec(job=job, inputs=inputs, params=params, seeds=seeds, items=items)
