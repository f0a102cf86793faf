"""From a ring-marker video to the user's own layout, in the app (issue 17): *Track…* with
"every marker in view" makes a take of markers m01..m04; the Custom layout fold opens on
the video's first frame with each marker labelled; the user clicks a marker on the frame
(or its row) and its point on the mesh, in an order of their own (the first chosen before
the layout is saved), and saves the layout and the landmarks. The saved landmarks name each point after the marker clicked.

The video is the built-in face with four ring markers (brows, nose tip, lower lip) rendered
by `retarget.testing.marker_video`; the mesh is the same face with another identity, so
each marker's vertex is the spot on the mesh its point belongs at."""

from __future__ import annotations

import numpy as np
import pytest

from retarget.landmarks import landmarks_from_json
from retarget.sample_face import sample_face
from retarget.testing.marker_video import render_marker_video
from tests.e2e.conftest import upload_face, write_face_file
from tests.waits import scaled_ms

_IDENTITY = np.array([-0.3, 0.4, 0.2, -0.5, 0.1])
MARKED = [19, 24, 30, 57]  # iBUG points of the sample face carrying the markers
CLICK_TOLERANCE = 0.15  # cm, as test_custom_layout_ui's


@pytest.fixture(scope="module")
def server(module_server):
    """One server for the module: the test makes a project of its own."""
    return module_server


@pytest.fixture(scope="module")
def face_file(tmp_path_factory):
    return write_face_file(tmp_path_factory.mktemp("meshes"), "own_face.obj", _IDENTITY)


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    """(path, truth, marker vertices) of a 30-frame video of four ring markers."""
    vertices = np.asarray(sample_face(1).landmarks68)[MARKED]
    path = tmp_path_factory.mktemp("video") / "four.mkv"
    truth = render_marker_video(path, n_frames=30, seed=3, start=0.55, vertices=vertices)
    return path, truth, vertices


def _screen(page, point) -> tuple[float, float]:
    xy = page.evaluate("p => window.app.viewer.project(p)", [float(c) for c in point])
    return xy["x"], xy["y"]


def test_markers_clicked_on_the_first_frame_place_their_points(server, page, face_file, video):
    path, truth, vertices = video
    project, face = upload_face(server, page, face_file, "own markers")
    page.evaluate("() => window.app.animation")  # the upload's find and rig, done
    pid = project["id"]

    page.select_option("#video-method", "own-markers")
    page.set_input_files("#video-file", str(path))
    page.wait_for_function("() => document.querySelectorAll('#custom-frame button').length === 4"
                           " && document.getElementById('custom-frame-image').naturalWidth === 640",
                           timeout=scaled_ms(60_000))
    assert page.evaluate("() => document.getElementById('custom-layout').open")
    assert page.inner_text("#custom-note").endswith(" Click a marker on the frame, then its point on the mesh.")
    [take] = server.api("GET", f"/api/projects/{pid}/takes")
    assert page.input_value("#custom-take") == take["id"]
    names = [f"m0{k}" for k in range(1, 5)]
    assert page.eval_on_selector_all("#custom-points tbody tr td:first-child", "cells => cells.map(c => c.textContent)") == names
    assert page.eval_on_selector_all("#custom-frame button", "labels => labels.map(l => l.textContent)") == names

    # which marker each label is on, by the server's first-frame places and the truth
    places = server.api("GET", f"/api/projects/{pid}/takes/{take['id']}/preview/markers")["markers"]
    spot = {}
    for m in places:
        k = int(np.argmin(np.linalg.norm(truth.points2d[0, 0] - [m["x"], m["y"]], axis=1)))
        spot[m["name"]] = face.vertices[vertices[k]]
    assert len({tuple(p) for p in spot.values()}) == 4

    # a marker chosen before the layout is saved is the first placed once it is chosen
    page.click("#custom-frame button[data-marker='m03']")
    assert page.inner_text("#custom-note") == "m03 chosen: save the layout, then click its point on the mesh."
    assert page.get_attribute("#custom-frame button[data-marker='m03']", "aria-pressed") == "true"
    page.select_option("#custom-region-2", "nose")
    page.fill("#custom-name", "four")
    page.click("#custom-save")
    page.wait_for_function("() => window.app.landmarks.state.layout.startsWith('custom-')"
                           " || document.querySelector('#confirm').open", timeout=scaled_ms(30_000))
    if page.evaluate("() => document.querySelector('#confirm').open"):
        page.click("#confirm-ok")  # the found points give way to the user's layout
        page.wait_for_function("() => window.app.landmarks.state.layout.startsWith('custom-')")
    assert page.inner_text("#landmark-count") == "0 / 4"
    page.wait_for_function("() => document.getElementById('next-point').textContent === 'm03'")
    page.mouse.click(*_screen(page, spot["m03"]))

    # out of the layout's order: markers on the frame, the last by its row
    for name in ("m01", "m04"):
        page.click(f"#custom-frame button[data-marker='{name}']")
        assert page.inner_text("#next-point") == name
        assert page.inner_text("#custom-note") == f"Click {name}'s point on the mesh."
        page.mouse.click(*_screen(page, spot[name]))
    assert page.inner_text("#landmark-count") == "3 / 4"
    assert page.get_attribute("#custom-frame button[data-marker='m04']", "aria-pressed") == "true"
    page.click("#custom-points tbody tr[data-marker='m02'] td")
    assert page.inner_text("#next-point") == "m02"
    page.mouse.click(*_screen(page, spot["m02"]))
    assert page.inner_text("#landmark-count") == "4 / 4"
    page.click("#save-landmarks")
    page.wait_for_function("() => !window.app.picker.dirty")

    layout = server.api("GET", f"/api/projects/{pid}/layouts/four")
    assert [p["name"] for p in layout["points"]] == names and layout["points"][2]["region"] == "nose"
    stored = server.api("GET", f"/api/projects/{pid}/landmarks")
    assert stored["layout"] == layout["name"]
    assert [p["name"] for p in stored["layout_spec"]["points"]] == names
    positions = landmarks_from_json(stored, face.vertices, face.faces).positions(face.vertices)
    expected = np.array([spot[name] for name in names])
    assert np.linalg.norm(positions - expected, axis=1).max() < CLICK_TOLERANCE
    assert page.inner_text("#error").strip() == ""
