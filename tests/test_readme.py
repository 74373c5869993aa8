"""The README is a page a newcomer copies from: its Python tour runs as written, and its test
command is the one CI runs."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def _blocks(language: str) -> list[str]:
    return re.findall(rf"^```{language}\n(.*?)^```$", README.read_text(encoding="utf-8"), re.S | re.M)


def test_ci_runs_the_readme_test_command_first() -> None:
    """The README's test command (the sh block after "To run every test") is, character for
    character, the first command of .ci/run after its guarded apt-get step (system packages that
    pip cannot install: the browser of the studio's end-to-end tests)."""
    text = README.read_text(encoding="utf-8")
    after = text[text.index("To run every test") :]
    readme_command = re.search(r"^```sh\n(.*?)\n```$", after, re.S | re.M)
    assert readme_command is not None
    ci = [
        line
        for line in (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()
        if line.strip() and not line.startswith(("#", "set ", "cd ", "if command -v apt-get "))
    ]
    assert ci[0] == readme_command.group(1)
    assert "make lint" in ci[1:]


def test_python_blocks_run_in_order_in_an_empty_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    blocks = _blocks("python")
    assert blocks, "the README has no python block"
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, object] = {"__name__": "__readme__"}
    for i, block in enumerate(blocks):
        exec(compile(block, f"README.md python block {i + 1}", "exec"), namespace)
