"""Jobs: the worker pool, progress, cancellation of queued and running jobs (a real engine too),
and failures that leave the pool serving."""

from __future__ import annotations

import json
import threading

import pytest

import phloem
from phloem.studio import JobManager


def _loop_until_cancelled(progress):
    while True:  # ends only by the cancel: its progress call raises
        progress(0, 1)
        threading.Event().wait(0.005)


def test_a_job_reports_progress_then_its_outputs():
    m = JobManager()
    seen = []
    submitted = threading.Event()

    def work(progress):
        submitted.wait(30)
        for i in range(3):
            progress(i + 1, 3)
            seen.append(m.get(job.id).done)
        return ["a.png"]

    job = m.submit("count", {"n": 3}, work)
    submitted.set()
    done = m.wait(job.id, timeout=30)
    m.shutdown()
    assert done.state == "done" and done.outputs == ["a.png"] and (done.done, done.total) == (3, 3)
    assert seen == [1, 2, 3]


def test_a_running_engine_stops_when_cancelled_and_the_pool_goes_on():
    """bark.generate itself stops: its progress callback raises once the job is cancelled."""
    m = JobManager()
    reported = threading.Event()
    go_on = threading.Event()
    finished = []

    def work(progress):
        def gated(done, total):
            reported.set()
            go_on.wait(30)
            progress(done, total)

        phloem.bark.generate(phloem.data.bark()[:64, :64, :3], (48, 48), threads=1, progress=gated)
        finished.append(True)  # never reached: the engine raised
        return []

    job = m.submit("bark", {}, work)
    assert reported.wait(30)
    m.cancel(job.id)
    go_on.set()
    assert m.wait(job.id, timeout=60).state == "cancelled"
    assert finished == []
    after = m.submit("next", {}, lambda progress: ["ok"])
    assert m.wait(after.id, timeout=30).outputs == ["ok"]
    m.shutdown()


def test_a_queued_job_cancelled_never_starts():
    m = JobManager(workers=1)
    blocker = m.submit("block", {}, _loop_until_cancelled)
    ran = []
    queued = m.submit("queued", {}, lambda progress: ran.append(1) or [])
    assert m.get(queued.id).state == "queued"
    m.cancel(queued.id)
    assert m.get(queued.id).state == "cancelled"
    m.cancel(blocker.id)
    assert m.wait(blocker.id, timeout=30).state == "cancelled"
    m.shutdown()
    assert ran == []


@pytest.mark.parametrize(
    ("error", "state", "message"),
    [
        (ValueError("size: too big"), "failed", "size: too big"),
        (ZeroDivisionError("x"), "failed", "internal error: ZeroDivisionError"),
    ],
)
def test_a_failing_job_is_reported_and_the_pool_goes_on(error, state, message, caplog):
    m = JobManager()

    def work(progress):
        raise error

    job = m.wait(m.submit("bad", {}, work).id, timeout=30)
    assert job.state == state and job.message.startswith(message)
    assert m.wait(m.submit("good", {}, lambda p: ["x"]).id, timeout=30).state == "done"
    m.shutdown()


def test_workers_must_be_positive():
    with pytest.raises(ValueError, match="workers: "):
        JobManager(workers=0)


# -- over HTTP ------------------------------------------------------------------------------------
def _events(client, job_id):
    with client.stream("GET", f"/api/jobs/{job_id}/events") as r:
        return [json.loads(line[6:]) for line in r.iter_lines() if line.startswith("data: ")]


def test_cancel_over_http_ends_the_event_stream_and_writes_nothing(client, project):
    manager = client.app.state.jobs
    running = manager.submit("block", {}, _loop_until_cancelled)
    # queued behind it: a real job, cancelled before it starts
    r = client.post("/api/jobs", json={"kind": "bark-labels", "image": "photos/bark.png", "out": "l.png"})
    queued = r.json()["id"]
    assert r.status_code == 202 and r.json()["state"] == "queued"
    assert client.post(f"/api/jobs/{queued}/cancel").json()["state"] == "cancelled"
    r = client.post(f"/api/jobs/{running.id}/cancel")
    assert r.status_code == 200
    events = _events(client, running.id)
    assert events[-1]["state"] == "cancelled"
    assert _events(client, queued)[-1]["state"] == "cancelled"
    assert not (project.root / "l.png").exists()
    # a finished job stays as it ended
    assert client.post(f"/api/jobs/{running.id}/cancel").json()["state"] == "cancelled"
