"""phloem.batch.run and ``phloem batch``: the files of a batch are those of its single command
lines, byte for byte; reruns, kills, failures and remote schedulers (issue 21)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

import phloem.data
from phloem import batch
from phloem.cli import main

from .conftest import outputs, write_spec

ENV = {**os.environ, "PYTHONPATH": str(Path(phloem.__file__).parents[1])}


def _records(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / "manifest.jsonl").read_text().splitlines()]


def _no_temporaries(out: Path) -> None:
    assert not [p.name for p in out.rglob(".*")], "hidden temporaries left behind"


def test_batch_is_the_single_runs_byte_for_byte(client, tmp_path: Path):
    out = tmp_path / "out"
    summary = batch.run(write_spec(tmp_path), out_dir=out, client=client)
    assert (summary.total, summary.made, summary.skipped, summary.failed) == (20, 20, 0, {})
    made = outputs(out)
    assert len(made) == 40  # 20 images and their sidecars
    records = _records(out)
    assert sorted(r["item"] for r in records) == sorted(it.name for it in batch.load_spec(write_spec(tmp_path)).items)
    assert all(r["status"] == "ok" and r["attempts"] == 1 and r["seconds"] > 0 for r in records)
    # the 20 single command lines, as the manifest recorded them, into the same (emptied) folder
    shutil.rmtree(out)
    out.mkdir()  # the batch makes its folder; a single --out run needs it
    for r in records:
        assert main(r["argv"]) == 0
    assert outputs(out) == made
    _no_temporaries(out)


def test_rerun_does_no_work_and_remakes_only_what_fails_to_verify(client, tmp_path: Path):
    out = tmp_path / "out"
    spec = write_spec(tmp_path, seeds="0..3")
    assert batch.run(spec, out_dir=out, client=client).made == 4
    before = outputs(out)
    again = batch.run(spec, out_dir=out, client=client)
    assert (again.submitted, again.made, again.skipped) == (0, 0, 4)
    # a damaged image and a deleted sidecar: those two items are made again, the same bytes
    victim = sorted(out.glob("*-s1.png"))[0]
    victim.write_bytes(b"damaged")
    sorted(out.glob("*-s2.png.json"))[0].unlink()
    third = batch.run(spec, out_dir=out, client=client)
    assert (third.submitted, third.made, third.skipped) == (2, 2, 2)
    assert outputs(out) == before


def test_failing_item_retried_once_then_recorded(client, tmp_path: Path):
    (tmp_path / "in").mkdir()
    shutil.copy(phloem.data.path("brick.png"), tmp_path / "in" / "good.png")
    (tmp_path / "in" / "bad.png").write_bytes(b"this is no image")
    out = tmp_path / "out"
    summary = batch.run(write_spec(tmp_path, seeds=[0, 1], inputs=["in/*.png"]), out_dir=out, client=client)
    assert summary.made == 2 and sorted(summary.failed) == sorted(n for n in summary.failed if n.startswith("bad-"))
    assert len(summary.failed) == 2 and summary.submitted == 6  # 2 good, 2 bad twice
    assert not summary.ok
    bad = [r for r in _records(out) if r["item"].startswith("bad-")]
    assert len(bad) == 2 and all(r["status"] == "failed" and r["attempts"] == 2 for r in bad)
    assert all("bad.png" in r["error"] and "\n" not in r["error"] for r in bad)
    assert not list(out.glob("bad-*"))


def test_cli_exit_status_and_summary(tmp_path: Path, capsys):
    (tmp_path / "bad.png").write_bytes(b"this is no image")
    spec = write_spec(tmp_path, seeds=[0], inputs=["bad.png", phloem.data.path("brick.png")])
    assert main(["batch", str(spec), "--out-dir", str(tmp_path / "out"), "--workers", "2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("phloem batch: error: 2 items: 1 made, 0 already done, 1 failed")
    assert main(["batch", str(tmp_path / "none.yaml"), "--out-dir", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.startswith("phloem batch: error: SPEC: cannot read")


def test_sigkill_mid_batch_then_rerun_completes_the_set(client, tmp_path: Path):
    spec = write_spec(tmp_path, seeds="0..11", size="64x64")
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "phloem", "batch", str(spec), "--out-dir", str(out), "--workers", "2", "-q"]
    proc = subprocess.Popen(cmd, env=ENV, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    while not ((out / "manifest.jsonl").exists() and (out / "manifest.jsonl").stat().st_size > 0):
        assert proc.poll() is None and time.monotonic() < deadline, "the batch ended before its first item"
        time.sleep(0.05)
    proc.kill()  # SIGKILL: no clean-up of any kind in the driver
    proc.communicate()
    assert proc.returncode == -signal.SIGKILL
    before = batch.Manifest(out)
    recorded = before.records()
    first = len(recorded)
    # what the killed driver recorded is whole: every recorded item's files are there and verify
    assert first >= 1 and all(before.verified(r) for r in recorded.values())
    # the cluster's worker processes go with their driver; wait for them before counting files
    time.sleep(1.0)
    rerun = batch.run(spec, out_dir=out, client=client)
    assert rerun.ok and rerun.made + rerun.skipped == 12 and rerun.skipped >= first, rerun.line()
    _no_temporaries(out)
    ok = batch.Manifest(out)
    assert all(ok.verified(r) for r in ok.records().values()) and len(ok.records()) == 12
    assert len(outputs(out)) == 24


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_a_rerun_removes_temporaries_of_dead_writers_only(client, tmp_path: Path):
    spec = write_spec(tmp_path, seeds="0..1", size="64x64")
    out = tmp_path / "out"
    assert batch.run(spec, out_dir=out, client=client).ok
    first = out / sorted(outputs(out))[0]
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    left = first.with_name(f".{first.name}.{dead.pid}.abcd1234.tmp")  # a worker killed while staging it
    live = first.with_name(f".{first.name}.{os.getpid()}.wxyz5678.tmp")  # a writer that still runs
    left.write_bytes(b"partial")
    live.write_bytes(b"partial")
    rerun = batch.run(spec, out_dir=out, client=client)
    assert rerun.made == 0 and not left.exists() and live.exists()
    live.unlink()
    _no_temporaries(out)


def test_scheduler_in_another_process(tmp_path: Path):
    address = f"tcp://127.0.0.1:{_free_port()}"
    port = address.rsplit(":", 1)[1]
    procs = [
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "distributed.cli.dask_scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                port,
                "--no-dashboard",
            ],
            env=ENV,
            stderr=subprocess.DEVNULL,
        ),
    ]
    try:
        procs.append(
            subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "distributed.cli.dask_worker",
                    address,
                    "--nthreads",
                    "1",
                    "--no-dashboard",
                    "--memory-limit",
                    "2GiB",
                ],
                env=ENV,
                stderr=subprocess.DEVNULL,
            )
        )
        spec = write_spec(tmp_path, seeds="0..3")
        res = subprocess.run([sys.executable, "-m", "phloem", "batch", str(spec), "--out-dir", str(tmp_path / "out"),
                              "--scheduler", address], env=ENV, capture_output=True, text=True, timeout=120)  # fmt: skip
        assert res.returncode == 0, res.stderr
        assert "4 items: 4 made" in res.stderr
        records = _records(tmp_path / "out")
        # the task took the remote worker's share: its one thread and its memory limit
        assert all(r["argv"][r["argv"].index("--threads") + 1] == "1" for r in records)
        assert all(r["argv"][r["argv"].index("--max-memory") + 1] == str(2 * 2**30) for r in records)
    finally:
        for p in reversed(procs):
            p.terminate()
            p.wait(timeout=30)


def test_trees_batch_prepares_the_library_once(client, tmp_path: Path):
    import numpy as np

    from phloem.trees import library as library_module

    lib = tmp_path / "lib"
    lib.mkdir()
    rng = np.random.default_rng(0)
    for s in range(2):  # two blob trees: a crown disk over a trunk, jittered
        img = np.zeros((120, 90, 4), np.float32)
        yy, xx = np.mgrid[:120, :90]
        r = 30 + 5 * s
        img[(yy - 45) ** 2 + (xx - 45) ** 2 < r * r] = (0.1, 0.5 + 0.1 * s, 0.1, 1.0)
        img[70:118, 40:50] = (0.4, 0.3, 0.2, 1.0)
        img[..., :3] += rng.uniform(0, 0.05, img.shape[:2] + (3,)).astype(np.float32) * img[..., 3:]
        phloem.io.write_image(lib / f"t{s}.png", img)
    spec = tmp_path / "trees.yaml"
    spec.write_text("job: trees\ninputs: [lib]\nparams: {n-variations: 1, size: 96}\nseeds: 0..3\n")
    out = tmp_path / "out"
    summary = batch.run(spec, out_dir=out, client=client)
    assert summary.ok and summary.made == 4, summary.line()
    assert len(list((out / ".phloem-cache").iterdir())) == 1  # prepared by the first item, read by the others
    records = _records(out)
    assert [r["argv"].count("--library-cache") for r in records] == [1] * 4
    # a cache named in the spec, in either spelling, is the one used
    spec.write_text("job: trees\ninputs: [lib]\nparams: {n-variations: 1, size: 96, library-cache: k}\nseeds: [0]\n")
    assert batch.run(spec, out_dir=tmp_path / "out2", client=client).ok
    assert _records(tmp_path / "out2")[0]["argv"].count("--library-cache") == 1
    assert (tmp_path / "k").is_dir() and not (tmp_path / "out2" / ".phloem-cache").exists()
    made = outputs(out)
    assert sum(name.endswith(".png") for name in made) == 4
    # each item alone, with no cache at all: the same trees
    for r in records:
        argv = r["argv"]
        i = argv.index("--library-cache")
        alone = tmp_path / "alone" / Path(argv[argv.index("--out-dir") + 1]).name
        argv = [*argv[:i], *argv[i + 2 :]]
        argv[argv.index("--out-dir") + 1] = str(alone)
        library_module._loaded.clear()
        assert main(argv) == 0
    for name, data in made.items():
        if name.endswith(".png") and not name.startswith(".phloem-cache"):
            assert (tmp_path / "alone" / name).read_bytes() == data, name


def test_a_local_cluster_leaves_the_callers_environment_alone():
    # Dask's nannies set OMP_NUM_THREADS=1, MALLOC_TRIM_THRESHOLD_ ... in the spawning process; a
    # caller's later subprocesses (its own phloem runs) would inherit them
    before = dict(os.environ)
    with batch.local_cluster(1):
        assert dict(os.environ) == before
    assert dict(os.environ) == before


def test_small_items_are_chunked_and_still_each_recorded(client, tmp_path: Path):
    # 8×8 syntheses take milliseconds: after a probe of single items they go several to a task
    out = tmp_path / "out"
    summary = batch.run(write_spec(tmp_path, seeds="0..59", size="8x8"), out_dir=out, client=client)
    assert summary.ok and summary.made == 60, summary.line()
    assert summary.submitted < 30, summary.line()
    records = _records(out)
    assert len(records) == 60 and len({r["item"] for r in records}) == 60
    ok = batch.Manifest(out)
    assert all(ok.verified(r) for r in ok.records().values())
    # each recorded command line, run alone, makes the very same bytes
    made = outputs(out)
    shutil.rmtree(out)
    out.mkdir()
    for r in records[::7]:
        assert main(r["argv"]) == 0
    assert all(made[name] == data for name, data in outputs(out).items())


def test_chunk_size_fills_half_a_second_and_keeps_four_tasks_per_worker():
    from phloem.batch.schedule import _chunk_size

    assert _chunk_size([0.04] * 6, 190, 2) == 12  # 0.5 s / 40 ms
    assert _chunk_size([0.01] * 6, 40, 2) == 5  # 40 left on 2 workers: no fewer than 8 tasks
    assert _chunk_size([1.3] * 6, 40, 2) == 1  # items of seconds go singly
    # each worker's first item reads the shared model: those seconds do not set the chunk
    assert _chunk_size([2.98, 3.1, 0.06, 0.06], 290, 2) == 8
    assert _chunk_size([], 10, 2) == 1


# a terminal's Ctrl-C goes to the whole process group, workers included; `kill -INT` to the driver alone
@pytest.mark.parametrize("group", [True, False], ids=["terminal", "driver"])
def test_ctrl_c_keeps_the_finished_items_and_says_so(tmp_path: Path, group: bool):
    spec = write_spec(tmp_path, seeds="0..39", size="64x64")
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "phloem", "batch", str(spec), "--out-dir", str(out), "--workers", "2", "-q"]
    proc = subprocess.Popen(cmd, env=ENV, stderr=subprocess.PIPE, text=True, start_new_session=group)
    deadline = time.monotonic() + 60
    while not ((out / "manifest.jsonl").exists() and (out / "manifest.jsonl").stat().st_size > 0):
        assert proc.poll() is None and time.monotonic() < deadline, "the batch ended before its first item"
        time.sleep(0.05)
    if group:
        os.killpg(proc.pid, signal.SIGINT)
    else:
        proc.send_signal(signal.SIGINT)
    err = proc.communicate(timeout=60)[1]
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == ["phloem batch: interrupted; finished items are kept; run it again to go on"]
    kept = batch.Manifest(out)
    assert kept.records() and all(kept.verified(r) for r in kept.records().values())


def test_a_ctrl_c_python_swallows_still_stops_the_batch(client, tmp_path: Path):
    # a Ctrl-C landing in a garbage collector callback (Dask's GC diagnosis does this) is only
    # printed as "Exception ignored" by Python: the batch ran on to its end with status 0
    import gc

    def swallowed_ctrl_c(phase: str, info: dict) -> None:
        gc.callbacks.remove(swallowed_ctrl_c)
        raise KeyboardInterrupt

    def progress(done: int, total: int) -> None:
        if done == 1:
            gc.callbacks.append(swallowed_ctrl_c)
            gc.collect()

    out = tmp_path / "out"
    spec = write_spec(tmp_path, seeds="0..39", size="64x64")
    hook = sys.unraisablehook
    with pytest.raises(KeyboardInterrupt):
        batch.run(spec, out_dir=out, client=client, progress=progress)
    assert sys.unraisablehook is hook  # Python's own reporting of other unraisable errors is back
    done = batch.Manifest(out).records()
    assert len(done) < 40, "the batch ran on to its end after the Ctrl-C"
    assert {r["status"] for r in done.values()} == {"ok"}
    # what it kept is kept: the rerun makes exactly the items the interrupt left
    again = batch.run(spec, out_dir=out, client=client)
    assert (again.skipped, again.made) == (len(done), 40 - len(done)), again.line()


def test_local_workers_keep_glibcs_own_malloc_trimming(client):
    # Dask's default MALLOC_TRIM_THRESHOLD_=65536 made every tree variation a third slower
    got = client.run(lambda: os.environ.get("MALLOC_TRIM_THRESHOLD_"))
    assert set(got.values()) == {os.environ.get("MALLOC_TRIM_THRESHOLD_")}


def test_extra_outputs_asked_by_true_are_per_item_hashed_and_verified(client, tmp_path: Path):
    import numpy as np

    img = np.zeros((64, 80), np.float32)
    img[30:34, 5:75] = 1.0
    img[10:34, 40:43] = 1.0
    phloem.io.write_image(tmp_path / "river.png", img)
    spec = tmp_path / "spec.yaml"
    spec.write_text("job: branching trace\ninputs: [river.png]\nparams: {kind: mask, overlay: true}\nseeds: [0, 1]\n")
    out = tmp_path / "out"
    summary = batch.run(spec, out_dir=out, client=client)
    assert summary.ok and summary.made == 2, summary.line()
    for r in _records(out):
        name = r["item"]
        # the skeleton, its sidecar (X.sidecar.json) and the item's own overlay
        assert sorted(r["outputs"]) == sorted([f"{name}.json", f"{name}.sidecar.json", f"{name}_overlay.png"])
        assert phloem.io.read_image(out / f"{name}_overlay.png").shape[:2] == (64, 80)
    # an extra output gone: its item is made again, the other is not
    first = _records(out)[0]["item"]
    (out / f"{first}_overlay.png").unlink()
    again = batch.run(spec, out_dir=out, client=client)
    assert (again.made, again.skipped) == (1, 1) and (out / f"{first}_overlay.png").is_file()


def test_a_ctrl_c_while_the_cluster_starts_is_held_until_it_is_up():
    from phloem.batch.schedule import _interrupts_held

    seen: list[object] = []
    with pytest.raises(KeyboardInterrupt), _interrupts_held():
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.2)  # a KeyboardInterrupt here would leave a half-started cluster
        # threads started meanwhile, and the worker processes they spawn, keep SIGINT blocked
        t = threading.Thread(target=lambda: seen.append(signal.pthread_sigmask(signal.SIG_BLOCK, set())))
        t.start()
        t.join()
        seen.append("built")
    assert seen == [{signal.SIGINT}, "built"]
    assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, set())
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
