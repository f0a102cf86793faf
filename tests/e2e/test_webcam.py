"""The webcam source end to end, with Chromium's fake camera: the page tracks the camera
(MediaPipe face mesh, tracking/webcam.js), sends the points over the stream, and the
server's live source sends back the frames that move the sample project's face.

The performer is the first 5 s of ``../shared/data/video/face_expressions_480.mp4`` (a
still face for about 1.5 s, then grimaces, an open mouth, raised brows), looped by the
fake camera; that test skips only when ../shared is absent. A camera that sees a
checkerboard (no face) runs everywhere.

Ground truth is what the page itself sent: every points message is logged in the page,
so the frames that come back are matched to the tracked points by frame index, and a
recorded take is compared with the points sent while recording.
"""

from __future__ import annotations

import io
from pathlib import Path

import httpx
import numpy as np
import pytest

from retarget.layouts import get_layout
from tests.e2e.conftest import ARTIFACTS, Server, open_project, write_face_file, sample_copy, chromium
from tests.e2e.fake_camera import checkerboard, video_frames, write_y4m
from tests.waits import scaled_ms, wait_job

SHARED = Path(__file__).resolve().parents[3] / "shared"
VIDEO = SHARED / "data" / "video" / "face_expressions_480.mp4"
CAMERA_FPS = 30
CAMERA_SIZE = 240  # px; MediaPipe's detector looks at 128 px and its mesh at 192 px
RECORD_S = 2.0

# Logs, in the page, the points messages and controls it sends (in sending order, which
# is the order the server handles them in), the frames and messages it receives, and the
# camera streams it opens.
_LOG = """() => {
    const stream = window.app.stream;
    window.log = { sent: [], frames: [], messages: [] };
    window.cameras = [];
    const getUserMedia = navigator.mediaDevices.getUserMedia.bind(navigator.mediaDevices);
    navigator.mediaDevices.getUserMedia = async (constraints) => {
        const camera = await getUserMedia(constraints);
        window.cameras.push(camera);
        return camera;
    };
    const sendPoints = stream.sendPoints.bind(stream);
    stream.sendPoints = (buffer) => {
        const view = new DataView(buffer);
        window.log.sent.push({ index: view.getUint32(8, true), time: view.getFloat64(16, true),
                               points: Array.from(new Float32Array(buffer, 32)) });
        return sendPoints(buffer);
    };
    const send = stream.send.bind(stream);
    stream.send = (message) => {
        window.log.sent.push({ control: message.type, at: performance.now() });
        return send(message);
    };
    stream.addEventListener('frame', (e) => window.log.frames.push({
        index: e.detail.frameIndex, flags: e.detail.flags,
        displacements: Array.from(e.detail.displacements) }));
    stream.addEventListener('message', (e) => window.log.messages.push(e.detail));
}"""

needs_shared = pytest.mark.skipif(not SHARED.is_dir(), reason="../shared is absent")


@pytest.fixture(scope="module")
def server(tmp_path_factory, sample_data_dir):
    """One real server for the module (starting one costs seconds on a loaded machine):
    the tests only add to its sample project, and each checks what it added."""
    srv = Server(sample_copy(sample_data_dir, tmp_path_factory.mktemp("webcam") / "data")).start()
    yield srv
    srv.stop()


@pytest.fixture(scope="module")
def camera(request, tmp_path_factory) -> Path:
    """The fake camera's Y4M file; `request.param` says what it shows. Module-scoped, so
    pytest runs the tests of one camera together, on one browser (a launch costs seconds)."""
    frames = (video_frames(VIDEO, 5 * CAMERA_FPS, CAMERA_SIZE) if request.param == "performer"
              else [checkerboard(CAMERA_SIZE)] * CAMERA_FPS)
    return write_y4m(tmp_path_factory.mktemp("camera") / "camera.y4m", frames, CAMERA_FPS)


@pytest.fixture(scope="module")
def browser(camera):
    """Chromium whose only camera is the `camera` file, granted without asking; the
    conftest `page` fixture (console errors fail the test, screenshots) runs on it."""
    yield from chromium(camera)


def open_sample(server, page) -> dict:
    """The rigged sample project, shown in the page with the log running."""
    sample = next(p for p in server.api("GET", "/api/projects") if p["rig"])
    open_project(page, server, sample["id"])
    page.wait_for_function("() => window.app.face && window.app.face.nJoints === 68", timeout=scaled_ms(30_000))
    page.wait_for_function("() => window.app.stream && window.app.stream.state === 'open'", timeout=scaled_ms(10_000))
    page.evaluate(_LOG)
    return sample


def play_webcam(page, clicks: int = 1) -> None:
    page.select_option("#source-select", "webcam")
    for _ in range(clicks):
        page.click("#play")
    page.wait_for_function("() => window.log.messages.some(m => m.type === 'started' && m.source === 'live')",
                           timeout=scaled_ms(60_000))


def rest_vertices(server, project_id: str) -> np.ndarray:
    """(V * 3) float32 the mesh at rest, as the server stores it."""
    arrays = server.read(f"/api/projects/{project_id}/mesh/arrays")
    n = np.frombuffer(arrays, "<u4", 1, 8)[0]
    return np.frombuffer(arrays, "<f4", 3 * n, 16)


def on_screen(page) -> np.ndarray:
    return np.array(page.evaluate("() => Array.from(window.app.face.deformedPositions())"), np.float32)


def press(page, selector: str) -> None:
    """Click a button of a page whose main thread is busy tracking: a click event, as
    page.click's waits for steady animation frames take seconds there."""
    page.dispatch_event(selector, "click")


def stop_releases_the_camera_and_rests(page, server, project_id: str) -> None:
    """Stop: the one camera the page opened ends, the video lets go of it, no more points
    go out, and the face is back at rest."""
    press(page, "#stop")
    page.wait_for_function("() => window.cameras.every(c => c.getTracks().every(t => t.readyState === 'ended'))",
                           timeout=scaled_ms(10_000))
    assert page.evaluate("() => window.cameras.length") == 1
    assert page.evaluate("() => document.getElementById('webcam-video').srcObject === null")
    assert page.is_hidden("#webcam-box") and not page.inner_text("#source-note").startswith("Webcam:")
    page.wait_for_function("() => window.log.frames.length > 0 && window.log.frames.at(-1).flags & 1",
                           timeout=scaled_ms(10_000))
    sent = page.evaluate("() => window.log.sent.length")
    page.wait_for_timeout(1000)
    assert page.evaluate("() => window.log.sent.length") == sent
    assert np.abs(on_screen(page) - rest_vertices(server, project_id)).max() < 1e-5


def _series(points: np.ndarray, layout) -> dict[str, np.ndarray]:
    """(F,) mouth opening and brow height of (F, N, 3) points, y up."""
    at = {name: points[:, i] for i, name in enumerate(layout.point_names)}
    regions = np.array(layout.regions)
    return {"mouth": at["lip_upper_inner_center"][:, 1] - at["lip_lower_inner_center"][:, 1],
            "brows": points[:, regions == "brows", 1].mean(axis=1) - points[:, regions == "eyes", 1].mean(axis=1)}


def unfiltered_from_the_first_frame(page) -> None:
    """Conditioning with no filter (each frame that comes back depends on that frame's
    points only) and the neutral from frame 0 (this performer does not hold still through
    a capture window; test_neutral_capture.py has the performer who moves refused)."""
    page.click("#conditioning summary")
    page.select_option("#filter", "none")
    page.select_option("#neutral-mode", "frame")
    page.fill("#neutral-value", "0")
    page.dispatch_event("#neutral-value", "change")


@needs_shared
@pytest.mark.parametrize("camera", ["performer"], indirect=True)
def test_webcam_drives_the_face_records_a_take_and_stop_releases_it(server, page):
    sample = open_sample(server, page)
    layout = get_layout(sample["landmarks"]["layout"])
    unfiltered_from_the_first_frame(page)
    play_webcam(page)
    assert page.evaluate("() => { const v = document.getElementById('webcam-video');"
                         " return !v.paused && v.readyState >= 2 && v.videoWidth; }") == CAMERA_SIZE
    page.wait_for_function("() => window.log.frames.length >= 12", timeout=scaled_ms(60_000))
    assert np.abs(on_screen(page) - rest_vertices(server, sample["id"])).max() > 0.05  # cm
    assert page.inner_text("#source-note") == "Webcam: neutral captured."  # after its countdown
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "test_webcam_playing.png"))  # the camera beside the face it drives

    log = page.evaluate("() => window.log")
    sent = {s["index"]: np.array(s["points"], np.float32).reshape(-1, 3) for s in log["sent"] if "index" in s}
    frames = [f for f in log["frames"] if f["index"] in sent]
    assert len(frames) >= 12 and all(f["flags"] == 0 for f in frames)  # a face, every frame
    performer = _series(np.stack([sent[f["index"]] for f in frames]), layout)
    target = _series(np.stack([np.reshape(f["displacements"], (-1, 3)) for f in frames]), layout)
    eyes_apart = np.median([p[layout.point_names.index("eye_left_outer"), 0]
                            - p[layout.point_names.index("eye_right_outer"), 0] for p in sent.values()])
    for part in ("mouth", "brows"):
        # the performer's own motion is there to follow...
        assert np.ptp(performer[part]) > 0.05 * eyes_apart
        # ...and the face on screen follows it: opens its mouth, raises its brows with her
        r = np.corrcoef(performer[part], target[part])[0, 1]
        assert r > 0.8, f"{part}: correlation {r:.2f} between performer and target"
        assert np.ptp(target[part]) > 0.05, f"{part}: the target moves only {np.ptp(target[part]):.3f} cm"

    # capture neutral: acknowledged, and frames come again once the new neutral is in
    press(page, "#recapture-neutral")
    page.wait_for_function("() => window.log.messages.some(m => m.type === 'neutral')", timeout=scaled_ms(10_000))
    n = page.evaluate("() => window.log.frames.length")
    page.wait_for_function(f"() => window.log.frames.length > {n}", timeout=scaled_ms(30_000))

    # record about 2 s under a name
    page.fill("#record-name", "webcam e2e")
    press(page, "#record")
    page.wait_for_function("() => window.log.messages.some(m => m.type === 'recording')", timeout=scaled_ms(10_000))
    assert page.inner_text("#record").startswith("■")
    page.wait_for_timeout(RECORD_S * 1000)
    # and at least 3 tracked frames: a loaded machine tracks about one frame a second
    page.wait_for_function("() => { const s = window.log.sent;"
                           " const start = s.findLastIndex(m => m.control === 'record');"
                           " return s.slice(start).filter(m => 'index' in m).length >= 3; }",
                           timeout=scaled_ms(30_000))
    press(page, "#record")
    page.wait_for_selector("#take-list li:has-text('webcam e2e')", timeout=scaled_ms(20_000))
    # a tracked frame after the recording stopped bounds its end (below)
    page.wait_for_function("() => { const s = window.log.sent;"
                           " const stop = s.findLastIndex(m => m.control === 'record_stop');"
                           " return s.slice(stop).some(m => 'index' in m); }", timeout=scaled_ms(10_000))
    log = page.evaluate("() => window.log.sent")
    start, stop = (max(i for i, s in enumerate(log) if s.get("control") == c) for c in ("record", "record_stop"))
    recorded = [s for s in log[start + 1:stop] if "index" in s]
    take = next(t for t in server.api("GET", f"/api/projects/{sample['id']}/takes") if t["name"] == "webcam e2e")
    assert take["n_frames"] == len(recorded) >= 2
    assert take["n_points"] == layout.n_points and take["dims"] == 3 and take["layout"] == layout.name
    assert take["duration"] == pytest.approx(recorded[-1]["time"] - recorded[0]["time"], abs=1e-6)
    # the frames span the time the recording was on, give or take the time between two
    # tracked frames at either end (0.25 to 1 s in SwiftShader, with the machine's load)
    on = (log[stop]["at"] - log[start]["at"]) / 1000
    before = next(s for s in reversed(log[:start]) if "index" in s)
    after = next(s for s in log[stop:] if "index" in s)
    gap = np.diff([s["time"] for s in (before, *recorded, after)]).max()
    assert on > RECORD_S and on - 2 * gap <= take["duration"] <= on + gap
    expected = np.array([s["points"] for s in recorded], np.float32).reshape(len(recorded), -1, 3)

    stop_releases_the_camera_and_rests(page, server, sample["id"])

    server.restart()
    kept = server.api("GET", f"/api/projects/{sample['id']}/takes/{take['id']}")
    assert kept["name"] == "webcam e2e" and kept["n_frames"] == take["n_frames"]
    points = np.load(io.BytesIO(server.read(f"/api/projects/{sample['id']}/takes/{take['id']}/points")))
    np.testing.assert_array_equal(points, expected)


@pytest.mark.parametrize("camera", ["no face"], indirect=True)
def test_a_camera_without_a_face_says_so_and_leaves_the_face_at_rest(server, page):
    # a capture over the first seconds waits for a face (another test may have left the
    # project's neutral on a frame number, which must have a face)
    sample = next(p for p in server.api("GET", "/api/projects") if p["rig"])
    conditioning = {**sample["settings"].get("conditioning", {}), "neutral": {"mode": "first_seconds", "seconds": 0.5}}
    server.api("PATCH", f"/api/projects/{sample['id']}", {"settings": {"conditioning": conditioning}})
    sample = open_sample(server, page)
    before = [server.api("GET", f"/api/projects/{sample['id']}{part}") for part in ("", "/takes")]
    play_webcam(page, clicks=2)  # impatient: again while the camera and the tracker load
    page.wait_for_function("() => document.getElementById('source-note').textContent.includes('no face')",
                           timeout=scaled_ms(60_000))
    assert page.inner_text("#source-note") == \
        "Webcam: no face found in the camera image. Face the camera, in good light."
    page.wait_for_function("() => window.log.sent.filter(s => 'index' in s).length >= 5", timeout=scaled_ms(30_000))

    log = page.evaluate("() => window.log")
    lost = np.array([s["points"] for s in log["sent"] if "index" in s], np.float32)
    assert np.isnan(lost).all()  # every frame went, as lost points
    assert log["frames"] == []  # no neutral, so nothing to show
    assert not [m for m in log["messages"] if m["type"] == "error"]
    assert page.inner_text("#error").strip() == ""
    assert np.abs(on_screen(page) - rest_vertices(server, sample["id"])).max() < 1e-5
    assert [server.api("GET", f"/api/projects/{sample['id']}{part}") for part in ("", "/takes")] == before

    stop_releases_the_camera_and_rests(page, server, sample["id"])


@needs_shared
@pytest.mark.parametrize("camera", ["performer"], indirect=True)
def test_webcam_drives_all_468_points_of_a_dense_project(server, page, tmp_path):
    """A mediapipe468 project: the webcam sends all 468 tracked points, not a reduction, and
    the face they come back onto follows the performer. The project is made through the API
    (points found by the server, an ellipsoid rig, four joints a vertex, cheap to draw in
    SwiftShader); test_dense_layout.py walks the page's own no-click way there."""
    layout = get_layout("mediapipe468")
    project = server.api("POST", "/api/projects", {"name": "dense webcam"})
    pid = project["id"]
    path, _ = write_face_file(tmp_path, "scan.obj", None)
    reply = httpx.put(f"{server.url}/api/projects/{pid}/mesh", timeout=60,
                      files={"file": ("scan.obj", path.read_bytes())})
    assert reply.status_code == 200, reply.text
    for post, body in (("landmarks/find", {"layout": layout.name}), ("rig", {"method": "ellipsoid"})):
        job = wait_job(server, server.api("POST", f"/api/projects/{pid}/{post}", body)["id"], 120)
        assert job["state"] == "done", job["detail"]
    open_project(page, server, pid)
    page.wait_for_function("n => window.app.face && window.app.face.nJoints === n", arg=layout.n_points,
                           timeout=scaled_ms(60_000))
    page.evaluate(_LOG)
    unfiltered_from_the_first_frame(page)
    play_webcam(page)
    page.wait_for_function("() => { const sent = new Set(window.log.sent.map(s => s.index));"
                           " return window.log.frames.filter(f => sent.has(f.index)).length >= 12; }",
                           timeout=scaled_ms(90_000))
    assert np.abs(on_screen(page) - rest_vertices(server, project["id"])).max() > 0.05  # cm

    log = page.evaluate("() => window.log")
    sent = {s["index"]: np.array(s["points"], np.float32).reshape(-1, 3) for s in log["sent"] if "index" in s}
    assert {len(points) for points in sent.values()} == {layout.n_points}
    frames = [f for f in log["frames"] if f["index"] in sent]
    assert len(frames) >= 12 and all(f["flags"] == 0 for f in frames)
    assert {len(f["displacements"]) for f in frames} == {3 * layout.n_points}
    performer = _series(np.stack([sent[f["index"]] for f in frames]), layout)
    target = _series(np.stack([np.reshape(f["displacements"], (-1, 3)) for f in frames]), layout)
    for part in ("mouth", "brows"):
        r = np.corrcoef(performer[part], target[part])[0, 1]
        assert r > 0.8, f"{part}: correlation {r:.2f} between performer and target"
        assert np.ptp(target[part]) > 0.05, f"{part}: the target moves only {np.ptp(target[part]):.3f} cm"
    # the cheeks, which no short layout drives, move with her too
    cheeks = np.array(layout.regions) == "cheeks"
    moved = np.ptp(np.stack([np.reshape(f["displacements"], (-1, 3))[cheeks] for f in frames]), axis=0)
    assert np.linalg.norm(moved, axis=1).max() > 0.05
    stop_releases_the_camera_and_rests(page, server, project["id"])
