"""A custom layout made in the page from a take's markers: the fold under the Landmarks
panel lists the take, makes a row of each marker, the user sets regions, sides and
partners and saves it; the layout is chosen, its points are clicked on the mesh in the
take's order with the landmark picker and saved, and a reload shows them in it."""

from __future__ import annotations

import json

import httpx
import numpy as np
import pytest

from retarget.landmarks import landmarks_from_json
from tests.e2e.conftest import upload_face, write_face_file
from tests.waits import scaled_ms

_IDENTITY = np.array([0.2, 0.6, -0.4, 0.1, 0.5])
# the user's six markers, on iBUG spots: brows, mouth corners, nose tip, chin
MARKERS = {"m1": (19, "brows", "right", "m2"), "m2": (24, "brows", "left", "m1"),
           "m3": (48, "mouth_corners", "right", "m4"), "m4": (54, "mouth_corners", "left", "m3"),
           "m5": (30, "nose", "center", ""), "m6": (8, "jaw", "center", "")}
CLICK_TOLERANCE = 0.15  # cm, as test_ui_editing's


@pytest.fixture(scope="module")
def server(module_server):
    """One server for the module: the test makes a project of its own."""
    return module_server


@pytest.fixture(scope="module")
def face_file(tmp_path_factory):
    return write_face_file(tmp_path_factory.mktemp("meshes"), "custom_face.obj", _IDENTITY)


def _screen(page, point) -> tuple[float, float]:
    xy = page.evaluate("p => window.app.viewer.project(p)", [float(c) for c in point])
    return xy["x"], xy["y"]


def test_a_layout_made_from_a_take_s_markers_is_placed_and_saved(server, page, face_file):
    project, face = upload_face(server, page, face_file, "my markers")
    page.evaluate("() => window.app.animation")  # the upload's find and rig, done
    pid = project["id"]
    rest = face.vertices[[face.landmarks68[i] for i, *_ in MARKERS.values()]]
    take = json.dumps({"names": list(MARKERS), "frames": [rest.tolist()] * 20}).encode()

    # the take file's markers (as a take it would be refused: the project's found points
    # are dutreve22's, which none of its markers is)
    page.click("#custom-layout summary")
    page.set_input_files("#custom-file", files=[{"name": "sticks.json", "mimeType": "application/json",
                                                 "buffer": take}])
    page.wait_for_function("() => document.querySelectorAll('#custom-points tbody tr').length === 6")
    for i, (name, (_, region, side, partner)) in enumerate(MARKERS.items()):
        assert page.inner_text(f"#custom-points tbody tr:nth-child({i + 1}) td") == name
        page.select_option(f"#custom-region-{i}", region)
        page.select_option(f"#custom-side-{i}", side)
        page.select_option(f"#custom-mirror-{i}", partner)
    page.fill("#custom-name", "sticks")
    page.click("#custom-save")
    page.wait_for_function("() => window.app.landmarks.state.layout.startsWith('custom-')"
                           " || document.querySelector('#confirm').open", timeout=scaled_ms(30_000))
    if page.evaluate("() => document.querySelector('#confirm').open"):
        page.click("#confirm-ok")  # the found points give way to the user's layout
        page.wait_for_function("() => window.app.landmarks.state.layout.startsWith('custom-')")
    layout = page.input_value("#layout-select")
    assert "Saved sticks (6 points)" in page.inner_text("#custom-note")
    saved = server.api("GET", f"/api/projects/{pid}/layouts/sticks")
    assert saved["name"] == layout and [p["name"] for p in saved["points"]] == list(MARKERS)
    assert saved["points"][0]["mirror"] == 1 and saved["points"][4]["region"] == "nose"

    assert page.inner_text("#landmark-count") == "0 / 6"  # no found point is one of the user's
    for name, point in zip(MARKERS, rest):
        assert page.inner_text("#next-point") == name
        page.mouse.click(*_screen(page, point))
    assert page.inner_text("#landmark-count") == "6 / 6"
    page.click("#save-landmarks")
    page.wait_for_function("() => !window.app.picker.dirty")
    stored = server.api("GET", f"/api/projects/{pid}/landmarks")
    assert stored["layout"] == layout and [p["name"] for p in stored["layout_spec"]["points"]] == list(MARKERS)
    positions = landmarks_from_json(stored, face.vertices, face.faces).positions(face.vertices)
    assert np.linalg.norm(positions - rest, axis=1).max() < CLICK_TOLERANCE
    assert page.inner_text("#error").strip() == ""

    # now the take is one of the project's layout: it is stored, and the fold lists it
    reply = httpx.post(f"{server.url}/api/projects/{pid}/takes", data={"fps": "30"},
                       files={"file": ("sticks.json", take)})
    assert reply.status_code == 201, reply.text
    page.click("#custom-layout summary")
    page.click("#custom-layout summary")
    page.wait_for_function("() => document.querySelectorAll('#custom-take option').length === 1")

    page.reload()  # the project's layout is listed and chosen again, its points placed
    page.wait_for_function("() => window.app && window.app.projectId")
    page.evaluate("() => window.app.ready")
    assert page.input_value("#layout-select") == layout
    assert page.inner_text("#landmark-count") == "6 / 6"
