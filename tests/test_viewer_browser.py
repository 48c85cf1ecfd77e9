"""The viewer in a real browser: Debian's chromium driven by Playwright (its own executable
path; no downloaded browser build). Software WebGL (SwiftShader) renders the canvas.

- ``mmrl view`` of a BVH file on a second skeleton (Mixamo names, other channel orders): the
  canvas shows the character, and frames advance;
- ``mmrl play``: a click on the ground moves the target (the trace shows the new target at
  a decision step) and the root then gets closer to it;
- ``mmrl render --html``: the page opens from file:// with the network disabled, shows the
  character, and its playback advances.

Marked ``browser``. In CI (``CI`` set) a missing chromium, Playwright or viser fails;
elsewhere these tests skip with one line saying what to install. ``MMRL_SCREENSHOTS=DIR``
keeps the screenshots (docs/viewer*.png come from here).
"""
import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.browser

# MMRL_CHROMIUM points at another chromium build (a distribution's, never a downloaded one).
CHROMIUM = os.environ.get("MMRL_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"
VIEWPORT = {"width": 960, "height": 600}
# The figure's right-side bones (mmrl.viz.render.RIGHT, orange) as the page draws them (RGB 0..255).
FIGURE_ORANGE = np.array([230, 128, 51])


def _missing():
    missing = []
    if not os.path.exists(CHROMIUM):
        missing.append(f"chromium at {CHROMIUM} (apt-get install chromium, or set MMRL_CHROMIUM)")
    if importlib.util.find_spec("playwright") is None:
        missing.append("playwright (pip install playwright)")
    if importlib.util.find_spec("viser") is None:
        missing.append("viser (pip install 'mmrl[viewer]')")
    return missing


@pytest.fixture(scope="module")
def browser():
    missing = _missing()
    if missing:
        needs = ", ".join(missing)
        if os.environ.get("CI"):
            pytest.fail(f"the browser tests need {needs}")
        from conftest import note_browser_skip

        note_browser_skip(f"they need {needs}")
        pytest.skip(f"the browser tests need {needs}")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM,
                              args=["--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--no-sandbox"])
        yield b
        b.close()


class Server:
    """``mmrl ARGS --no-browser --port 0`` in a subprocess; ``url`` once it serves."""

    def __init__(self, *args):
        self.proc = subprocess.Popen([sys.executable, "-u", "-m", "mmrl", *map(str, args), "--no-browser", "--port",
                                      "0"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.lines = []
        deadline = time.time() + 90
        while time.time() < deadline:
            line = self.proc.stdout.readline()
            if not line:
                break
            self.lines.append(line)
            m = re.match(r"serving (http://\S+)", line)
            if m:
                self.url = m.group(1)
                return
        self.stop()
        raise AssertionError("the server did not start:\n" + "".join(self.lines))

    def stop(self) -> str:
        if self.proc.poll() is None:
            self.proc.terminate()  # SIGTERM: a clean stop, with the timing report
        out, _ = self.proc.communicate(timeout=30)
        self.lines.append(out or "")
        return "".join(self.lines)


def open_page(browser, url, **context):
    page = browser.new_context(viewport=VIEWPORT, **context).new_page()
    page.goto(url)
    page.wait_for_selector("canvas", timeout=30000)
    return page


def canvas_image(page, name=None):
    import imageio.v3 as iio

    # A page screenshot clipped to the canvas: an element screenshot first waits for the element
    # to be "stable" over animation frames, which timed out on a loaded machine.
    box = page.locator("canvas").first.bounding_box()
    png = page.screenshot(clip=box, timeout=60000)
    keep = os.environ.get("MMRL_SCREENSHOTS")
    if keep and name:
        Path(keep).mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(Path(keep) / name))
    return iio.imread(png)[..., :3].astype(np.int64)


def assert_shows_character(img):
    """Not blank (the ground grid and more), and the figure's orange bones are on the canvas."""
    assert img.std() > 10, "the canvas is blank"
    orange = (np.abs(img - FIGURE_ORANGE).max(-1) < 45).sum()
    assert orange >= 15, f"the character's bones are not on the canvas ({orange} orange pixels)"


def wait_for(fn, timeout=20.0, every=0.05):
    deadline = time.time() + timeout
    while time.time() < deadline:
        value = fn()
        if value:
            return value
        time.sleep(every)
    raise AssertionError(f"timed out after {timeout} s")


def shown_frame(page):
    m = re.search(r"frame (\d+) /", page.inner_text("body"))
    return None if m is None else int(m.group(1))


def test_view_shows_the_character_and_plays(browser, tmp_path):
    """On a second skeleton: Mixamo joint names, other channel orders, meters."""
    from test_import_axes_fps import other_skeleton, read_clip

    from mmrl import synth

    synth.write_clip(tmp_path / "walk.bvh", speed=1.4, turn_rate=0.3, seconds=6.0, seed=1)
    (tmp_path / "mixamo.bvh").write_text(other_skeleton(read_clip((tmp_path / "walk.bvh").read_text())).text())
    server = Server("view", tmp_path / "mixamo.bvh")
    try:
        page = open_page(browser, server.url)
        first = wait_for(lambda: shown_frame(page))
        time.sleep(1.5)
        assert_shows_character(canvas_image(page, "viewer_view.png"))
        second = shown_frame(page)
        assert second != first  # frames advance (the clip loops, so only "different")
    finally:
        server.stop()


def read_trace(path):
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.endswith("}")]


@pytest.fixture(scope="module")
def plane_run(tmp_path_factory):
    from mmrl.cli import main

    run = tmp_path_factory.mktemp("run") / "plane"
    assert main(["train", "plane", "--steps", "1024", "--envs", "8", "--out", str(run), "--no-progress"]) == 0
    return run


def test_play_click_moves_the_target_and_the_character_follows(browser, plane_run, tmp_path):
    trace = tmp_path / "trace.jsonl"
    server = Server("play", plane_run, "--policy", "joystick", "--trace", trace)
    try:
        page = open_page(browser, server.url)
        wait_for(lambda: len(read_trace(trace)) >= 10)
        assert_shows_character(canvas_image(page, "viewer.png"))
        old_target = read_trace(trace)[-1]["target"]
        page.mouse.click(0.25 * VIEWPORT["width"], 0.62 * VIEWPORT["height"])  # the ground, left of the panel
        clicked = time.time()
        changed = wait_for(lambda: [line for line in read_trace(trace) if line["target"] != old_target], every=0.01)
        latency = time.time() - clicked
        new_target = np.array(changed[0]["target"])
        start = np.array(changed[0]["root"][:2])
        assert np.hypot(*(new_target - start)) < 15.0  # a point on the ground in view, not the horizon
        assert latency < 1.0, f"the click reached a decision after {latency:.2f} s"
        time.sleep(4.0)
        lines = read_trace(trace)
        after = [np.hypot(*(new_target - np.array(line["root"][:2]))) for line in lines if line["t"] >= changed[0]["t"]]
        assert all(np.allclose(line["target"], new_target) for line in lines if line["t"] >= changed[0]["t"])
        assert min(after) < after[0] - 0.75, after  # the root gets closer
        print(f"click -> trace line: {1000 * latency:.0f} ms")
    finally:
        print(server.stop())


def test_play_shift_drag_places_the_target_and_turns_the_facing_along_the_drag(browser, tmp_path):
    """Arrive task: a shift+drag puts the target where it began and the facing along it. One drag
    goes right of its start, then as far left: the camera holds still during a drag and a screen
    row meets the ground in a line through the start, so the facing turns around (by pi)."""
    from mmrl.cli import main

    run = tmp_path / "arrive"
    assert main(["train", "arrive", "--steps", "1024", "--envs", "8", "--out", str(run), "--no-progress"]) == 0
    trace = tmp_path / "trace.jsonl"
    server = Server("play", run, "--policy", "joystick", "--trace", trace)
    try:
        page = open_page(browser, server.url)
        wait_for(lambda: len(read_trace(trace)) >= 10)
        # A still camera: the client eases toward each camera the server sets, so a following
        # camera is still moving when a drag starts, and the drag's start pixel leaves its point.
        page.get_by_text("camera follows").click()
        time.sleep(1.5)
        x0, y0 = 0.3 * VIEWPORT["width"], 0.65 * VIEWPORT["height"]
        page.keyboard.down("Shift")
        page.mouse.move(x0, y0)
        page.mouse.down()
        facings, first = [], read_trace(trace)[-1]
        for direction in (1, -1):
            old = read_trace(trace)[-1]
            page.mouse.move(x0 + direction * 120, y0, steps=8)
            changed = wait_for(lambda: [line for line in read_trace(trace)
                                        if line["t"] > old["t"] and abs(line["facing"] - old["facing"]) > 1e-4],
                               every=0.05)
            time.sleep(0.5)  # the drag's last updates reach a decision
            facings.append(read_trace(trace)[-1]["facing"])
            assert changed[-1]["target"] != first["target"]  # the drag placed the target
            assert np.hypot(*(np.array(changed[-1]["target"]) - changed[-1]["root"][:2])) < 15.0
        page.mouse.up()
        page.keyboard.up("Shift")
        turn = abs((facings[1] - facings[0] + np.pi) % (2 * np.pi) - np.pi)
        assert turn > 0.9 * np.pi, facings
    finally:
        print(server.stop())


def test_html_export_opens_offline(browser, tmp_path):
    from mmrl.cli import main

    out = tmp_path / "episode.html"
    assert main(["render", "--policy", "joystick", "--length", "6", "--html", str(out)]) == 0
    requests = []
    context = browser.new_context(viewport=VIEWPORT, offline=True)
    context.route("**/*", lambda route: (requests.append(route.request.url),
                                         route.continue_() if route.request.url.startswith("file:")
                                         else route.abort()))
    page = context.new_page()
    page.goto(out.as_uri())
    page.wait_for_selector("canvas", timeout=30000)
    clock = page.locator("input").first
    t0 = wait_for(lambda: clock.input_value())
    # The playback advances (polled: a loaded CI machine may render the first frames slowly).
    wait_for(lambda: clock.input_value() != t0, timeout=30.0)
    assert_shows_character(canvas_image(page, "viewer_html.png"))
    assert [r for r in requests if not r.startswith("file:")] == []
