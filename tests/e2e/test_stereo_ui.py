"""The stereo colour-marker form of the Performance panel on the sample project: a
rendered stereo pair and its rig's exact calibration uploaded through the form, the
progress bar while the server tracks, the take in the list, and playing it moves the
face; bad input refused with its message in the page and nothing stored.

Ground truth: `retarget.testing.stereo_rig` renders the pair (6 frames of the demo's
expressions under head motion, seen by two cameras at 1 m) and gives the exact
calibration; the tracked take's points are compared with the rendered markers.
"""

from __future__ import annotations

import io

import cv2
import numpy as np
import pytest

from retarget.sources.calibration import StereoCalibration
from retarget.testing.stereo_rig import (checkerboard_views, render_sticker_video, render_stereo_video, rig_calibration,
                                         stereo_cameras)
from tests.e2e.conftest import open_project
from tests.waits import scaled_ms

N_FRAMES = 6

# Every (hidden, value) state of the source progress bar and every note, from now on.
_WATCH = """() => {
    const bar = document.getElementById('source-progress');
    const note = document.getElementById('source-note');
    window.progress = [];
    window.notes = [];
    new MutationObserver(() => window.progress.push([bar.hidden, bar.value]))
        .observe(bar, {attributes: true, attributeFilter: ['hidden', 'value']});
    new MutationObserver(() => window.notes.push(note.textContent))
        .observe(note, {childList: true, characterData: true, subtree: true});
}"""

_RECORD = """() => {
    window.frames = [];
    window.app.stream.addEventListener('frame', (e) => window.frames.push(
        {index: e.detail.frameIndex, d: Array.from(e.detail.displacements)}));
}"""


@pytest.fixture(scope="module")
def server(module_server):
    """One server for the module (with the sample project)."""
    return module_server


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """(left video, right video, calibration .npz, a non-calibration .npz, truth, rig)."""
    folder = tmp_path_factory.mktemp("stereo_ui")
    rig = stereo_cameras()
    truth = render_stereo_video(folder / "face.mkv", n_frames=N_FRAMES, cameras=rig, start=3.6, seed=2)
    rig_calibration(*rig).save(folder / "rig.npz")
    np.savez(folder / "points.npz", points=np.zeros((4, 3)))
    return (*truth.videos, folder / "rig.npz", folder / "points.npz", truth, rig)


@pytest.fixture(scope="module")
def boards(tmp_path_factory, pair):
    """Both cameras' videos of a 9 x 6 checkerboard (25 mm) in 6 poses, lossless."""
    folder = tmp_path_factory.mktemp("stereo_boards")
    paths = []
    for side, frames in zip(("left", "right"), checkerboard_views(*pair[5], 6, seed=0)):
        path = folder / f"board_{side}.mkv"
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 30.0, (640, 480))
        for frame in frames:
            writer.write(frame)
        writer.release()
        paths.append(path)
    return paths


def open_form(page) -> None:
    page.select_option("#video-method", "stereo")
    page.click("label[for=video-file]")
    page.wait_for_selector("#stereo-dialog[open]")


def test_a_stereo_pair_tracked_through_the_form_plays_and_bad_input_is_named(server, page, pair):
    left, right, calibration, not_calibration, truth, rig = pair
    sample = next(p for p in server.api("GET", "/api/projects") if p["rig"])
    open_project(page, server, sample["id"])
    page.wait_for_function("() => window.app.face && window.app.face.nJoints === 68", timeout=scaled_ms(30_000))
    before = server.api("GET", f"/api/projects/{sample['id']}/takes")

    # the form says what is missing and stays open
    open_form(page)
    page.set_input_files("#stereo-left", str(left))
    page.click("#stereo-track")
    assert page.inner_text("#stereo-note") == "Choose the right camera's video."
    assert page.is_visible("#stereo-dialog")

    # the server refuses a calibration file that is not one: its reason shows, nothing is stored
    page.set_input_files("#stereo-right", str(right))
    page.set_input_files("#stereo-calibration", str(not_calibration))
    page.click("#stereo-track")
    page.wait_for_selector("#error", state="visible", timeout=scaled_ms(30_000))
    message = page.inner_text("#error-text")
    assert "'points.npz' is not a stereo calibration saved by retarget" in message and "HTTP 422" in message
    assert page.is_hidden("#source-progress") and page.is_enabled("#video-file")
    assert server.api("GET", f"/api/projects/{sample['id']}/takes") == before
    page.click("#error-close")

    # the pair with its calibration: progress, then the take, selected
    open_form(page)
    assert page.input_value("#stereo-left").endswith("face_left.mkv")  # kept for the retry
    page.set_input_files("#stereo-calibration", str(calibration))
    page.evaluate(_WATCH)
    page.click("#stereo-track")
    page.wait_for_function("n => window.app.sources.takes.length === n", arg=len(before) + 1, timeout=scaled_ms(60_000))
    page.wait_for_selector("#source-progress", state="hidden")
    (info,) = [t for t in server.api("GET", f"/api/projects/{sample['id']}/takes")
               if t["id"] not in {b["id"] for b in before}]
    assert (info["source"], info["n_frames"], info["n_points"], info["dims"]) == ("stereo", N_FRAMES, 21, 3)
    shown = [value for hidden, value in page.evaluate("() => window.progress") if not hidden]
    assert shown and max(shown) > 0, shown
    notes = page.evaluate("() => window.notes")
    assert any(n.startswith("Tracking the stereo pair on the server") for n in notes), notes
    assert "baseline 150.0 mm" in page.inner_text("#source-note")
    row = page.locator(f"#take-list li[data-take='{info['id']}']")
    assert "stereo · 21 pts 3D" in row.inner_text()

    # the stored points are the rendered markers (left camera frame, mm)
    points = np.load(io.BytesIO(server.read(f"/api/projects/{sample['id']}/takes/{info['id']}/points")))
    err = np.linalg.norm(points - rig[0].to_camera(truth.points3d), axis=2)
    assert np.median(err) < 0.3

    # selecting it and Play moves the face with the expression, not the head: its neutral
    # is the first frame (the take is shorter than the default half second of neutral
    # capture), its head motion is removed, and no filter delays it
    row.locator("input[type=radio]").check()
    assert page.input_value("#source-select") == "take"
    page.click("#conditioning summary")
    page.select_option("#neutral-mode", "frame")
    page.fill("#neutral-value", "0")
    page.select_option("#filter", "none")
    page.check("#take-loop")
    page.evaluate(_RECORD)
    page.click("#play")
    page.wait_for_function("() => window.frames.length >= 24", timeout=scaled_ms(30_000))
    frames = page.evaluate("() => window.frames")
    index = np.array([f["index"] for f in frames]) % N_FRAMES  # frame indices go on over loops
    size = np.linalg.norm(np.array([f["d"] for f in frames]).reshape(len(frames), -1, 3), axis=2).max(axis=1)
    page.click("#stop")
    # the rendered expression alone: the markers with the head's pose taken out
    posed = np.einsum("fnj,fji->fni", truth.points3d - truth.head_translation[:, None], truth.head_rotation)
    expression = np.linalg.norm(posed - posed[0], axis=2).max(axis=1)  # mm
    assert size.max() > 0.02  # cm on the sample face
    assert np.corrcoef(size, expression[index])[0, 1] > 0.9


def test_checkerboard_videos_calibrate_through_the_form(server, page, pair, boards, tmp_path):
    left, right, _, _, truth, rig = pair
    sample = next(p for p in server.api("GET", "/api/projects") if p["rig"])
    open_project(page, server, sample["id"])
    before = server.api("GET", f"/api/projects/{sample['id']}/takes")
    open_form(page)
    page.set_input_files("#stereo-left", str(left))
    page.set_input_files("#stereo-right", str(right))
    page.check("#stereo-dialog input[value=board]")
    assert page.is_hidden("#stereo-calibration") and page.is_visible("#stereo-board-left")
    page.set_input_files("#stereo-board-left", str(boards[0]))
    page.click("#stereo-track")
    assert page.inner_text("#stereo-note") == "Choose the right camera's checkerboard video."
    page.set_input_files("#stereo-board-right", str(boards[1]))
    page.click("#stereo-track")
    page.wait_for_function("n => window.app.sources.takes.length === n", arg=len(before) + 1, timeout=scaled_ms(60_000))
    note = page.inner_text("#source-note")
    assert "calibration from 6 checkerboard views" in note, note
    # the calibration it made: the rig's, to be downloaded for the next pairs
    href = page.get_attribute("#source-note a", "href")
    (tmp_path / "cal.npz").write_bytes(server.read(href))
    cal = StereoCalibration.load(tmp_path / "cal.npz")
    assert cal.baseline == pytest.approx(150.0, rel=0.01) and cal.meta["views"] == 6
    (take,) = [t for t in server.api("GET", f"/api/projects/{sample['id']}/takes")
               if t["id"] not in {b["id"] for b in before}]
    points = np.load(io.BytesIO(server.read(f"/api/projects/{sample['id']}/takes/{take['id']}/points")))
    assert np.median(np.linalg.norm(points - rig[0].to_camera(truth.points3d), axis=2)) < 1.5  # mm


def test_stickers_of_one_colour_through_the_form_make_a_take_and_its_layout_rows(server, page, tmp_path):
    """Issue 17 §2: "stickers of one colour" in the form tracks every blue sticker of a
    rendered vertical webcam pair (issue 17's take) into a take of m01..m13, and the custom
    layout fold opens on it with a row per sticker and their places kept; a colour the
    pair does not show is refused with its reason, nothing stored."""
    truth = render_sticker_video(tmp_path / "stickers.mp4", n_frames=30, seed=2)
    rig_calibration(*truth.cameras).save(tmp_path / "webcams.npz")
    sample = next(p for p in server.api("GET", "/api/projects") if p["rig"])
    open_project(page, server, sample["id"])
    page.wait_for_function("() => window.app.face && window.app.face.nJoints === 68", timeout=scaled_ms(30_000))
    before = server.api("GET", f"/api/projects/{sample['id']}/takes")
    open_form(page)
    assert page.is_hidden("#stereo-color")
    page.check("input[name=stereo-markers][value=stickers]")
    assert page.is_visible("#stereo-color") and page.input_value("#stereo-color") == "blue"
    page.set_input_files("#stereo-left", str(truth.videos[0]))
    page.set_input_files("#stereo-right", str(truth.videos[1]))
    page.set_input_files("#stereo-calibration", str(tmp_path / "webcams.npz"))
    page.fill("#stereo-color", "yellow")
    page.click("#stereo-track")
    page.wait_for_selector("#error", state="visible", timeout=scaled_ms(30_000))
    assert "of colour 'yellow' seen by both cameras; at least 3 are needed" in page.inner_text("#error-text")
    assert server.api("GET", f"/api/projects/{sample['id']}/takes") == before
    page.click("#error-close")

    open_form(page)
    page.fill("#stereo-color", "blue")
    page.click("#stereo-track")
    page.wait_for_function("n => window.app.sources.takes.length === n", arg=len(before) + 1, timeout=scaled_ms(60_000))
    (info,) = [t for t in server.api("GET", f"/api/projects/{sample['id']}/takes")
               if t["id"] not in {b["id"] for b in before}]
    assert (info["source"], info["n_frames"], info["n_points"], info["layout"]) == ("stereo", 30, 13, None)
    page.wait_for_function("() => document.querySelector('#custom-layout').open", timeout=scaled_ms(20_000))
    assert "Custom layout" in page.inner_text("#source-note")
    markers = server.api("GET", f"/api/projects/{sample['id']}/layouts/from-take/{info['id']}")
    assert markers["names"] == [f"m{k:02d}" for k in range(1, 14)] and markers["reference"] is not None
    page.wait_for_function("() => document.querySelectorAll('#custom-points tbody tr').length === 13",
                           timeout=scaled_ms(10_000))
    rows = page.locator("#custom-points tbody tr").all_inner_texts()
    assert [row.split()[0] for row in rows] == markers["names"], rows
    server.api("DELETE", f"/api/projects/{sample['id']}/takes/{info['id']}")
