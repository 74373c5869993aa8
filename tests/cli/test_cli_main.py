"""The phloem command as a whole: help for every option, the console script, --size, deprecated flags."""

from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from phloem.cli import _common, build_parser, main


@pytest.mark.parametrize("cmd", [[], ["synthesize"], ["quilt"], ["complete"], ["nnf"], ["bark"], ["demo"]])
def test_help_explains_every_option(cmd, capsys):
    with pytest.raises(SystemExit) as e:
        main([*cmd, "--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    assert "usage: phloem" in text
    for action in build_parser()._actions:
        assert action.help  # no undocumented option at the top level


def test_every_subcommand_option_has_help():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name, p in sub.choices.items():
        for action in p._actions:
            assert action.help, f"{name}: {action.dest} has no help"
            if action.dest == "action":  # nested sub-commands (phloem branching ...)
                for inner, q in action.choices.items():
                    for a in q._actions:
                        assert a.help, f"{name} {inner}: {a.dest} has no help"


def test_bad_size_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as e:
        main(["synthesize", "x.png", "--size", "big", "--out", "o.png"])
    assert e.value.code == 2 and "WIDTHxHEIGHT" in capsys.readouterr().err


@pytest.mark.parametrize("module", ["phloem.cli", "phloem"])
def test_python_dash_m_runs_the_command(module):
    r = subprocess.run([sys.executable, "-m", module, "--version"], capture_output=True, text=True, check=True)
    assert r.stdout.startswith("phloem ")


@pytest.mark.parametrize(("text", "hw"), [("512x384", (384, 512)), ("64X32", (32, 64)), ("512", (512, 512))])
def test_size_is_wxh_or_n(text, hw):
    assert _common.parse_size(text) == hw


@pytest.mark.parametrize("text", ["big", "3x", "x4", "1x2x3", "0x5", "0", "-5"])
def test_bad_sizes_are_refused(text):
    with pytest.raises(argparse.ArgumentTypeError, match="expected"):
        _common.parse_size(text)


def test_square_size_is_n_or_nxn():
    assert _common.parse_square_size("128") == _common.parse_square_size("128x128") == 128
    with pytest.raises(argparse.ArgumentTypeError, match="square"):
        _common.parse_square_size("128x96")


def test_every_size_flag_takes_n(capsys):
    """--size N works on every sub-command that has --size (issue 16: `--size 512` was refused)."""
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    seen = []
    for name, p in sub.choices.items():
        inner = [(name, p)]
        action = next((a for a in p._actions if a.dest == "action"), None)
        if action is not None:
            inner = [(f"{name} {n}", q) for n, q in action.choices.items()]
        for label, q in inner:
            for a in q._actions:
                if "--size" in a.option_strings:
                    assert a.type("48") in ((48, 48), 48), label
                    seen.append(label)
    assert {"synthesize", "quilt", "bark", "trees", "demo", "branching grow", "branching run"} <= set(seen)


def _cli_error(tmp_path, *argv):
    """Run the command in a subprocess; it must fail with exit 2 and one stderr line, no traceback."""
    r = subprocess.run([sys.executable, "-m", "phloem.cli", *map(str, argv)], capture_output=True, text=True,
                       timeout=120, cwd=tmp_path)  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    return r.stderr


def test_api_errors_name_the_flags_not_the_python_parameters(tmp_path, exemplar_png):
    out = tmp_path / "o.png"
    err = _cli_error(tmp_path, "bark", exemplar_png, "--size", "64", "--n-labels", "200", "--out", out, "-q")
    assert "--n-labels:" in err and " k:" not in err and " labels:" not in err
    err = _cli_error(tmp_path, "bark", tmp_path / "missing.png", "--size", "64", "--out", out)
    assert "error: IN:" in err and "path:" not in err
    err = _cli_error(tmp_path, "bark", exemplar_png, "--out", out)
    assert "--size: required unless --labels-out is given" in err
    err = _cli_error(tmp_path, "synthesize", exemplar_png, "--size", "8", "--out", exemplar_png)
    assert "--force" in err and "overwrite=True" not in err and "--out:" in err


@pytest.mark.parametrize("cmd", [["synthesize", "{ex}"], ["bark", "{ex}"]])
@pytest.mark.parametrize("size", [["--size", "-5x5"], ["--size=-5x5"], ["--size", "-5"]])
def test_negative_size_is_named_not_taken_for_an_option(tmp_path, exemplar_png, cmd, size):
    argv = [a.format(ex=exemplar_png) for a in cmd] + size + ["--out", str(tmp_path / "o.png"), "-q"]
    r = subprocess.run([sys.executable, "-m", "phloem.cli", *argv], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    last = r.stderr.strip().splitlines()[-1]  # argparse puts its usage lines above the one error line
    assert "--size: expected WxH or N with positive integers" in last and "'-5" in last, r.stderr
    assert "expected one argument" not in r.stderr
    assert not (tmp_path / "o.png").exists()
