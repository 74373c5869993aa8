"""``phloem studio``: its help, its one-line errors, and a real server started by the command,
answering with the token it printed and stopping on Ctrl-C."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import httpx
import pytest

from phloem.cli import main


def test_help_explains_the_command(capsys):
    with pytest.raises(SystemExit) as e:
        main(["studio", "--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    for words in ("PROJECT_DIR", "--port", "--host", "--no-browser", "127.0.0.1", "token", "phloem[studio]"):
        assert words in text


def test_a_project_under_a_missing_folder_is_a_one_line_error(tmp_path, capsys):
    assert main(["studio", str(tmp_path / "a" / "b"), "--no-browser"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"phloem studio: error: PROJECT_DIR: {tmp_path / 'a' / 'b'} is not a folder"]


def test_a_bad_port_names_it(tmp_path, capsys):
    assert main(["studio", str(tmp_path), "--port", "70000", "--no-browser"]) == 2
    assert "--port: expected 0 to 65535, got 70000" in capsys.readouterr().err


def test_the_command_serves_the_page_with_its_token_and_stops_on_ctrl_c(tmp_path: Path):
    project = tmp_path / "new-project"  # made by the command
    with subprocess.Popen(
        [sys.executable, "-m", "phloem.cli", "studio", str(project), "--port", "0", "--no-browser"],
        stderr=subprocess.PIPE,
        text=True,
    ) as p:
        try:
            assert p.stderr is not None
            lines = [p.stderr.readline() for _ in range(2)]
            url = lines[1].removeprefix("open ").strip()
            assert url.startswith("http://127.0.0.1:") and "/?token=" in url, lines
            base, token = url.split("/?token=")
            assert len(token) >= 32 and project.is_dir()
            assert httpx.get(url, timeout=30).status_code == 200
            assert httpx.get(f"{base}/api/info", timeout=30).status_code == 401
            info = httpx.get(f"{base}/api/info", headers={"X-Phloem-Token": token}, timeout=30).json()
            assert info["project"] == str(project.resolve())
            p.send_signal(signal.SIGINT)
            assert p.wait(timeout=30) == 0
            assert p.stderr.read().strip().splitlines()[-1] == "phloem studio: stopped"
        finally:
            if p.poll() is None:
                p.kill()
