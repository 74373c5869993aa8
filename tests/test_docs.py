"""Every Examples section in phloem's docstrings runs and shows what it claims."""

from __future__ import annotations

import doctest
import importlib
import inspect
import pkgutil

import pytest

import phloem

# Every module of the package, found rather than listed, so that moving code between modules
# cannot drop its examples from the run.
MODULES = sorted(m.name for m in pkgutil.walk_packages(phloem.__path__, "phloem.") if m.name != "phloem._core")
# Public modules without examples of their own.
NO_EXAMPLES = {"phloem.data"}


@pytest.mark.parametrize("module", MODULES)
def test_docstring_examples(module: str) -> None:
    mod = importlib.import_module(module)
    result = doctest.testmod(mod, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0


@pytest.mark.parametrize("module", [f"phloem.{n}" for n in phloem.__all__ if inspect.ismodule(getattr(phloem, n))])
def test_public_modules_show_examples(module: str) -> None:
    """A public module's examples live in it or in the modules of its package."""
    if module in NO_EXAMPLES:
        pytest.skip("no examples")
    mod = importlib.import_module(module)
    mods = [mod]
    if hasattr(mod, "__path__"):
        mods += [importlib.import_module(m.name) for m in pkgutil.walk_packages(mod.__path__, module + ".")]
    finder = doctest.DocTestFinder()
    assert any(t.examples for m in mods for t in finder.find(m)), f"{module} has no examples"


def test_every_docs_page_is_in_the_mkdocs_nav() -> None:
    """mkdocs.yml parses, and no page under docs/ is left out of its nav."""
    from pathlib import Path

    import yaml

    root = Path(__file__).resolve().parents[1]
    config = yaml.safe_load((root / "mkdocs.yml").read_text(encoding="utf-8"))

    def pages(nav: object) -> list[str]:
        if isinstance(nav, str):
            return [nav]
        if isinstance(nav, list):
            return [p for item in nav for p in pages(item)]
        if isinstance(nav, dict):
            return [p for value in nav.values() for p in pages(value)]
        return []

    listed = set(pages(config["nav"]))
    docs = root / config.get("docs_dir", "docs")
    on_disk = {p.relative_to(docs).as_posix() for p in docs.rglob("*.md")}
    assert on_disk <= listed, f"pages missing from the mkdocs nav: {sorted(on_disk - listed)}"
