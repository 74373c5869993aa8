"""The studio's responsiveness budgets of issue 20, measured once in headless chromium (a script,
not a test: timings belong here, not in ``tests/``).

- a skeleton vertex drag: a ``pointermove`` dispatched on the branching canvas until the frame
  after it (two ``requestAnimationFrame`` callbacks), for a traced skeleton and a dense one;
- a 256² preview job of each engine kind the studio runs: submitted to its first event with a
  progress total (over HTTP, server-sent events);
- the page load (navigation start to ``load``).

Run:  PYTHONPATH=python python benches/python/studio_latency.py   (needs chromium, chromedriver, selenium)
"""

from __future__ import annotations

import json
import shutil
import socket
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from statistics import median
from typing import Any

import numpy as np

import phloem
from phloem import io
from phloem.branching import Branch, Skeleton
from phloem.studio import Project, create_app
from phloem.testing import channel_scene, river_picture, river_skeleton

TOKEN = "bench"


def _serve(root: Path) -> tuple[str, Any]:
    import uvicorn

    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    app = create_app(Project(root), token=TOKEN)
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning"))
    threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True).start()
    url = f"http://127.0.0.1:{sock.getsockname()[1]}"
    for _ in range(100):
        try:
            urllib.request.urlopen(f"{url}/api/info?token={TOKEN}", timeout=1)
            break
        except OSError:
            time.sleep(0.05)
    return url, server


def _first_progress(url: str, body: dict[str, Any]) -> tuple[float, float]:
    """Seconds from submitting a job to its first event with a progress total, and to its end."""
    req = urllib.request.Request(f"{url}/api/jobs?token={TOKEN}", json.dumps(body).encode(),
                                 {"Content-Type": "application/json"})  # fmt: skip
    t0 = time.perf_counter()
    job = json.load(urllib.request.urlopen(req))
    first = None
    with urllib.request.urlopen(f"{url}/api/jobs/{job['id']}/events?token={TOKEN}") as r:
        for line in r:
            if not line.startswith(b"data: "):
                continue
            s = json.loads(line[6:])
            if first is None and s["total"] > 0:
                first = time.perf_counter() - t0
            if s["state"] in ("done", "failed", "cancelled"):
                assert s["state"] == "done", s
                break
    return float(first if first is not None else np.nan), time.perf_counter() - t0


DRAG = """
const [b, v, n, done] = arguments;
const c = document.getElementById('br-canvas');
const r = c.getBoundingClientRect();
const [x, y] = K.branches[b].points[v];
const at = (px, py) => ({clientX: r.left + c.clientLeft + (px + 0.5) * c.clientWidth / c.width,
                         clientY: r.top + c.clientTop + (py + 0.5) * c.clientHeight / c.height,
                         pointerId: 1, bubbles: true});
c.dispatchEvent(new PointerEvent('pointerdown', at(x, y)));
if (!K.drag) { done(["no vertex under the pointer", K.branches.length, x, y, c.width, c.clientWidth]); return; }
const handler = [], frame = [], after = [];
let i = 0;
function step() {
  const t0 = performance.now();
  c.dispatchEvent(new PointerEvent('pointermove', at(x + 1 + (i % 10), y + 1)));
  handler.push(performance.now() - t0);
  requestAnimationFrame(() => {
    frame.push(performance.now() - t0);
    requestAnimationFrame(() => {
      after.push(performance.now() - t0);
      if (++i < n) step();
      else { c.dispatchEvent(new PointerEvent('pointerup', at(x, y))); done([handler, frame, after]); }
    });
  });
}
step();
"""


def main() -> None:
    from selenium import webdriver
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select, WebDriverWait

    root = Path(tempfile.mkdtemp(prefix="phloem-studio-bench-"))
    (root / "photos").mkdir()
    img, sk = channel_scene(0)
    io.write_image(root / "photos" / "channel.png", img)
    sk.save(root / "photos" / "channel_skeleton.json")
    # a dense skeleton: a 1024² river, every branch resampled to 0.5 px steps
    river = river_skeleton((1024, 1024), scale=3.0, children=6)
    dense = Skeleton([Branch(b.resample(0.5).points, 3.0, b.parent) for b in river.branches], river.shape)
    dense = dense.resample(0.5)
    io.write_image(root / "photos" / "river.png", river_picture(river))
    dense.save(root / "photos" / "river_skeleton.json")
    io.write_image(root / "photos" / "bark.png", phloem.data.bark()[:256, :256, :3])
    url, server = _serve(root)

    opts = webdriver.ChromeOptions()
    opts.binary_location = shutil.which("chromium") or ""
    for flag in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--window-size=1400,900",
    ):
        opts.add_argument(flag)
    d = webdriver.Chrome(options=opts, service=webdriver.ChromeService(executable_path=shutil.which("chromedriver")))
    d.set_script_timeout(120)
    try:
        loads = []
        for _ in range(5):
            d.get(f"{url}/?token={TOKEN}")
            WebDriverWait(d, 30).until(lambda d: d.execute_script("return document.body.dataset.ready") == "1")
            loads.append(d.execute_script("const t = performance.timing; return t.loadEventEnd - t.navigationStart"))
        print(f"page load (ms), 5 loads: {loads}")
        d.find_element(By.CSS_SELECTOR, '#tabs button[data-ws="branching"]').click()
        for photo, skel in (("photos/channel.png", sk), ("photos/river.png", dense)):
            Select(d.find_element(By.ID, "br-image")).select_by_value(photo)
            WebDriverWait(d, 30).until(
                lambda d, s=skel: d.execute_script("return document.getElementById('br-canvas').height") == s.shape[0]
            )
            d.find_element(By.ID, "br-load").click()
            WebDriverWait(d, 60).until(
                lambda d, p=photo: f"loaded {p[:-4]}_skeleton" in d.find_element(By.ID, "br-msg").text
            )
            verts = sum(len(b) for b in skel.branches)
            b = 0
            got = d.execute_async_script(DRAG, b, len(skel.branches[b]) // 2, 40)
            assert len(got) == 3, (got, d.get_log("browser"))
            handler, frame, after = got
            print(f"vertex drag, {photo} ({verts} vertices, {len(skel.branches)} branches), 40 moves: handler (redraw) "
                  f"median {median(handler):.1f} ms, max {max(handler):.1f}; to the frame that shows it (first rAF) median "
                  f"{median(frame):.1f}, max {max(frame):.1f}; to the frame after it median {median(after):.1f}, max {max(after):.1f}")  # fmt: skip
    finally:
        d.quit()
    jobs = {
        "bark-texture": {"kind": "bark-texture", "image": "photos/bark.png", "size": [256, 256]},
        "texture-synthesize": {"kind": "texture-synthesize", "image": "photos/bark.png", "size": [256, 256]},
        "texture-quilt": {"kind": "texture-quilt", "image": "photos/bark.png", "size": [256, 256]},
        "branching-grow": {"kind": "branching-grow", "skeleton": "photos/channel_skeleton.json", "size": [256, 256]},
        "branching-render": {
            "kind": "branching-render",
            "image": "photos/channel.png",
            "skeleton": "photos/channel_skeleton.json",
            "target": "photos/channel_skeleton.json",
        },
    }
    for name, body in jobs.items():
        runs = [_first_progress(url, {**body, "seed": s}) for s in range(3)]
        print(f"{name}: first progress {[round(a, 2) for a, _ in runs]} s, done {[round(b, 2) for _, b in runs]} s")
    server.should_exit = True


if __name__ == "__main__":
    main()
