"""The API dialect's helpers: seeds and sizes, and the old spellings kept for one release.

``docs/conventions.md`` states the dialect; this module holds what keeps it uniform: the
``Seed`` and ``Size`` types, :func:`renamed` (old keyword names and old ``return_*`` flags
that still work with a ``DeprecationWarning``) and :func:`warn_deprecated` for old option
values.
"""

from __future__ import annotations

import functools
import os
import sys
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar, cast

import numpy as np

__all__ = ["OldFlag", "Seed", "Size", "old_flag", "renamed", "warn_deprecated"]

#: A seed: an int, or a ``numpy.random.Generator`` that one is drawn from.
Seed = int | np.random.Generator
#: An output size: ``(height, width)``, or an int ``N`` for ``N × N``.
Size = int | tuple[int, int]

F = TypeVar("F", bound=Callable[..., Any])

_PACKAGE = str(Path(__file__).resolve().parent) + os.sep


def _caller_stacklevel() -> int:
    """The ``stacklevel`` that points a warning at the first frame outside phloem."""
    level, frame = 1, sys._getframe(1)
    while frame is not None and str(Path(frame.f_code.co_filename).resolve()).startswith(_PACKAGE):
        level += 1
        frame = frame.f_back  # type: ignore[assignment]
    return level


def warn_deprecated(message: str) -> None:
    """A ``DeprecationWarning`` attributed to the user's code, not to phloem's."""
    warnings.warn(message, DeprecationWarning, stacklevel=_caller_stacklevel())


@dataclass(frozen=True)
class OldFlag:
    """An old ``return_*=True`` flag: ``full_output=True`` plus the old return value."""

    legacy: Callable[[Any], Any]
    """Turns the result dataclass into what the old flag returned (e.g. a tuple)."""


def old_flag(legacy: Callable[[Any], Any]) -> OldFlag:
    """Declare an old ``return_*`` flag for :func:`renamed`; ``legacy`` maps the result to
    the value the flag used to return."""
    return OldFlag(legacy)


def renamed(**old: str | OldFlag) -> Callable[[F], F]:
    """Keep old keyword spellings working for one release, each with a ``DeprecationWarning``.

    ``@renamed(labels="n_labels")`` passes ``labels=`` on as ``n_labels=``;
    ``@renamed(return_info=old_flag(to_tuple))`` turns ``return_info=True`` into
    ``full_output=True`` and returns ``to_tuple(result)``, the old output, unchanged. Giving
    an old and its new spelling together is a ``TypeError``. Positional calls are untouched.
    """

    def decorate(func: F) -> F:
        name = f"{func.__module__.split('.')[1]}.{func.__qualname__}"  # the public path: trees.vary

        @functools.wraps(func)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            legacy: Callable[[Any], Any] | None = None
            for spelling, new in old.items():
                if spelling not in kwargs:
                    continue
                target = "full_output" if isinstance(new, OldFlag) else new
                if target in kwargs:
                    raise TypeError(f"{spelling}: deprecated spelling of {target}; pass only {target}")
                value = kwargs.pop(spelling)
                if isinstance(new, OldFlag):
                    warn_deprecated(
                        f"{name}: {spelling}= is deprecated and goes in the next release; "
                        "pass full_output=True (it returns a result object)"
                    )
                    if value:
                        kwargs["full_output"] = True
                        legacy = new.legacy
                else:
                    warn_deprecated(f"{name}: {spelling}= is deprecated and goes in the next release; use {new}=")
                    kwargs[new] = value
            result = func(*args, **kwargs)
            return result if legacy is None else legacy(result)

        return cast(F, wrapper)

    return decorate
