"""Zero clicks from upload to a moving face (issue 14): the sample face picked in the file
chooser of a new project and, with no click after it, its points appear (found by the
server), it is rigged and the built-in demo moves it; the points the finder is unsure of
are ringed on the face and named by region in the Landmarks panel. A mesh with no face
says so under *Find points*, not as an error, and its points are placed by hand as before.
"""

from __future__ import annotations

import io

import numpy as np
import pytest
import trimesh
from PIL import Image

from retarget.layouts import get_layout
from retarget.mesh import mesh_from_arrays, save_mesh
from retarget.sample_face import sample_face
from tests.e2e.conftest import open_project, wait_face_moves
from tests.waits import scaled_ms


@pytest.fixture(scope="module")
def face_file(tmp_path_factory):
    face = sample_face(1)
    path = tmp_path_factory.mktemp("meshes") / "scan.obj"
    save_mesh(mesh_from_arrays(face.vertices, face.faces), path)
    return path, face


def _upload(server, page, path, name: str) -> str:
    project = server.api("POST", "/api/projects", {"name": name})
    open_project(page, server, project["id"])
    page.set_input_files("#file-input", str(path))
    return project["id"]


def _red_pixels(page, xy: dict, half: int = 12) -> int:
    """Pixels around screen point `xy` that are strongly red (the halo of a point to check)."""
    clip = {"x": xy["x"] - half, "y": xy["y"] - half, "width": 2 * half, "height": 2 * half}
    rgb = np.asarray(Image.open(io.BytesIO(page.screenshot(clip=clip))).convert("RGB"), np.int32)
    return int(((rgb[..., 0] - np.maximum(rgb[..., 1], rgb[..., 2])) > 60).sum())


def test_an_uploaded_face_is_found_rigged_and_moving_with_no_click(server, page, face_file):
    path, face = face_file
    pid = _upload(server, page, path, "zero click")
    layout = get_layout("dutreve22")  # a new project's layout

    # no click from here on: the points are found, the face rigged and the demo plays
    page.wait_for_function("n => window.app.face && window.app.face.nJoints === n && window.app.streaming"
                           " && window.app.stream.stats.frames > 30", arg=layout.n_points,
                           timeout=scaled_ms(120_000))
    assert page.inner_text("#error").strip() == ""
    project = server.api("GET", f"/api/projects/{pid}")
    assert project["landmarks"] == {"layout": layout.name, "n_points": layout.n_points}
    assert project["rig"] is not None
    stored = server.api("GET", f"/api/projects/{pid}/landmarks")
    shown = page.evaluate("() => window.app.picker.state")
    assert shown["layout"] == layout.name
    assert [p["triangle"] for p in shown["points"]] == stored["triangles"]
    assert page.inner_text("#landmark-count") == f"{layout.n_points} / {layout.n_points}"
    assert not page.is_visible("#unsaved")

    # the face moves: the skinning shader's vertices leave the rest pose by millimetres
    wait_face_moves(page, 0.1)

    # the points to check: named by region in the panel, ringed on the face once it stops
    confidence = np.array(stored["confidence"])
    flagged = np.flatnonzero(confidence < stored["check_below"])
    assert len(flagged) > 0  # the sample face has no brow in its geometry and a soft jaw
    regions = list(dict.fromkeys(layout.regions[i].replace("_", " ") for i in flagged))
    note = page.inner_text("#find-note")
    assert note.startswith(f"Check {len(flagged)} point{'s' if len(flagged) > 1 else ''}: {', '.join(regions)}"), note
    page.click("#stop")
    page.wait_for_function("n => window.app.picker.markers.group.visible"
                           " && window.app.picker.markers.flaggedCount === n", arg=len(flagged))
    page.evaluate("() => new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)))")
    screen = lambda i: page.evaluate("i => window.app.viewer.project(window.app.picker.worldPosition(i))", int(i))
    trusted = layout.point_names.index("nose_tip")
    assert confidence[trusted] >= stored["check_below"]
    assert _red_pixels(page, screen(flagged[0])) > 40
    assert _red_pixels(page, screen(trusted)) < 5

    # dragging a flagged point over the surface is checking it: its ring goes
    start = screen(flagged[0])
    page.mouse.move(start["x"], start["y"])
    page.mouse.down()
    page.mouse.move(start["x"] + 4, start["y"] + 6, steps=4)
    page.mouse.up()
    page.wait_for_function("n => window.app.picker.markers.flaggedCount === n", arg=len(flagged) - 1)
    assert page.is_visible("#unsaved")


def test_a_mesh_with_no_face_says_so_and_is_placed_by_hand(server, page, tmp_path):
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=8.0)
    path = tmp_path / "ball.obj"
    save_mesh(mesh_from_arrays(sphere.vertices, sphere.faces), path)
    pid = _upload(server, page, path, "no face")
    page.wait_for_function("() => document.getElementById('find-note').textContent.startsWith('No face found')",
                           timeout=scaled_ms(120_000))
    assert "place the points by hand" in page.inner_text("#find-note")
    assert page.inner_text("#error").strip() == ""
    assert server.api("GET", f"/api/projects/{pid}")["landmarks"] is None
    assert page.is_hidden("#find-progress") and page.is_enabled("#find-points")
    # a click places the next point, as on any mesh
    xy = page.evaluate("p => window.app.viewer.project(p)", [0.0, 0.0, 8.0])
    page.mouse.click(xy["x"], xy["y"])
    assert page.evaluate("() => window.app.picker.placedCount") == 1
