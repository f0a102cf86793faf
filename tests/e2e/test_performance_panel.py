"""The Performance panel end to end on the sample project (68-point iBUG rig): a take
file imported, played, renamed, trimmed, downloaded and deleted from the page; a ring-
marker video tracked by the server with the progress bar; and bad input, each refused
with a message naming the problem while the project and its takes stay as they were.

Ground truth: the take is the sample face's 68 landmarks opening the jaw between known
times, so the frames the stream plays must move the face exactly when the take does; the
marker video is rendered by `retarget.testing.marker_video`. One server and one page
serve the whole module (the sample project's rig loads once).
"""

from __future__ import annotations

import multiprocessing
import re
from concurrent.futures import ProcessPoolExecutor

import cv2
import numpy as np
import pytest

from retarget.layouts import get_layout
from retarget.sample_face import EXPRESSION_NAMES, posed_vertices, sample_face
from retarget.sources.files import write_take_csv
from retarget.sources.take import Take
from retarget.testing.marker_video import default_camera, render_marker_video
from retarget.testing.render import render_face
from tests.e2e.conftest import ARTIFACTS, Server, _expected_error, open_project, sample_copy, wait_face_moves
from tests.waits import scaled_ms

FPS = 30.0
N_FRAMES = 90
TRIM = (0.5, 2.5)  # s: starts at rest, so the trimmed take's neutral is a rest pose
MARKER_FRAMES = 16

# Collects every stream frame and control message the page receives, from now on.
_RECORD = """() => {
    window.streamFrames = [];
    window.messages = [];
    window.app.stream.addEventListener('frame', (e) => window.streamFrames.push({
        index: e.detail.frameIndex, time: e.detail.sourceTime,
        d: Array.from(e.detail.displacements)}));
    window.app.stream.addEventListener('message', (e) => window.messages.push(e.detail));
}"""

# Every (hidden, value) state the source progress bar is put in, from now on
# (window.progress; `bar_runs` reads it).
WATCH_PROGRESS = """() => {
    const bar = document.getElementById('source-progress');
    window.progress = [];
    const properties = [[HTMLElement.prototype, 'hidden'], [HTMLProgressElement.prototype, 'value']];
    for (const [proto, key] of properties) {
        const property = Object.getOwnPropertyDescriptor(proto, key);
        Object.defineProperty(bar, key, {configurable: true, get() { return property.get.call(this); },
            set(v) { property.set.call(this, v); window.progress.push([this.hidden, this.value]); }});
    }
}"""


def bar_runs(progress: list) -> list[list[float]]:
    """The values of each stretch the source progress bar was shown, from the (hidden,
    value) states `WATCH_PROGRESS` collected."""
    runs, run = [], None
    for hidden, value in progress:
        if hidden:
            run = None
        elif run is None:
            runs.append(run := [value])
        else:
            run.append(value)
    return runs


def assert_upload_then_job(page) -> None:
    """The source bar showed the upload, then the server's job from 0 to done, never going
    back, and is hidden at the end."""
    progress = page.evaluate("() => window.progress")
    runs = bar_runs(progress)
    assert len(runs) == 2 and progress[-1][0] is True, progress
    job = runs[1]
    assert job[0] == 0 and job[-1] == 1 and job == sorted(job), job


def jaw_weight(t: np.ndarray) -> np.ndarray:
    """(F,) jawOpen weight at times t (s): rest until 1.1 s, open by 1.4 s, held to 1.8 s,
    closed again by 2.1 s (smooth ramps)."""
    up = np.clip((t - 1.1) / 0.3, 0, 1)
    down = np.clip((2.1 - t) / 0.3, 0, 1)
    w = np.minimum(up, down)
    return w * w * (3 - 2 * w)


@pytest.fixture(scope="module")
def server(tmp_path_factory, sample_data_dir):
    srv = Server(sample_copy(sample_data_dir, tmp_path_factory.mktemp("perf") / "data")).start()
    yield srv
    srv.stop()


@pytest.fixture(scope="module")
def shared_page(browser, server):
    """One page on the sample project for the module; console errors collect in
    `page.console_errors` and fail the test during which they appeared."""
    context = browser.new_context(viewport={"width": 1280, "height": 800}, accept_downloads=True)
    page = context.new_page()
    page.set_default_timeout(15_000)
    page.console_errors = []
    page.on("console", lambda msg: page.console_errors.append(f"console.{msg.type}: {msg.text}")
            if msg.type == "error" and not _expected_error(msg.text) else None)
    page.on("pageerror", lambda exc: page.console_errors.append(f"page error: {exc}"))
    sample = next(p for p in server.api("GET", "/api/projects") if p["rig"])
    open_project(page, server, sample["id"])
    page.wait_for_function("() => window.app.face && window.app.face.nJoints === 68", timeout=scaled_ms(30_000))
    page.sample = sample
    yield page
    context.close()


@pytest.fixture
def page(shared_page, request):
    """The module's page, the error banner cleared; a screenshot after each test."""
    shared_page.evaluate("() => window.app.errors.clear()")
    yield shared_page
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    name = re.sub(r"[^A-Za-z0-9_.-]+", "_", request.node.name)
    shared_page.screenshot(path=str(ARTIFACTS / f"{name}.png"))
    errors, shared_page.console_errors[:] = list(shared_page.console_errors), []
    assert not errors, "browser reported errors:\n" + "\n".join(errors)


@pytest.fixture(scope="module")
def jaw_take() -> Take:
    """The sample face's 68 landmarks (cm) at 30 fps opening and closing the jaw."""
    face = sample_face(1)
    t = np.arange(N_FRAMES) / FPS
    weights = np.zeros((N_FRAMES, len(EXPRESSION_NAMES)))
    weights[:, EXPRESSION_NAMES.index("jawOpen")] = jaw_weight(t)
    points = posed_vertices(face, weights)[:, face.landmarks68].astype(np.float32)
    return Take(points, get_layout("ibug68").point_names, FPS)


@pytest.fixture(scope="module", autouse=True)
def rendering(tmp_path_factory):
    """The module's marker video rendered in another process from the start, so the
    rendering (a few seconds) overlaps the first test: (path, its future)."""
    path = tmp_path_factory.mktemp("video") / "markers.avi"
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        yield path, pool.submit(render_marker_video, path, n_frames=MARKER_FRAMES, seed=3, start=0.55)


@pytest.fixture(scope="module")
def marker_video(rendering):
    """A short ring-marker video (MJPG .avi) of the sample face talking and blinking."""
    path, future = rendering
    future.result(timeout=120)
    return path


def reload(page) -> None:
    """Reload the page and wait until the sample project and its face are shown again."""
    page.reload()
    page.wait_for_function("() => window.app && window.app.projectId")
    page.evaluate("() => window.app.ready")
    page.wait_for_function("() => window.app.face && window.app.face.nJoints === 68", timeout=scaled_ms(30_000))


def open_conditioning(page) -> None:
    if not page.evaluate("() => document.getElementById('conditioning').open"):
        page.click("#conditioning summary")


def takes(server, page) -> list[dict]:
    return server.api("GET", f"/api/projects/{page.sample['id']}/takes")


def take_row(page, take_id: str):
    return page.locator(f"#take-list li[data-take='{take_id}']")


def play_to_the_end(page) -> tuple[dict, list[dict]]:
    """Play the selected take once (no loop); the 'started' message and every frame
    received up to its last one."""
    page.evaluate("() => { window.streamFrames.length = 0; window.messages.length = 0; }")
    page.click("#play")
    page.wait_for_function("() => window.messages.some(m => m.type === 'started')", timeout=scaled_ms(15_000))
    started = page.evaluate("() => window.messages.find(m => m.type === 'started')")
    page.wait_for_function("n => window.streamFrames.some(f => f.index === n - 1)",
                           arg=started["frames"], timeout=scaled_ms(30_000))
    # the last frame says it is the last: the page is back at Play, nothing to stop
    page.wait_for_function("() => document.getElementById('stop').disabled", timeout=scaled_ms(5_000))
    return started, page.evaluate("() => window.streamFrames")


def motion(frames: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """(indices (K,), largest point displacement (K,)) of the received frames."""
    index = np.array([f["index"] for f in frames])
    d = np.array([f["d"] for f in frames], np.float64).reshape(len(frames), -1, 3)
    return index, np.linalg.norm(d, axis=2).max(axis=1)


def assert_motion_follows(weight: np.ndarray, size: np.ndarray) -> None:
    """The face is still where the take rests and moves with the jaw where it opens."""
    assert size.max() > 0.1, size.max()  # cm on the sample face
    assert np.all(size[weight == 0] < 1e-3 * size.max()), size[weight == 0].max()
    assert np.all(size[weight > 0.99] > 0.5 * size.max())
    assert np.corrcoef(weight, size)[0, 1] > 0.99


def test_imported_take_plays_renames_trims_downloads_and_deletes(server, page, jaw_take, tmp_path):
    path = tmp_path / "jaw open.csv"
    write_take_csv(jaw_take, path)
    page.select_option("#source-select", "demo")
    page.set_input_files("#take-file", str(path))
    page.wait_for_selector("#take-list li", timeout=scaled_ms(15_000))
    (info,) = takes(server, page)
    assert info["name"] == "jaw open" and info["n_frames"] == N_FRAMES and info["n_points"] == 68
    assert info["dims"] == 3 and info["layout"] == "ibug68"
    assert info["duration"] == pytest.approx((N_FRAMES - 1) / FPS)
    assert info["trim"] == [0.0, pytest.approx(info["duration"])]
    assert page.is_hidden("#takes-empty")
    assert "jaw open" in take_row(page, info["id"]).inner_text()
    assert f"{N_FRAMES} frames" in page.inner_text("#source-note")

    # select it, play it once unfiltered: the face moves exactly where the take does
    page.select_option("#source-select", "demo")
    take_row(page, info["id"]).locator(".take-name").click()
    assert page.input_value("#source-select") == "take"
    open_conditioning(page)
    page.select_option("#filter", "none")
    page.uncheck("#take-loop")
    page.evaluate(_RECORD)
    started, frames = play_to_the_end(page)
    assert started["source"] == "take" and started["take"] == info["id"]
    # every frame plays, the neutral capture's first 0.5 s too (its neutral is found first)
    assert started["frames"] == N_FRAMES
    index, size = motion(frames)
    assert len(index) > started["frames"] // 2
    assert_motion_follows(jaw_weight(index / FPS), size)

    # rename in the list
    take_row(page, info["id"]).locator(".rename").click()
    box = take_row(page, info["id"]).locator("input.take-rename")
    box.fill("  wide jaw ")
    box.press("Enter")
    page.wait_for_function("id => document.querySelector(`#take-list li[data-take='${id}']`)"
                           ".innerText.includes('wide jaw')", arg=info["id"])
    assert takes(server, page)[0]["name"] == "wide jaw"

    # trim: the server keeps the span, playback covers only it
    row = take_row(page, info["id"])
    row.locator(".trim-start").fill(str(TRIM[0]))
    row.locator(".trim-start").press("Enter")
    page.wait_for_function("id => window.app.sources.takes.find(t => t.id === id).trim[0] > 0",
                           arg=info["id"])
    row = take_row(page, info["id"])
    row.locator(".trim-stop").fill(str(TRIM[1]))
    row.locator(".trim-stop").press("Enter")
    page.wait_for_function("([id, stop]) => window.app.sources.takes.find(t => t.id === id)"
                           ".trim[1] === stop", arg=[info["id"], TRIM[1]])
    (trimmed,) = takes(server, page)
    assert trimmed["trim"] == [pytest.approx(TRIM[0]), pytest.approx(TRIM[1])]
    span = jaw_take.trimmed(*TRIM)
    first = int(round(TRIM[0] * FPS))
    started, frames = play_to_the_end(page)
    assert started["frames"] == span.n_frames
    played = (started["frames"] - 1) / FPS
    assert started["duration"] == pytest.approx(played + 1 / FPS)
    index, size = motion(frames)
    assert index.max() == started["frames"] - 1
    assert max(f["time"] for f in frames) == pytest.approx(played)
    assert_motion_follows(jaw_weight((first + index) / FPS), size)

    # download: the trimmed take's points
    with page.expect_download() as download:
        take_row(page, info["id"]).locator(".download").click()
    got = np.load(download.value.path())
    np.testing.assert_allclose(got, span.points, atol=1e-5)

    # a reload shows the same list, names and spans
    reload(page)
    page.wait_for_selector(f"#take-list li[data-take='{info['id']}']")
    row = take_row(page, info["id"])
    assert "wide jaw" in row.inner_text()
    assert float(row.locator(".trim-start").input_value()) == pytest.approx(TRIM[0])
    assert float(row.locator(".trim-stop").input_value()) == pytest.approx(TRIM[1])
    assert page.locator("#take-list li").count() == len(takes(server, page))

    # delete, after confirming
    take_row(page, info["id"]).locator(".delete").click()
    page.click("#confirm-ok")
    page.wait_for_selector(f"#take-list li[data-take='{info['id']}']", state="detached")
    assert takes(server, page) == []
    assert page.is_visible("#takes-empty")


def test_marker_video_is_tracked_with_progress_into_a_take_that_moves_the_face(server, page,
                                                                              marker_video):
    before = takes(server, page)
    page.select_option("#video-method", "markers")
    page.evaluate(WATCH_PROGRESS)
    page.set_input_files("#video-file", str(marker_video))
    page.wait_for_function("n => window.app.sources.takes.length === n", arg=len(before) + 1,
                           timeout=scaled_ms(30_000))
    page.wait_for_selector("#source-progress", state="hidden")
    (info,) = [t for t in takes(server, page) if t["id"] not in {b["id"] for b in before}]
    assert info["name"] == "markers" and info["source"] == "markers"
    assert info["n_frames"] == MARKER_FRAMES and info["n_points"] == 21 and info["dims"] == 2
    assert f"{MARKER_FRAMES} frames" in page.inner_text("#source-note")
    assert page.is_enabled("#video-file") and page.is_enabled("#take-file")

    assert_upload_then_job(page)

    # it is selected; it is no longer than the default neutral capture (its first half
    # second), so Play says what to change instead of playing nothing
    assert page.input_value("#source-select") == "take"
    assert take_row(page, info["id"]).get_attribute("class") == "selected"
    page.check("#take-loop")
    open_conditioning(page)
    page.select_option("#neutral-mode", "first_seconds")
    page.fill("#neutral-value", "0.5")
    page.click("#play")
    page.wait_for_selector("#error", state="visible")
    assert re.search(r'"markers" lasts 0\.50 s, no longer than the neutral capture .* frame number',
                     page.inner_text("#error-text")), page.inner_text("#error-text")
    page.evaluate("() => window.app.errors.clear()")

    # with the neutral from its first frame, playing it moves the face
    page.select_option("#neutral-mode", "frame")
    page.fill("#neutral-value", "0")
    page.evaluate(_RECORD)
    page.click("#play")
    page.wait_for_function("() => window.streamFrames.length >= 20 || "
                           "!document.querySelector('#error').hidden", timeout=scaled_ms(30_000))
    assert page.inner_text("#error-text") == ""
    _, size = motion(page.evaluate("() => window.streamFrames"))
    assert size.max() > 0.05
    # and the face on screen is deformed by them (its skinned vertices leave the rest pose)
    wait_face_moves(page, 0.05)
    if page.is_enabled("#stop"):  # a short take played once may have ended by now
        page.click("#stop")


def _cut_video(tmp_path, marker_video):
    """The marker video with its second half cut off."""
    data = marker_video.read_bytes()
    path = tmp_path / "cut.avi"
    path.write_bytes(data[: len(data) // 2])
    return path


def _text_video(tmp_path, marker_video):
    path = tmp_path / "notes.mp4"
    path.write_text("not a video at all\n" * 50)
    return path


def _plain_video(tmp_path, marker_video):
    """Three rendered frames of the sample face without markers (MJPG)."""
    face = sample_face(1)
    rng = np.random.default_rng(0)
    camera = default_camera()
    path = tmp_path / "plain.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), FPS, camera.size)
    for _ in range(3):
        writer.write(render_face(camera, face.vertices, face.faces, noise=2.0, rng=rng).image)
    writer.release()
    return path


def _faceless_video(tmp_path, marker_video):
    """A second of noise, VP8 WebM: a video without a face."""
    path = tmp_path / "noise.webm"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"VP80"), FPS, (96, 96))
    rng = np.random.default_rng(4)
    for _ in range(int(FPS)):
        writer.write(rng.integers(0, 256, (96, 96, 3), dtype=np.uint8))
    writer.release()
    return path


def _unlabelled_c3d(tmp_path, marker_video):
    """A C3D of the 68 landmarks whose labels are a capture system's own (M01 ...), none
    of them a point of the project's layout."""
    import ezc3d

    face = sample_face(1)
    points = face.vertices[face.landmarks68] * 10  # mm
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [FPS]
    c3d["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = tuple(f"M{i + 1:02d}" for i in range(68))
    data = np.ones((4, 68, 20))
    data[:3] = points.T[:, :, None]
    c3d["data"]["points"] = data
    c3d["data"]["meta_points"]["residuals"] = np.zeros((1, 68, 20))
    c3d["data"]["meta_points"]["camera_masks"] = np.zeros((7, 68, 20), dtype=bool)
    path = tmp_path / "vicon.c3d"
    c3d.write(str(path))
    return path


def _empty_take(tmp_path, marker_video):
    path = tmp_path / "empty.csv"
    path.write_bytes(b"")
    return path


def _garbage_take(tmp_path, marker_video):
    path = tmp_path / "garbage.c3d"
    path.write_bytes(np.random.default_rng(1).integers(0, 256, 4000, dtype=np.uint8).tobytes())
    return path


# name: (the file, its input, the video method, what the message must say)
BAD = {
    "truncated video": (_cut_video, "#video-file", "markers",
                        rf"cut\.avi.*cut off: only \d+ of the {MARKER_FRAMES} frames"),
    "not a video": (_text_video, "#video-file", "markers", r"notes\.mp4.* is not a video"),
    "no markers": (_plain_video, "#video-file", "markers", r"plain\.avi.*found 0 ring markers"),
    "unknown labels": (_unlabelled_c3d, "#take-file", None,
                       r"vicon\.c3d.* none of the take's 68 labels \(M01, M02, .*\) is a point of layout 'ibug68'"),
    "empty take": (_empty_take, "#take-file", None, r"empty\.csv.* is empty"),
    "garbage take": (_garbage_take, "#take-file", None,
                     r"garbage\.c3d' refused: 'garbage\.c3d' is not a C3D file"),
    "no face": (_faceless_video, "#video-file", "markerless",
                rf"Face tracking failed: no face was found in any of the {int(FPS)} frames of 'noise\.webm'"),
}


@pytest.fixture(scope="module")
def kept_take(server, shared_page, jaw_take, tmp_path_factory) -> dict:
    """A take the project holds before the bad input (imported here when the module's
    earlier tests left none)."""
    held = takes(server, shared_page)
    if held:
        return held[0]
    path = tmp_path_factory.mktemp("kept") / "kept.csv"
    write_take_csv(jaw_take, path)
    info = shared_page.evaluate("""async ([id, text]) => {
        const form = new FormData();
        form.append('file', new File([text], 'kept.csv'));
        const reply = await fetch(`/api/projects/${id}/takes`, {method: 'POST', body: form});
        return reply.json();
    }""", [shared_page.sample["id"], path.read_text()])
    shared_page.evaluate("() => window.app.sources.refreshTakes()")
    return info


@pytest.mark.parametrize("case", list(BAD))
def test_bad_input_says_what_is_wrong_and_keeps_the_project(server, page, kept_take, marker_video,
                                                            tmp_path, case):
    make, control, method, expected = BAD[case]
    project_path = f"/api/projects/{page.sample['id']}"
    project, before = server.api("GET", project_path), takes(server, page)
    assert kept_take["id"] in {t["id"] for t in before}
    path = make(tmp_path, marker_video)
    if method:
        page.select_option("#video-method", method)
    page.evaluate("() => { const note = document.getElementById('source-note'); "
                  "note.textContent = ''; note.className = 'note'; }")
    page.set_input_files(control, str(path))

    # the message names the file and the problem: in the error banner, or for a cut-off
    # video whose frames up to the cut were kept, as a warning under the takes
    page.wait_for_function("() => !document.getElementById('error').hidden || "
                           "document.getElementById('source-note').classList.contains('warn')",
                           timeout=scaled_ms(45_000))
    shown = page.inner_text("#error-text") or page.inner_text("#source-note")
    assert re.search(expected, shown, re.IGNORECASE), shown

    # nothing is left half done in the panel
    page.wait_for_selector("#source-progress", state="hidden")
    assert page.is_enabled("#take-file") and page.is_enabled("#video-file")
    assert not re.search(r"uploading|tracking", page.inner_text("#source-note"), re.IGNORECASE)

    # the project and its takes are as they were (a cut-off video adds its frames' take)
    assert server.api("GET", project_path) == project
    after = takes(server, page)
    assert [t for t in after if t["id"] in {b["id"] for b in before}] == before
    added = [t for t in after if t not in before]
    if case == "truncated video":
        (cut,) = added
        assert 0 < cut["n_frames"] < MARKER_FRAMES
        assert f"only {cut['n_frames']} of the {MARKER_FRAMES} frames" in shown
    else:
        assert added == []
    assert page.locator("#take-list li").count() == len(after)
