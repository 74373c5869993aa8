"""Ctrl-C during a long job: the command stops promptly, writes nothing and says so in one line."""

from __future__ import annotations

import signal
import subprocess
import sys
import time


def test_ctrl_c_stops_a_long_bark_run_promptly(tmp_path):
    out = tmp_path / "o.png"
    # 2048² takes tens of seconds on two cores; Rust stages that did not poll for cancellation
    # held the interrupt for 6-15 s at 1024².
    p = subprocess.Popen(
        [sys.executable, "-m", "phloem", "bark", "--out", str(out), "--size", "2048x2048", "-q"],
        stderr=subprocess.PIPE,
        text=True,
    )
    time.sleep(4.0)
    assert p.poll() is None, "the run ended before it could be interrupted"
    sent = time.monotonic()
    p.send_signal(signal.SIGINT)
    err = p.communicate(timeout=60)[1]
    waited = time.monotonic() - sent
    assert p.returncode == 130, err
    assert err.strip().splitlines() == ["phloem bark: interrupted; nothing was written"]
    assert waited < 5.0, f"took {waited:.1f} s to stop"
    assert list(tmp_path.iterdir()) == []
