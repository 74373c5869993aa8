"""End to end in a real headless browser: Debian's chromium driven by Selenium through Debian's
chromium-driver (no browser download). Opens the page, draws strokes and paints a label map with
mouse events, renders, and checks the files on disk. Skips when chromium or its driver is absent.

Screenshots go to ``$PHLOEM_SCREENSHOTS`` (default ``out/screenshots``, which git ignores).
"""

from __future__ import annotations

import json
import os
import shutil
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import phloem
from phloem import bark, io
from phloem.branching import Skeleton
from phloem.strokes import StrokeSet
from phloem.testing import channel_scene, layered_leaf

from .conftest import TOKEN, tree_image

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
DRIVER = shutil.which("chromedriver")
if CHROMIUM is None or DRIVER is None:
    pytest.skip("Debian's chromium and chromium-driver are not installed (apt-get install chromium chromium-driver)",
                allow_module_level=True)  # fmt: skip
webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed")
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.support.ui import Select, WebDriverWait  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SHOTS = Path(os.environ.get("PHLOEM_SCREENSHOTS", ROOT / "out" / "screenshots"))
W, H = 240, 90  # the object photo; the page shows it scaled up to 256 px wide


def _photo() -> np.ndarray:
    """An RGBA bar along y = 45 (rows 30..60, columns 15..225): stripes across it, random grain."""
    rng = np.random.default_rng(1)
    img = np.zeros((H, W, 4), np.float32)
    xx = np.arange(15, 226)
    stripes = 0.5 + 0.4 * np.sin(xx / 6.0)
    img[30:61, 15:226, 0] = stripes
    img[30:61, 15:226, 1] = 0.35 + 0.2 * rng.random((31, 211))
    img[30:61, 15:226, 2] = 0.2
    img[30:61, 15:226, 3] = 1
    return img


@pytest.fixture(scope="module")
def studio(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, Path, Any]]:
    """A real uvicorn server on a free loopback port, in a thread; its URL, project folder and app."""
    import socket

    import uvicorn

    from phloem.studio import Project, create_app

    root = tmp_path_factory.mktemp("studio") / "project"
    (root / "photos").mkdir(parents=True)
    io.write_image(root / "photos" / "bar.png", _photo())
    io.write_image(root / "photos" / "bark.png", phloem.data.bark()[:96, :96, :3])
    io.write_image(root / "photos" / "channel.png", channel_scene(0)[0])
    for v in range(2):
        io.write_image(root / "photos" / f"leaf{v}.png", layered_leaf(variant=v, seed=v)[0])
    (root / "trees").mkdir()
    for i, kw in enumerate(({}, {"crown_r": 30, "trunk_w": 14, "trunk_h": 60}, {"crown_r": 50, "trunk_w": 8})):
        io.write_image(root / "trees" / f"t{i}.png", tree_image(i, **kw))
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    app = create_app(Project(root), token=TOKEN, threads=1)
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning"))
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{sock.getsockname()[1]}", root, app
    finally:
        server.should_exit = True
        thread.join(30)
        sock.close()


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for flag in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--window-size=1400,800",
    ):
        opts.add_argument(flag)
    from selenium.common.exceptions import SessionNotCreatedException

    try:
        driver = webdriver.Chrome(options=opts, service=webdriver.ChromeService(executable_path=DRIVER))
    except SessionNotCreatedException as e:  # e.g. a chromium that is a stub for a snap, or a driver of another version
        pytest.skip(f"chromium did not start under chromedriver: {e.msg}")
    driver.set_page_load_timeout(30)
    try:
        yield driver
    finally:
        driver.quit()


def _open(browser: Any, url: str) -> None:
    browser.get(f"{url}/?token={TOKEN}")
    WebDriverWait(browser, 30).until(lambda d: d.execute_script("return document.body.dataset.ready") == "1")
    errors = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert not errors, errors  # e.g. a script or image the page's security policy blocked


def _drag(browser: Any, canvas: Any, points: list[tuple[float, float]], *, shift: bool = False) -> None:
    """Press, move through ``points`` (canvas pixels) and release, as a mouse does (with Shift held)."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys

    # Selenium offsets are from the element's centre, in CSS px; the canvas may be shown scaled.
    width, height, css_w, css_h = browser.execute_script(
        "const c = arguments[0]; return [c.width, c.height, c.clientWidth, c.clientHeight];", canvas
    )

    def offset(p: tuple[float, float]) -> tuple[int, int]:
        return round((p[0] + 0.5) * css_w / width - css_w / 2), round((p[1] + 0.5) * css_h / height - css_h / 2)

    chain = ActionChains(browser, duration=10).move_to_element_with_offset(canvas, *offset(points[0]))
    if shift:
        chain = chain.key_down(Keys.SHIFT)
    chain = chain.click_and_hold()
    for p in points[1:]:
        chain = chain.move_to_element_with_offset(canvas, *offset(p))
    chain = chain.release()
    if shift:
        chain = chain.key_up(Keys.SHIFT)
    chain.perform()


def _type(browser: Any, element_id: str, text: str) -> None:
    field = browser.find_element(By.ID, element_id)
    field.clear()
    field.send_keys(text)


def _line(a: tuple[float, float], b: tuple[float, float], n: int = 12) -> list[tuple[float, float]]:
    return [(a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t) for t in np.linspace(0, 1, n)]


def _wait_message(browser: Any, element_id: str, text: str) -> str:
    def ready(d: Any) -> str | bool:
        el = d.find_element(By.ID, element_id)
        shown = str(el.text)
        if "error" in (el.get_attribute("class") or "") or "failed" in shown:
            raise AssertionError(f"the page says: {shown}")
        return shown if text in shown else False

    return str(WebDriverWait(browser, 60).until(ready))


def _run_and_show(browser: Any, button: str, ws: str, shot: str) -> str:
    """Click ``button``, wait for the job's result to show in the workspace ``ws``, save a screenshot;
    the page's message (it names the result file)."""
    browser.find_element(By.ID, button).click()
    message = _wait_message(browser, f"{ws}-msg", "sidecar")
    WebDriverWait(browser, 30).until(
        lambda d: d.execute_script(
            f"const i = document.getElementById('{ws}-result'); return i.complete && i.naturalWidth"
        )
    )
    SHOTS.mkdir(parents=True, exist_ok=True)
    browser.save_screenshot(str(SHOTS / shot))
    return message


def test_draw_a_source_and_a_target_stroke_and_render(
    studio: tuple[str, Path, Any], browser: Any, tmp_path: Path
) -> None:
    url, root, _ = studio
    _open(browser, url)
    # Upload the photo through the page's file picker: saved under photos/, its name made safe.
    picked = tmp_path / "my bar.png"
    io.write_image(picked, _photo())
    browser.find_element(By.ID, "s-upload").send_keys(str(picked))
    _wait_message(browser, "s-msg", "saved photos/my_bar.png (240×90)")
    assert (root / "photos" / "my_bar.png").read_bytes() == picked.read_bytes()
    assert Select(browser.find_element(By.ID, "s-image")).first_selected_option.text == "photos/my_bar.png"
    WebDriverWait(browser, 30).until(
        lambda d: d.execute_script("return document.getElementById('s-source').width") == W
    )
    source = browser.find_element(By.ID, "s-source")
    target = browser.find_element(By.ID, "s-target")
    _drag(browser, source, _line((20, 45), (220, 45)))
    bend = _line((30, 70), (120, 20), 8) + _line((120, 20), (210, 60), 8)[1:]
    _drag(browser, target, bend)
    assert browser.find_element(By.ID, "s-nsrc").text == "1" and browser.find_element(By.ID, "s-ntgt").text == "1"
    _type(browser, "s-file", "drawn.json")
    message = _run_and_show(browser, "s-render", "s", "studio_strokes.png")

    # The stroke file is the CLI's: one pair, along the mouse paths, in the photo's pixels.
    sset = StrokeSet.load(root / "drawn.json")
    assert len(sset.pairs) == 1 and sset.source_shape == (H, W) and sset.target_size == (H, W)
    src, tgt = sset.pairs[0].source.points, sset.pairs[0].target.points
    assert np.abs(src[:, 1] - 45).max() <= 1.5 and src[0, 0] <= 22 and src[-1, 0] >= 218
    assert np.hypot(*(tgt[0] - (30, 70))) <= 2 and np.hypot(*(tgt[-1] - (210, 60))) <= 2
    assert np.hypot(*(tgt - (120, 20)).T).min() <= 2  # through the bend
    # The result: the bar re-drawn along the bent target stroke, with its sidecar.
    out = message.split("wrote ")[1].split(" and")[0]
    img = io.read_image(root / out)
    assert img.shape == (H, W, 4)
    alpha = img[..., 3] > 0.5
    on_stroke = [alpha[round(y), round(x)] for x, y in tgt]
    assert np.mean(on_stroke) >= 0.9
    assert not alpha[85:, :10].any() and not alpha[:8, 200:].any()  # corners away from the stroke stay empty
    side = json.loads((root / f"{out}.json").read_text())
    assert side["command"] == "studio strokes-edit" and side["parameters"]["strokes"] == "drawn.json"
    assert side["parameters"]["image"] == "photos/my_bar.png"


def test_move_a_target_stroke_point_by_mouse_then_render(studio: tuple[str, Path, Any], browser: Any) -> None:
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys

    url, root, _ = studio
    _open(browser, url)
    Select(browser.find_element(By.ID, "s-image")).select_by_value("photos/bar.png")
    WebDriverWait(browser, 30).until(
        lambda d: d.execute_script("return document.getElementById('s-source').width") == W
    )
    source = browser.find_element(By.ID, "s-source")
    target = browser.find_element(By.ID, "s-target")
    _drag(browser, source, _line((20, 45), (220, 45)))
    _drag(browser, target, _line((30, 70), (120, 20), 8) + _line((120, 20), (210, 60), 8)[1:])
    _type(browser, "s-file", "moved.json")
    browser.find_element(By.ID, "s-save").click()
    _wait_message(browser, "s-msg", "saved moved.json")
    before = StrokeSet.load(root / "moved.json").pairs[0]
    tgt = before.target.points
    k = int(np.argmin(np.hypot(*(tgt - (120, 20)).T)))  # the bend's point; its neighbours lie ~14 px away
    assert 0 < k < len(tgt) - 3

    # Edit mode: drag that point 15 px right and 30 px down (16 and 32 CSS px: the 240 px canvas is
    # shown 256 px wide, so the mouse moves by whole CSS pixels).
    browser.find_element(By.CSS_SELECTOR, 'input[name="s-mode"][value="edit"]').click()
    start = (float(tgt[k][0]), float(tgt[k][1]))
    _drag(browser, target, _line(start, (start[0] + 15, start[1] + 30), 6))
    assert browser.find_element(By.ID, "s-sel").text.startswith(f"target 1 #{k} ")
    browser.find_element(By.ID, "s-save").click()
    _wait_message(browser, "s-msg", "saved moved.json")
    after = StrokeSet.load(root / "moved.json").pairs[0]
    moved = after.target.points
    assert moved.shape == tgt.shape
    assert np.allclose(moved[k] - tgt[k], (15, 30), atol=1.0), (moved[k], tgt[k])
    assert np.array_equal(np.delete(moved, k, axis=0), np.delete(tgt, k, axis=0))  # only that point moved
    assert np.array_equal(after.source.points, before.source.points)
    message = _run_and_show(browser, "s-render", "s", "studio_strokes_moved.png")
    out = message.split("wrote ")[1].split(" and")[0]
    assert (root / out).is_file() and io.read_image(root / out).shape == (H, W, 4)

    # A double click halfway along a segment adds a point there; Delete removes it; Undo (three
    # times) takes back the delete, the insertion and the move.
    count = "return S.target[0].length"
    mid = (tgt[k + 2] + tgt[k + 3]) / 2
    css_w, css_h = browser.execute_script("return [arguments[0].clientWidth, arguments[0].clientHeight]", target)
    dx, dy = round((mid[0] + 0.5) * css_w / W - css_w / 2), round((mid[1] + 0.5) * css_h / H - css_h / 2)
    ActionChains(browser).move_to_element_with_offset(target, dx, dy).double_click().perform()
    assert browser.execute_script(count) == len(tgt) + 1
    assert browser.find_element(By.ID, "s-sel").text.startswith(f"target 1 #{k + 3} ")
    target.send_keys(Keys.DELETE)
    assert browser.execute_script(count) == len(tgt)
    for _ in range(3):
        browser.find_element(By.ID, "s-undo").click()
    assert np.allclose(browser.execute_script("return S.target[0]"), tgt)


def test_make_a_label_map_paint_it_and_make_a_texture(studio: tuple[str, Path, Any], browser: Any) -> None:
    url, root, _ = studio
    _open(browser, url)
    browser.find_element(By.CSS_SELECTOR, '#tabs button[data-ws="bark"]').click()
    Select(browser.find_element(By.ID, "b-image")).select_by_value("photos/bark.png")
    _type(browser, "b-n", "2")
    browser.find_element(By.ID, "b-labels").click()
    _wait_message(browser, "b-msg", "paint it")
    before = bark.decode_labels(io.read_image(root / "photos" / "bark_labels_in.png"))
    # Label 0 (the dark furrows) with a 20 px brush, a stripe down the middle of the map.
    browser.find_elements(By.CSS_SELECTOR, "#b-palette button")[0].click()
    browser.execute_script("document.getElementById('b-brush').value = 20")
    canvas = browser.find_element(By.ID, "b-canvas")
    _drag(browser, canvas, _line((48, 5), (48, 90), 10))
    _type(browser, "b-tw", "64")
    _type(browser, "b-th", "64")
    message = _run_and_show(browser, "b-texture", "b", "studio_bark.png")

    after = bark.decode_labels(io.read_image(root / "photos" / "bark_labels_in.png"))
    assert (after[10:86, 44:53] == 0).all() and (before[10:86, 44:53] == 1).any()  # the stroke painted
    assert np.array_equal(after[:, :30], before[:, :30]) and np.array_equal(after[:, 66:], before[:, 66:])
    out = message.split("wrote ")[1].split(" and")[0]
    assert io.read_image(root / out).shape == (64, 64, 3)
    side = json.loads((root / f"{out}.json").read_text())
    assert side["parameters"]["labels_in"] == "photos/bark_labels_in.png"

    # The new label map the texture was painted by: edit it (label 1 down its left quarter) and paint again.
    out_map = out.removesuffix(".png") + "_labels_out.png"
    browser.find_element(By.ID, "b-edit-out").click()
    _wait_message(browser, "b-msg", f"editing {out_map}")
    assert browser.find_element(By.ID, "b-role").text == "new"
    browser.find_elements(By.CSS_SELECTOR, "#b-palette button")[1].click()
    browser.execute_script("document.getElementById('b-brush').value = 16")
    _drag(browser, browser.find_element(By.ID, "b-canvas"), _line((8, 2), (8, 62), 8))
    message = _run_and_show(browser, "b-texture", "b", "studio_bark_edited_map.png")
    edited = bark.decode_labels(io.read_image(root / out_map))
    assert edited.shape == (64, 64) and (edited[4:60, 2:14] == 1).all()
    second = message.split("wrote ")[1].split(" and")[0]
    side = json.loads((root / f"{second}.json").read_text())
    assert (
        side["parameters"]["labels_out"] == out_map and side["parameters"]["labels_in"] == "photos/bark_labels_in.png"
    )


def _loop_until_cancelled(progress: Any) -> list[str]:
    while True:  # holds the one worker until it is cancelled: its progress call then raises
        progress(0, 1)
        threading.Event().wait(0.005)


def test_cancel_a_job_from_the_page(studio: tuple[str, Path, Any], browser: Any) -> None:
    """The page's Cancel button stops its job: queued behind a job that holds the one worker,
    so it is still waiting when the button is pressed, whatever the machine's speed."""
    url, root, app = studio
    StrokeSet.from_lists(
        [[[20, 45], [220, 45]]], [[[20, 20], [220, 70]]], source_shape=(H, W), target_size=(H, W)
    ).save(root / "cancel.json")
    blocker = app.state.jobs.submit("block", {}, _loop_until_cancelled)
    results = set((root / "results").glob("*")) if (root / "results").exists() else set()
    try:
        _open(browser, url)
        Select(browser.find_element(By.ID, "s-image")).select_by_value("photos/bar.png")
        _type(browser, "s-file", "cancel.json")
        browser.find_element(By.ID, "s-load").click()
        _wait_message(browser, "s-msg", "1 stroke pairs")
        browser.find_element(By.ID, "s-render").click()
        cancel = browser.find_element(By.ID, "s-cancel")
        WebDriverWait(browser, 30).until(lambda d: cancel.is_enabled())
        cancel.click()
        message = _wait_message(browser, "s-msg", "cancelled")
        assert message == "strokes-edit cancelled: cancelled before it started"
        WebDriverWait(browser, 30).until(lambda d: not cancel.is_enabled())
    finally:
        app.state.jobs.cancel(blocker.id)
    assert app.state.jobs.wait(blocker.id, timeout=30).state == "cancelled"
    job = next(
        j for j in app.state.jobs.jobs() if j.kind == "strokes-edit" and j.parameters["strokes"] == "cancel.json"
    )
    assert job.state == "cancelled" and job.outputs == []
    assert (set((root / "results").glob("*")) if (root / "results").exists() else set()) == results


def _shot(browser: Any, name: str) -> None:
    SHOTS.mkdir(parents=True, exist_ok=True)
    browser.save_screenshot(str(SHOTS / name))


def _selected_vertex(browser: Any) -> int:
    """The index of the main branch's vertex the page has selected ("branch 0 #i (x, y)")."""
    selected = str(browser.find_element(By.ID, "br-sel").text)
    assert selected.startswith("branch 0 #"), selected
    return int(selected.split("#")[1].split(" ")[0])


def test_trace_and_edit_a_skeleton_by_mouse_then_grow_and_render(studio: tuple[str, Path, Any], browser: Any) -> None:
    url, root, _ = studio
    _open(browser, url)
    browser.find_element(By.CSS_SELECTOR, '#tabs button[data-ws="branching"]').click()
    Select(browser.find_element(By.ID, "br-image")).select_by_value("photos/channel.png")
    WebDriverWait(browser, 30).until(
        lambda d: d.execute_script("return document.getElementById('br-canvas').width") == 224
    )
    browser.find_element(By.ID, "br-trace").click()
    _wait_message(browser, "br-msg", "edit it with the mouse")
    path = root / "photos" / "channel_skeleton.json"
    traced = Skeleton.load(path)
    main = traced.branches[0].points
    n = len(main)
    canvas = browser.find_element(By.ID, "br-canvas")

    # Drag vertex v of the main branch 15 px down; it moves by the drag, in image pixels. The
    # trace's vertices lie 1 px apart and the press lands on a whole canvas pixel, so the vertex
    # pressed may be v's neighbour: the rest follows the one selected.
    v = n // 2
    _drag(browser, canvas, _line(tuple(main[v]), (main[v][0], main[v][1] + 15), 6))
    picked = _selected_vertex(browser)
    assert abs(picked - v) <= 1, (picked, v)
    v = picked
    start = tuple(main[v])
    # Delete vertex v + 6 (click it, press Delete), or the neighbour the press selects.
    _drag(browser, canvas, [tuple(main[v + 6])])
    gone_at = _selected_vertex(browser)
    assert abs(gone_at - (v + 6)) <= 1, (gone_at, v + 6)
    gone = tuple(main[gone_at])
    canvas.send_keys("\ue017")  # the Delete key
    # Shift-drag from vertex v - 20 draws a new branch on it, up and to the left.
    root_pt = tuple(main[v - 20])
    _drag(browser, canvas, _line(root_pt, (root_pt[0] - 30, root_pt[1] - 40), 10), shift=True)
    # Its last vertex is selected: a thickness of 5 px.
    _type(browser, "br-thick", "5\n")
    # A guide path along the bottom of the image.
    browser.find_element(By.CSS_SELECTOR, 'input[name="br-mode"][value="guide"]').click()
    _drag(browser, canvas, _line((10, 110), (214, 110), 12))
    browser.find_element(By.ID, "br-save").click()
    _wait_message(browser, "br-msg", "saved photos/channel_skeleton.json")

    edited = Skeleton.load(path)
    new_main = edited.branches[0].points
    assert len(new_main) == n - 1
    assert np.allclose(new_main[v], (start[0], start[1] + 15), atol=1.0), (new_main[v], start)
    assert not np.isclose(new_main, gone).all(axis=1).any()  # the deleted vertex is gone
    assert np.array_equal(
        np.delete(new_main, [v], axis=0)[: gone_at - 1], np.delete(main, [v], axis=0)[: gone_at - 1].round(2)
    )
    added = edited.branches[-1]
    # on the vertex pressed (its neighbours lie 1.4 px away, a CSS pixel is half an image pixel)
    assert len(edited.branches) == len(traced.branches) + 1 and added.parent is not None
    assert added.parent[0] == 0 and abs(added.parent[1] - (v - 20)) <= 1
    assert np.allclose(added.points[0], new_main[added.parent[1]], atol=0.01)
    assert np.allclose(added.points[-1], (root_pt[0] - 30, root_pt[1] - 40), atol=1.5)
    assert added.thickness[-1] == 5.0
    _shot(browser, "studio_branching_edit.png")

    # Extend the main branch at its tip (§6): select the tip, press Extend branch; the page's skeleton grows.
    browser.find_element(By.CSS_SELECTOR, 'input[name="br-mode"][value="edit"]').click()
    _drag(browser, canvas, [tuple(new_main[-1])])
    assert browser.find_element(By.ID, "br-sel").text.startswith(f"branch 0 #{len(new_main) - 1} ")
    browser.find_element(By.ID, "br-extend").click()
    message = _wait_message(browser, "br-msg", "extended branch 0")
    assert int(message.split(" to ")[1].split(" ")[0]) > len(new_main)
    browser.find_element(By.ID, "br-undo").click()  # and back: the saved skeleton is what grows below
    assert browser.execute_script("return K.branches[0].points.length") == len(new_main)

    # Grow along the guide, then render the grown skeleton; the histograms are drawn.
    _type(browser, "br-seed", "2")
    browser.find_element(By.ID, "br-grow").click()
    message = _wait_message(browser, "br-msg", "grew")
    guide = np.array(json.loads((root / "guide.json").read_text()))  # the CLI's --guide file, in image pixels
    assert np.allclose(guide[0], (10, 110), atol=1) and np.allclose(guide[-1], (214, 110), atol=1)
    grown_name = message.split("grew ")[1].split(":")[0]
    grown = Skeleton.load(root / grown_name)
    assert grown.shape == (128, 224)
    assert json.loads((io.sidecar_path(root / grown_name)).read_text())["parameters"]["guide"] == "guide.json"
    drawn = browser.execute_script(
        "const c = document.getElementById('br-hist'); const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;"
        "let n = 0; for (let i = 0; i < d.length; i += 4) if (d[i] > 200 && d[i + 1] > 100 && d[i + 1] < 160 && d[i + 2] < 80) n++; return n;"
    )
    assert drawn > 50  # orange bars of the grown skeleton
    message = _run_and_show(browser, "br-render", "br", "studio_branching.png")
    out = message.split("wrote ")[1].split(" and")[0]
    assert io.read_image(root / out).shape[:2] == (128, 224)
    assert json.loads((root / f"{out}.json").read_text())["parameters"]["target"] == grown_name

    # A second guide path: the guide becomes a mask (--guide takes one), and Re-roll grows with the next seed.
    browser.find_element(By.CSS_SELECTOR, 'input[name="br-mode"][value="guide"]').click()
    _drag(browser, canvas, _line((10, 15), (214, 15), 12))
    browser.find_element(By.ID, "br-reroll").click()
    message = _wait_message(browser, "br-msg", "grew")
    assert browser.find_element(By.ID, "br-seed").get_attribute("value") == "3"
    mask = io.read_image(root / "guide.png") > 0.5
    assert mask[110, 20:200].all() and mask[15, 20:200].all() and not mask[40:90].any()
    side = json.loads(io.sidecar_path(root / message.split("grew ")[1].split(":")[0]).read_text())
    assert side["parameters"]["guide"] == "guide.png" and side["seed"] == 3


def test_scribble_two_layers_on_a_leaf_expand_and_synthesize(studio: tuple[str, Path, Any], browser: Any) -> None:
    url, root, _ = studio
    _open(browser, url)
    browser.find_element(By.CSS_SELECTOR, '#tabs button[data-ws="leaves"]').click()
    Select(browser.find_element(By.ID, "lv-image")).select_by_value("photos/leaf0.png")
    WebDriverWait(browser, 30).until(
        lambda d: d.execute_script("return document.getElementById('lv-canvas').height") == 160
    )
    _type(browser, "lv-n", "2\n")
    browser.execute_script("document.getElementById('lv-brush').value = 3")
    canvas = browser.find_element(By.ID, "lv-canvas")
    browser.find_element(By.CSS_SELECTOR, '#lv-palette button[data-layer="1"]').click()
    _drag(browser, canvas, _line((48, 30), (48, 60), 8))  # along the midrib (veins)
    browser.find_element(By.CSS_SELECTOR, '#lv-palette button[data-layer="2"]').click()
    _drag(browser, canvas, _line((66, 60), (66, 90), 8))  # on the blade
    browser.find_element(By.ID, "lv-expand").click()
    _wait_message(browser, "lv-msg", "expanded")

    labels, n = phloem.leaves.read_scribbles(root / "photos" / "leaf0_scribbles.png", (160, 96))
    assert n == 2
    assert (labels[32:59, 48] == 1).all() and (labels[62:89, 66] == 2).all()
    assert set(np.unique(labels[:, :40])) == {0} and (labels > 0).sum() < 400  # only where drawn
    WebDriverWait(browser, 30).until(
        lambda d: d.execute_script(
            "const i = document.getElementById('lv-layers'); return i.complete && i.naturalWidth"
        )
    )
    layers = io.read_image(root / "photos" / "leaf0_scribbles_layers.png")
    truth = layered_leaf(variant=0, seed=0)[1]
    first = layers[..., 0] > 0.8  # layer 1 is red (#e6194b), layer 2 blue (#4363d8)
    assert first[truth == 1].mean() > 0.6 and not first[truth == 3].mean() > 0.2
    assert (layers[..., 3][truth == 0] == 0).all()

    Select(browser.find_element(By.ID, "lv-leaves")).select_by_value("photos/leaf1.png")
    _type(browser, "lv-count", "2")
    browser.find_element(By.ID, "lv-synth").click()
    message = _wait_message(browser, "lv-msg", "sidecar")
    assert message.startswith("wrote 2 leaves")
    WebDriverWait(browser, 30).until(
        lambda d: d.execute_script(
            "return [...document.querySelectorAll('#lv-gallery img, #lv-sheet')].every((i) => i.complete && i.naturalWidth)"
            " && document.querySelectorAll('#lv-gallery img').length === 2"
        )
    )
    _shot(browser, "studio_leaves.png")
    sheet = message.split("and ")[1].split(",")[0]
    assert io.read_image(root / sheet).shape[0] >= 1000


def test_fill_a_hole_painted_with_the_brush(studio: tuple[str, Path, Any], browser: Any) -> None:
    url, root, _ = studio
    _open(browser, url)
    browser.find_element(By.CSS_SELECTOR, '#tabs button[data-ws="textures"]').click()
    Select(browser.find_element(By.ID, "tx-image")).select_by_value("photos/bark.png")
    WebDriverWait(browser, 30).until(
        lambda d: d.execute_script("return document.getElementById('tx-canvas').width") == 96
    )
    browser.execute_script("document.getElementById('tx-brush').value = 12")
    _drag(browser, browser.find_element(By.ID, "tx-canvas"), _line((30, 48), (66, 48), 10))
    message = _run_and_show(browser, "tx-run", "tx", "studio_textures.png")

    hole = io.read_image(root / "photos" / "bark_mask.png") > 0.5  # the CLI's mask: white where filled
    assert hole[44:53, 32:65].all() and not hole[:35].any() and not hole[62:].any() and 300 < hole.sum() < 800
    out = message.split("wrote ")[1].split(" and")[0]
    before, after = io.read_image(root / "photos" / "bark.png"), io.read_image(root / out)
    assert np.array_equal(after[~hole], before[~hole]) and not np.array_equal(after[hole], before[hole])
    assert json.loads((root / f"{out}.json").read_text())["parameters"]["mask"] == "photos/bark_mask.png"


def test_make_trees_from_a_library_folder(studio: tuple[str, Path, Any], browser: Any) -> None:
    url, root, _ = studio
    _open(browser, url)
    browser.find_element(By.CSS_SELECTOR, '#tabs button[data-ws="trees"]').click()
    Select(browser.find_element(By.ID, "tr-library")).select_by_value("trees")
    assert len(browser.find_elements(By.CSS_SELECTOR, "#tr-library-gallery img")) == 3
    _type(browser, "tr-count", "3")
    _type(browser, "tr-size", "128")
    browser.find_element(By.ID, "tr-run").click()
    message = _wait_message(browser, "tr-msg", "sidecar")
    WebDriverWait(browser, 30).until(
        lambda d: d.execute_script(
            "const i = [...document.querySelectorAll('#tr-gallery img')];"
            "return i.length === 3 && i.every((x) => x.complete && x.naturalWidth === 128)"
        )
    )
    _shot(browser, "studio_trees.png")
    folder = message.split(" to ")[1].split(",")[0]
    assert sorted(p.name for p in (root / folder).glob("tree_*.png")) == [
        "tree_0000.png",
        "tree_0001.png",
        "tree_0002.png",
    ]
