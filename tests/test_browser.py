"""``iloci serve`` end to end in a real headless Chromium (Debian's, never a downloaded one).

A LASA shape is drawn on the page's canvas with the mouse (Pointer Events),
at a pace unlike LASA's; the robot answers; the person answers through a new
concept and a correct guess, renames a concept, reloads the page and finds
the memory. Screenshots are saved: ``answer.png`` (a guess on screen) and
``serve.png`` (the end), in ``ILOCI_SCREENSHOT_DIR`` or else the test's
temporary directory. ``ILOCI_SERVE_TEST_CONFIG`` names a TOML config to
serve instead of the small one here (the guide's screenshot uses
``docs/examples/tiny.toml``, whose drawings are recognizable).
"""

from __future__ import annotations

import os
from pathlib import Path
import shutil
import socket
import threading
import time

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("uvicorn")
pytest.importorskip("iloci_native")
pytest.importorskip("pinocchio")
sync_api = pytest.importorskip("playwright.sync_api")

from iloci.commands.serve import build_classroom  # noqa: E402
from iloci.data import load_lasa  # noqa: E402
from iloci.web.app import create_app  # noqa: E402

EPOCHS = 30
CONFIG = os.environ.get("ILOCI_SERVE_TEST_CONFIG") or {
    "perceptual_model": {"name": "native-rnnpb", "epochs": EPOCHS, "recognition_steps": EPOCHS},
    "learner": {"rehearsal_epochs": EPOCHS}, "evaluation": {"seed": 0}}
#: Debian's chromium; a browser is never downloaded.
CHROMIUM = os.environ.get("ILOCI_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--no-first-run"]
WAIT = 180_000  # ms: rehearsals on a loaded 2-core machine


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def server(tmp_path):
    import uvicorn

    memory = tmp_path / "memory.npz"
    classroom = build_classroom(memory, CONFIG)
    port = free_port()
    srv = uvicorn.Server(uvicorn.Config(create_app(classroom), host="127.0.0.1", port=port,
                                        log_level="warning"))
    thread = threading.Thread(target=srv.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 30
    while not srv.started and time.monotonic() < deadline:
        time.sleep(0.05)
    assert srv.started, "uvicorn did not start"
    yield f"http://127.0.0.1:{port}/", memory
    srv.should_exit = True
    thread.join(10)
    classroom.agent.close()


@pytest.fixture
def browser():
    if not Path(CHROMIUM).exists():
        pytest.skip(f"no chromium at {CHROMIUM}: install Debian's (`apt-get install chromium`); "
                    "the browser test never downloads one")
    with sync_api.sync_playwright() as p:
        try:
            b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS, headless=True)
        except sync_api.Error as exc:
            pytest.skip(f"chromium at {CHROMIUM} does not start headless: {exc}")
        yield b
        b.close()


def draw(page, demo, pace: str) -> None:
    """Draw a LASA demonstration on the pad with the mouse, y up, at the given pace."""
    box = page.locator("#pad").bounding_box()
    pos = demo.positions[np.linspace(0, len(demo.positions) - 1, 80).astype(int)]
    p = (pos - pos.min(axis=0)) / np.ptp(pos, axis=0).max() * 0.8 + 0.1   # in [0.1, 0.9]
    xs = box["x"] + p[:, 0] * box["width"]
    ys = box["y"] + (1 - p[:, 1]) * box["height"]                           # y up on the page
    page.mouse.move(xs[0], ys[0])
    page.mouse.down()
    for i, (x, y) in enumerate(zip(xs[1:], ys[1:])):
        page.mouse.move(x, y)
        # LASA is sampled evenly in time; a person slows down in curves and speeds up after
        time.sleep(0.004 if pace == "fast" else 0.002 + 0.02 * (i % 20 == 0))
    page.mouse.up()


def test_teach_in_the_browser(server, browser, tmp_path):
    url, memory = server
    shots = Path(os.environ.get("ILOCI_SCREENSHOT_DIR") or tmp_path)
    lasa = {d.key: d for d in load_lasa(["GShape", "Angle"])}
    page = browser.new_page(viewport={"width": 1000, "height": 900})
    errors = []
    page.on("pageerror", lambda exc: errors.append(f"{exc}\n{exc.stack}"))
    page.on("requestfailed", lambda req: errors.append(f"request failed: {req.url}"))
    outside = []
    page.on("request", lambda req: None if req.url.startswith(url) else outside.append(req.url))
    page.goto(url)
    expect = sync_api.expect
    expect(page.locator("#concepts")).to_contain_text("Empty")

    draw(page, lasa["GShape/0"], "slow")                       # first: a new concept
    expect(page.locator("#message")).to_contain_text('new concept, "c1"', timeout=WAIT)

    draw(page, lasa["Angle/0"], "fast")                        # guessed c1: no -> c2
    expect(page.locator("#guess")).to_contain_text('Is it "c1"?', timeout=WAIT)
    expect(page.locator("#judge")).to_be_visible()
    page.keyboard.press("n")
    expect(page.locator("#message")).to_contain_text('new concept, "c2"', timeout=WAIT)

    draw(page, lasa["GShape/1"], "slow")                       # guessed c1: yes
    expect(page.locator("#guess")).to_contain_text('Is it "c1"?', timeout=WAIT)
    page.wait_for_timeout(6500)                                # let the answer's animation run
    page.screenshot(path=str(shots / "answer.png"))
    page.locator("#yes").click()
    expect(page.locator("#message")).to_contain_text("Learned", timeout=WAIT)
    expect(page.locator(".concept")).to_have_count(2)

    form = page.locator('.concept[data-concept="c1"] form')
    form.locator("input").fill("G")
    form.locator("button").click()
    expect(page.locator('.concept[data-concept="G"]')).to_have_count(1)

    page.reload()                                              # the memory is the file's
    expect(page.locator('.concept[data-concept="G"]')).to_contain_text("G (2 drawings)")
    expect(page.locator('.concept[data-concept="c2"]')).to_have_count(1)
    expect(page.locator("#memsummary")).to_contain_text("3 drawing(s) learned")

    # a bad drawing: the server's error is shown, nothing learned
    box = page.locator("#pad").bounding_box()
    page.mouse.move(box["x"] + 50, box["y"] + 50)
    page.mouse.down()
    for _ in range(5):
        page.mouse.move(box["x"] + 50, box["y"] + 50)
        time.sleep(0.01)
    page.mouse.up()
    expect(page.locator("#error")).to_be_visible()
    shot = shots / "serve.png"
    page.screenshot(path=str(shot), full_page=True)
    assert shot.stat().st_size > 10_000
    assert not errors, errors
    assert not outside, f"the page fetched from elsewhere: {outside}"
    from iloci.agent import Agent
    assert Agent.load(memory).memory.concepts() == ["G", "c2"]
