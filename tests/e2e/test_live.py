"""The live panel on the sample project: the demo moves the face, the region checkboxes
restrict the motion live (partial retargeting), Stop puts the face back at rest."""

from __future__ import annotations

import json

import numpy as np

from retarget.layouts import get_layout
from tests.e2e.conftest import open_project

_RECORD = """() => {
    window.received = [];
    window.app.stream.addEventListener('frame', (e) =>
        window.received.push(Array.from(e.detail.displacements)));
    window.app.stream.addEventListener('message', (e) => {
        if (e.detail.type === 'mask') window.lastMask = JSON.stringify(e.detail.regions);
    });
}"""


def wait_for_mask(page, regions) -> None:
    """Until the server has acknowledged the mask `regions` (None: all)."""
    page.wait_for_function("m => window.lastMask === m", arg=json.dumps(regions, separators=(",", ":")),
                           timeout=10_000)


def recent_frames(page, n: int) -> np.ndarray:
    """(n, N, 3) the last n frames the page received after the recorder started."""
    page.evaluate("() => { window.received.length = 0; }")
    page.wait_for_function(f"() => window.received.length >= {n}", timeout=30_000)
    return np.array(page.evaluate(f"() => window.received.slice(-{n})")).reshape(n, -1, 3)


def test_region_toggles_restrict_the_motion_live_and_stop_rests(server, page):
    sample = next(p for p in server.api("GET", "/api/projects") if p["rig"])
    open_project(page, server, sample["id"])
    page.wait_for_function("() => window.app.face && window.app.face.nJoints === 68", timeout=30_000)
    page.click("#play")
    page.wait_for_function("() => window.app.stream.stats.frames > 5", timeout=30_000)
    page.evaluate(_RECORD)
    layout = get_layout(sample["landmarks"]["layout"])
    mouth = layout.region_mask(["mouth"])

    moving = recent_frames(page, 60)
    assert np.abs(moving[:, ~mouth]).max() > 1e-3 and np.abs(moving[:, mouth]).max() > 1e-3

    # only the mouth regions stay checked: everything else is held at rest, live
    for box in page.query_selector_all("#regions input[data-region]"):
        if box.get_attribute("data-region") not in ("upper_lip", "lower_lip", "mouth_corners"):
            box.uncheck()
    wait_for_mask(page, ["upper_lip", "lower_lip", "mouth_corners"])
    masked = recent_frames(page, 30)
    assert np.all(masked[:, ~mouth] == 0.0)
    assert np.abs(masked[:, mouth]).max() > 1e-3

    # checking them all again moves every region
    for box in page.query_selector_all("#regions input[data-region]"):
        box.check()
    wait_for_mask(page, None)
    again = recent_frames(page, 60)
    assert np.abs(again[:, ~mouth]).max() > 1e-3

    # stop: the face comes back to rest
    page.click("#stop")
    page.wait_for_function("() => window.received.length > 0 && "
                           "window.received[window.received.length - 1].every(v => v === 0)",
                           timeout=10_000)
    rest = page.evaluate("() => Array.from(window.app.face.deformedPositions())")
    arrays = server.read(f"/api/projects/{sample['id']}/mesh/arrays")
    n = np.frombuffer(arrays, "<u4", 1, 8)[0]
    v0 = np.frombuffer(arrays, "<f4", 3 * n, 16)
    assert np.abs(np.array(rest, np.float32) - v0).max() < 1e-5
