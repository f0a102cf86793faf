"""The Live stereo panel's Calibrate as a user meets it, clicked in Chromium: the fake camera
plays rendered checkerboard views of the synthetic rig (`stereo_cameras`: 150 mm apart,
about 1360 px focal length; both views side by side in one file, the panel's "one camera,
side by side"), Calibrate counts the good views as the page sends the pairs, Save
calibration stores the calibration with the project, and it matches the rig.

The clip holds 12 board poses, each for 2 frames at 30 fps and played in a loop: whatever
rate the page grabs at, consecutive pairs mostly show different poses, so the count rises
to the 10 needed within seconds (a pose seen again after another counts again; with 12
poses most of the 10 are distinct). The same clip checks the pairs StereoCapture's worker
encodes (the camera's two halves; at most two at once).
"""

from __future__ import annotations

import json
import time

import cv2

import numpy as np
import pytest
from websockets.sync.client import connect

from retarget.sources.calibration import StereoCalibration
from retarget.sources.stereo_live import MIN_CALIBRATION_VIEWS
from retarget.testing.stereo_rig import checkerboard_views, rig_calibration, stereo_cameras
from tests.e2e.conftest import open_project
from tests.e2e.fake_camera import write_y4m
from tests.e2e.test_stereo_live import FPS, browser, dutreve21_project, server  # noqa: F401 (fixtures)
from tests.waits import scaled, scaled_ms

POSES, HELD = 12, 2  # board poses in the clip, frames each is held

# every text the panel's status shows, in order
_STATUS = """() => {
    window.statuses = [];
    const el = document.getElementById('live-stereo-status');
    new MutationObserver(() => window.statuses.push(el.textContent))
        .observe(el, { childList: true, characterData: true, subtree: true });
}"""


@pytest.fixture(scope="module")
def material(tmp_path_factory):
    """The fake camera's file (test_stereo_live's `browser` plays material[0]): the rig's
    checkerboard views, left and right side by side; and the views (lefts, rights)."""
    lefts, rights, _ = checkerboard_views(*stereo_cameras(), n_views=POSES, seed=7)
    frames = [np.hstack(pair) for pair in zip(lefts, rights) for _ in range(HELD)]
    return write_y4m(tmp_path_factory.mktemp("stereo-calibrate") / "boards.y4m", frames, FPS), (lefts, rights)


def test_calibrate_clicked_counts_views_and_saves_the_rigs_calibration(server, page):
    pid = dutreve21_project(server)
    open_project(page, server, pid)
    page.select_option("#live-stereo-split", "side")
    page.click("#live-stereo-open")
    page.wait_for_function("() => document.querySelector('#live-stereo-status').textContent.startsWith('Not calibrated')",
                           timeout=scaled_ms(20_000))
    assert page.is_disabled("#live-stereo-save") and page.is_disabled("#live-stereo-start")
    # dutreve21 has no points named m01..: single-colour stickers could drive none of them
    assert page.is_disabled("#live-stereo-markers option[value=stickers]") and page.is_disabled("#live-stereo-color")
    page.evaluate(_STATUS)

    page.click("#live-stereo-calibrate")
    page.wait_for_function("(n) => window.app.stereo.last?.type === 'views' && window.app.stereo.last.count >= n",
                           arg=MIN_CALIBRATION_VIEWS, timeout=scaled_ms(30_000), polling=100)
    page.wait_for_function("() => !document.querySelector('#live-stereo-save').disabled", timeout=scaled_ms(5_000))
    page.click("#live-stereo-save")
    page.wait_for_function("() => window.statuses.some((s) => s.startsWith('Calibrated: '))", timeout=scaled_ms(60_000))
    assert page.is_enabled("#live-stereo-start")
    page.evaluate("() => window.app.stereo.close()")

    # the UI showed the count rising, one good view at a time, to the number needed
    counts = [int(s.split()[2]) for s in page.evaluate("() => window.statuses") if s.startswith("Good views: ")]
    assert all(f" of {MIN_CALIBRATION_VIEWS} needed" in s for s in page.evaluate("() => window.statuses")
               if s.startswith("Good views: "))
    assert counts == sorted(counts) and all(b - a <= 1 for a, b in zip(counts, counts[1:])), counts
    assert len(set(counts)) >= 3 and counts[-1] >= MIN_CALIBRATION_VIEWS, counts
    saved = next(s for s in page.evaluate("() => window.statuses") if s.startswith("Calibrated: "))

    # stored with the project: a new session starts on it ...
    with connect(server.url.replace("http://", "ws://") + f"/api/projects/{pid}/stereo/live",
                 open_timeout=scaled(30)) as ws:
        hello = json.loads(ws.recv(timeout=scaled(30)))
    summary = hello["calibration"]
    assert summary is not None and summary["size"] == [640, 480]
    assert summary["views"] >= MIN_CALIBRATION_VIEWS and saved.startswith(f"Calibrated: {summary['views']} views")
    # ... and it is the rig's (found within about 0.1 % of it from the page's JPEGs of clean
    # renders: the bounds fail a wrong square, a view cut from the wrong half or a scaled frame)
    saved_files = list((server.data_dir / "projects" / pid).glob("stereo-calibration-*.json"))
    assert len(saved_files) == 1, saved_files   # the store's one file for it
    found = StereoCalibration.from_dict(json.loads(saved_files[0].read_text()))
    truth = rig_calibration(*stereo_cameras())
    assert found.rms < 0.3
    assert found.baseline == pytest.approx(150.0, rel=0.01)
    for K, true_K in ((found.K1, truth.K1), (found.K2, truth.K2)):
        assert K[0, 0] == pytest.approx(true_K[0, 0], rel=0.01) and K[1, 1] == pytest.approx(true_K[1, 1], rel=0.01)
        assert np.abs(K[:2, 2] - true_K[:2, 2]).max() < 5.0  # principal point, px
    turn = np.degrees(np.arccos(np.clip((np.trace(found.R @ truth.R.T) - 1) / 2, -1, 1)))
    assert turn < 0.2  # the right camera's rotation against the left's, degrees


_GRABS = """async () => {
    const { StereoCapture, MAX_ENCODING } = await import('/static/js/tracking/StereoCapture.js');
    const capture = new StereoCapture([document.createElement('video'), document.createElement('video')],
                                      { left: '', split: 'side' });
    await capture.open();
    const size = capture.size;
    const grabs = [capture.grab(0.9), capture.grab(0.9), capture.grab(0.9)];
    capture.close();  // while the first two encode
    const [first, second, third] = await Promise.allSettled(grabs);
    const after = await capture.grab(0.9).then(() => 'a pair', (error) => error.message);
    return { max: MAX_ENCODING, size, states: [first.status, second.status], third: third.reason?.message, after,
             left: Array.from(first.value.left), right: Array.from(first.value.right), time: first.value.time };
}"""


def test_pairs_are_encoded_off_the_page_two_at_most(server, page, material):
    """StereoCapture itself (the panel asks for one pair at a time): its worker's JPEGs are
    the camera's two halves; a third pair asked while two encode is dropped, not queued; the
    pairs begun before close still come, and a grab after close is refused."""
    page.goto(server.url)
    page.wait_for_function("() => window.app && window.app.projectId")
    got = page.evaluate(_GRABS)
    assert got["max"] == 2 and got["size"] == [640, 480] and got["states"] == ["fulfilled", "fulfilled"]
    assert "2 frame pairs are being encoded already" in got["third"]
    assert "closed" in got["after"]
    assert abs(got["time"] - time.time()) < scaled(30)
    lefts, rights = material[1]
    left, right = (cv2.imdecode(np.array(got[k], np.uint8), cv2.IMREAD_COLOR) for k in ("left", "right"))
    assert left.shape == right.shape == (480, 640, 3)
    # the pose the camera showed, in each half: its left view on the left, its right on the right
    pose = int(np.argmin([cv2.absdiff(left, view).mean() for view in lefts]))
    assert cv2.absdiff(left, lefts[pose]).mean() < 3 and cv2.absdiff(right, rights[pose]).mean() < 3
