"""ARKit's 52 blendshapes in the page (issue 16): *Generate* makes them (a job, its progress
bar), a slider poses the face in the shader exactly as the shapes say (the pixels change
too), a gain is saved with the project and shown again after a reload, and *Drive by:
ARKit 52* streams weight frames (RTAW) that move the face. One server for the module."""

from __future__ import annotations

import time

import numpy as np
import pytest

from server.wire import decode_arkit_shapes
from tests.e2e.conftest import open_project
from tests.waits import scaled_ms

TOLERANCE = 1e-4  # of the mesh's bounding-box diagonal: float32 on the GPU


@pytest.fixture(scope="module")
def server(module_server):
    return module_server


_POSE = "() => Array.from(window.app.face.deformedPositions())"
_CANVAS = "#viewport canvas"


def test_generate_pose_gain_and_drive_by_arkit(server, page):
    sample = next(p for p in server.api("GET", "/api/projects") if p["rig"])
    url = f"/api/projects/{sample['id']}/arkit"
    open_project(page, server, sample["id"])
    page.wait_for_function("() => window.app.face && window.app.face.nJoints === 68", timeout=scaled_ms(30_000))
    page.click("#arkit-details summary")
    page.wait_for_function("() => document.getElementById('arkit-note').textContent.includes('Generate')")
    page.click("#arkit-generate")
    page.wait_for_selector("#arkit-progress:not([hidden])", timeout=scaled_ms(10_000))
    page.wait_for_selector("#arkit-sliders input[data-shape='jawOpen']", timeout=scaled_ms(120_000))
    assert server.api("GET", url)["state"] == "ready"

    # a slider poses the face in the shader: rest + the shape's delta, as the server made it
    arrays = server.read(f"/api/projects/{sample['id']}/mesh/arrays")
    n = int(np.frombuffer(arrays, "<u4", 1, 8)[0])
    rest = np.frombuffer(arrays, "<f4", 3 * n, 16).reshape(n, 3).astype(np.float64)
    names, deltas = decode_arkit_shapes(server.read(f"{url}/shapes"))
    diagonal = float(np.linalg.norm(rest.max(0) - rest.min(0)))
    before = page.locator(_CANVAS).screenshot()
    page.evaluate("""() => { const s = document.querySelector("#arkit-sliders input[data-shape='jawOpen']");
        s.value = 0.8; s.dispatchEvent(new Event('input')); }""")
    drawn = np.array(page.evaluate(_POSE)).reshape(n, 3) - rest
    expected = 0.8 * deltas[names.index("jawOpen")]
    assert np.abs(expected).max() > 0.05 * diagonal
    assert np.abs(drawn - expected).max() < TOLERANCE * diagonal
    deadline = time.monotonic() + scaled_ms(10_000) / 1000  # the next frame drawn (SwiftShader: a few a second)
    while page.locator(_CANVAS).screenshot() == before:
        assert time.monotonic() < deadline, "the pixels did not change"
        page.wait_for_timeout(100)

    # a gain is saved with the project and shown again after a reload
    gain = page.locator("#arkit-sliders input[data-gain='jawOpen']")
    gain.fill("1.5")
    gain.dispatch_event("change")
    deadline = time.monotonic() + scaled_ms(10_000) / 1000
    while server.api("GET", url)["settings"]["gains"]["jawOpen"] != 1.5:
        assert time.monotonic() < deadline, "the gain was not saved"
        time.sleep(0.1)
    page.reload()
    page.wait_for_function("() => window.app && window.app.face && window.app.face.nJoints === 68",
                           timeout=scaled_ms(30_000))
    page.click("#arkit-details summary")
    page.wait_for_selector("#arkit-sliders input[data-gain='jawOpen']", timeout=scaled_ms(30_000))
    assert page.input_value("#arkit-sliders input[data-gain='jawOpen']") == "1.5"

    # Fix: a stroke across the face paints jawOpen's mask (the rig painter's brush), saved
    # with the project, and the face shows the fixed shape (the server's ?fixed=true)
    page.click("#arkit-sliders button[data-fix='jawOpen']")
    page.locator("#arkit-radius").fill("300")
    page.locator("#arkit-radius").dispatch_event("input")
    box = page.locator(_CANVAS).bounding_box()
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(x - 40, y)
    page.mouse.down()
    for step in range(1, 9):
        page.mouse.move(x - 40 + 10 * step, y + 5 * step)
    page.mouse.up()
    deadline = time.monotonic() + scaled_ms(10_000) / 1000
    while "jawOpen" not in server.api("GET", url)["settings"]["masks"]:
        assert time.monotonic() < deadline, "the fix was not saved"
        time.sleep(0.1)
    _, fixed = decode_arkit_shapes(server.read(f"{url}/shapes?fixed=true"))
    k = names.index("jawOpen")
    drawn = np.array(page.evaluate(_POSE)).reshape(n, 3) - rest
    assert np.abs(fixed[k] - deltas[k]).max() > 1e-3 * diagonal  # the stroke took some of it away
    assert np.abs(drawn - fixed[k]).max() < TOLERANCE * diagonal + 1e-3 * np.abs(deltas[k]).max()
    page.click("#arkit-fix-done")
    page.click("#arkit-reset")   # the face at rest: what moves it next is the stream

    # driven by ARKit, the demo streams weight frames that move the face, and the sliders
    # follow them (the stream's frames count from connecting; the panel applies them once
    # the shapes the drive loads are in, which a loaded machine takes a while to do)
    page.evaluate("""() => { window.arkitFrames = 0;
        window.app.live.connect();
        window.app.stream.addEventListener('arkit', (e) => {
            window.arkitFrames ++; window.lastArkit = Array.from(e.detail.weights); }); }""")
    page.check("#drive-arkit")
    page.click("#play")
    page.wait_for_function("() => window.arkitFrames > 5", timeout=scaled_ms(30_000))
    page.wait_for_function("""() => { const face = window.app.face, rest = face.mesh.geometry.attributes.position.array;
        const v = face.deformedPositions(); let most = 0;
        for (let i = 0; i < rest.length; i ++) most = Math.max(most, Math.abs(v[i] - rest[i]));
        return most > 0.05; }""", polling=200, timeout=scaled_ms(30_000))
    page.wait_for_function("""() => { const last = window.lastArkit;
        const sliders = Array.from(document.querySelectorAll('#arkit-sliders input[type=range]'), (e) => Number(e.value));
        return sliders.length === 52 && last.length === 52 && Math.max(...last) > 0.05
            && sliders.every((value, k) => Math.abs(value - last[k]) <= 0.006); }""",
                           polling=100, timeout=scaled_ms(30_000))
    page.click("#stop")
    assert server.api("GET", f"/api/projects/{sample['id']}")["settings"].get("drive") == "arkit"
