"""The wheel installs and works where no Rust toolchain is: ``make wheel`` (or the wheel named by
``PHLOEM_WHEEL``) into a fresh virtualenv, then ``phloem demo`` and the README's Python tour.

Minutes of work (a release build, then numpy, OpenCV, scikit-image… from PyPI into the new
environment), so it runs only when asked: ``pytest -m wheel`` (CI runs it after the main suite,
see ``.ci/run``). ``PHLOEM_WHEEL=dist/phloem-….whl pytest -m wheel`` skips the build.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

pytestmark = [pytest.mark.wheel, pytest.mark.timeout(1800)]

ROOT = Path(__file__).resolve().parents[1]
#: Environment variables that would let the venv see the checkout or a Rust toolchain.
_DROP = ("PYTHONPATH", "PYTHONHOME", "CARGO_HOME", "RUSTUP_HOME", "RUSTUP_TOOLCHAIN", "VIRTUAL_ENV")
_TOOLS = ("cargo", "rustc", "rustup", "maturin")


def _readme_blocks() -> list[str]:
    """The README's python blocks, as tests/test_readme.py extracts them."""
    spec = importlib.util.spec_from_file_location("_phloem_readme_test", Path(__file__).with_name("test_readme.py"))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    blocks: list[str] = module._blocks("python")
    return blocks


def _no_rust_env(venv: Path) -> dict[str, str]:
    """This process's environment with the venv first on PATH and every directory that holds a
    Rust tool (or the checkout's sources) taken off it."""
    env = {k: v for k, v in os.environ.items() if k not in _DROP}
    keep = [
        d
        for d in env.get("PATH", "").split(os.pathsep)
        if d and not any(shutil.which(t, path=d) for t in _TOOLS) and ".cargo" not in d and "rustup" not in d
    ]
    env["PATH"] = os.pathsep.join([str(venv / "bin"), *keep])
    env["VIRTUAL_ENV"] = str(venv)
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    return env


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    given = os.environ.get("PHLOEM_WHEEL")
    if given:
        path = Path(given).resolve()  # pip runs in a temporary folder
        if not path.is_file():
            pytest.fail(f"PHLOEM_WHEEL: {given} is not a file")
        return path
    out = tmp_path_factory.mktemp("dist")
    subprocess.run(["make", "-C", str(ROOT), "wheel", f"DIST={out}"], check=True)
    (path,) = out.glob("phloem-*.whl")
    return path


def test_wheel_is_abi3_manylinux_with_the_embedded_data(wheel: Path) -> None:
    name = wheel.name
    assert "-abi3-" in name, name
    if sys.platform.startswith("linux"):
        assert "manylinux" in name, f"{name}: not a manylinux tag PyPI accepts"
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
    assert any(n.startswith("phloem/_core") for n in names)
    data = {n for n in names if n.startswith("phloem/data/")}
    shipped = {f"phloem/data/{p.name}" for p in (ROOT / "python" / "phloem" / "data").iterdir() if p.is_file()}
    assert shipped and shipped <= data, sorted(shipped - data)
    assert "phloem/py.typed" in names


def test_wheel_installs_and_runs_without_rust(wheel: Path, tmp_path: Path) -> None:
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    env = _no_rust_env(venv)
    for tool in _TOOLS:
        assert shutil.which(tool, path=env["PATH"]) is None, f"{tool} is still on PATH"
    py = str(venv / "bin" / "python")
    # --only-binary: a missing wheel for a dependency must not quietly start a source build.
    subprocess.run(
        [py, "-m", "pip", "install", "--only-binary", ":all:", str(wheel)], check=True, env=env, cwd=tmp_path
    )
    work = tmp_path / "work"
    work.mkdir()
    where = subprocess.run(
        [py, "-c", "import phloem; print(phloem.__file__)"],
        check=True,
        env=env,
        cwd=work,
        capture_output=True,
        text=True,
    ).stdout.strip()
    assert Path(where).resolve().is_relative_to(venv.resolve()), where

    subprocess.run([str(venv / "bin" / "phloem"), "demo", "--out", "demo.png"], check=True, env=env, cwd=work)
    assert (work / "demo.png").stat().st_size > 1000
    assert (work / "demo.png.json").is_file()

    tour = work / "tour"
    tour.mkdir()
    script = tour / "readme_tour.py"
    script.write_text("\n\n".join(_readme_blocks()), encoding="utf-8")
    done = subprocess.run([py, script.name], env=env, cwd=tour, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-4000:]
