"""Landmark editing in a real browser: click points where known vertices appear on screen,
drag one over the surface, undo and redo, delete, mirror, save, reload, switch layouts;
unsaved points survive a reload."""

from __future__ import annotations

import base64

import numpy as np
import pytest

from retarget.landmarks import landmarks_from_json
from retarget.layouts import get_layout
from tests.e2e.conftest import write_face_file, open_project, upload_face
from tests.waits import scaled_ms

_IDENTITY = np.array([0.5, -0.4, 0.7, -0.3, 0.2])  # neither the sample project's face nor test_app_flow's
CLICK_TOLERANCE = 0.15  # cm: a click lands within a few pixels, about 0.03 cm each at this zoom


@pytest.fixture(scope="module")
def server(module_server):
    """One server for the module (a start costs seconds of CPU): each test edits a project
    of its own, and the sample project is only read."""
    return module_server


@pytest.fixture(scope="module")
def face_file(tmp_path_factory):
    """An OBJ of a generated face (cm, symmetric about x = 0) and the face."""
    return write_face_file(tmp_path_factory.mktemp("meshes"), "edit_face.obj", _IDENTITY)






def screen(page, point) -> tuple[float, float]:
    xy = page.evaluate("p => window.app.viewer.project(p)", [float(c) for c in point])
    return xy["x"], xy["y"]


def click_at(page, point) -> None:
    page.mouse.click(*screen(page, point))


def marker_screen(page, index: int) -> tuple[float, float]:
    xy = page.evaluate("i => window.app.viewer.project(window.app.picker.worldPosition(i))", index)
    return xy["x"], xy["y"]


def picked(page) -> list[list[float] | None]:
    """Rest positions of the picker's points (None: unplaced)."""
    return page.evaluate("""() => window.app.picker.points.map((p, i) =>
        p ? window.app.picker.position(i).toArray() : null)""")


def placed_count(page) -> int:
    return page.evaluate("() => window.app.picker.placedCount")



def test_pick_drag_undo_delete_mirror_save_reload_and_switch_layout(server, page, face_file):
    project, face = upload_face(server, page, face_file, "editing")
    layout = get_layout("dutreve21")
    page.select_option("#layout-select", "dutreve21")
    targets = face.vertices[face.landmarks68[list(layout.ibug68)]]

    # click every point in layout order where its vertex appears
    for i, point in enumerate(targets):
        assert page.inner_text("#next-point") == layout.point_names[i]
        click_at(page, point)
    assert placed_count(page) == layout.n_points
    assert "all placed" in page.inner_text("#next-point")
    assert page.inner_text("#landmark-count") == f"{layout.n_points} / {layout.n_points}"
    error = np.linalg.norm(np.array(picked(page)) - targets, axis=1)
    assert error.max() < CLICK_TOLERANCE, f"click error up to {error.max():.3f} cm"

    # drag the nose tip's marker up the bridge: it slides over the surface, one undo step
    tip = layout.point_names.index("nose_tip")
    bridge = face.vertices[face.landmarks68[get_layout("ibug68").point_names.index("nose_bridge_lower")]]
    before = picked(page)
    start, end = marker_screen(page, tip), screen(page, bridge)
    page.mouse.move(*start)
    page.mouse.down()
    for t in np.linspace(0.2, 1.0, 6):
        page.mouse.move(start[0] + t * (end[0] - start[0]), start[1] + t * (end[1] - start[1]))
    page.mouse.up()
    moved = picked(page)
    assert np.linalg.norm(np.array(moved[tip]) - bridge) < CLICK_TOLERANCE
    assert all(moved[i] == before[i] for i in range(layout.n_points) if i != tip)
    assert page.evaluate("() => window.app.picker.selected") == tip
    page.click("#undo")
    assert picked(page) == before
    page.keyboard.press("Control+Shift+Z")
    assert picked(page) == moved
    page.keyboard.press("Control+Z")
    assert picked(page) == before
    page.keyboard.press("Control+Y")
    assert picked(page) == moved
    page.keyboard.press("Control+Z")

    # delete the left side: select a marker (a click once all are placed, else Shift+click:
    # a plain click places the next point), then Delete (or the button)
    left = [i for i, side in enumerate(layout.sides) if side == "left"]
    for k, i in enumerate(left):
        if k:
            page.keyboard.down("Shift")
        page.mouse.click(*marker_screen(page, i))
        page.keyboard.up("Shift")
        assert page.evaluate("() => window.app.picker.selected") == i
        if k % 2:
            page.click("#delete-point")
        else:
            page.keyboard.press("Delete")
    assert placed_count(page) == layout.n_points - len(left)
    assert page.inner_text("#next-point") in {layout.point_names[i] for i in left}
    page.keyboard.press("Control+Z")
    assert placed_count(page) == layout.n_points - len(left) + 1
    page.click("#redo")
    assert placed_count(page) == layout.n_points - len(left)

    # mirror puts every left point back at the mirror image of its right partner
    page.click("#mirror")
    assert placed_count(page) == layout.n_points
    mirrored = np.array(picked(page))
    error = np.linalg.norm(mirrored - targets, axis=1)
    assert error.max() < 2 * CLICK_TOLERANCE, f"mirror error up to {error.max():.3f} cm"
    page.click("#undo")
    assert placed_count(page) == layout.n_points - len(left)
    page.click("#redo")
    assert placed_count(page) == layout.n_points

    # save, then a reload shows the saved points and nothing unsaved
    assert page.is_visible("#unsaved")
    page.click("#save-landmarks")
    page.wait_for_function("() => !window.app.picker.dirty")
    stored = server.api("GET", f"/api/projects/{project['id']}/landmarks")
    assert stored["layout"] == "dutreve21"
    positions = landmarks_from_json(stored, face.vertices, face.faces).positions(face.vertices)
    np.testing.assert_allclose(positions, mirrored, atol=1e-4)
    page.reload()
    page.wait_for_function("() => window.app && window.app.projectId")
    page.evaluate("() => window.app.ready")
    assert page.evaluate("() => window.app.projectId") == project["id"]
    assert page.input_value("#layout-select") == "dutreve21"
    np.testing.assert_allclose(np.array(picked(page)), positions, atol=1e-4)
    assert not page.is_visible("#unsaved")
    assert page.evaluate("() => window.app.picker.canUndo") is False

    # a layout switch asks first; the points it shares by name carry over; undo switches back
    page.select_option("#layout-select", "ibug51")
    page.click("#confirm-ok")
    page.wait_for_function("() => window.app.picker.state.layout === 'ibug51'")
    ibug51 = get_layout("ibug51")
    assert page.inner_text("#landmark-count") == f"{layout.n_points} / {ibug51.n_points}"
    carried = picked(page)
    for name, position in zip(layout.point_names, positions):
        assert np.allclose(carried[ibug51.point_names.index(name)], position, atol=1e-4)
    page.click("#undo")
    assert page.input_value("#layout-select") == "dutreve21"
    assert placed_count(page) == layout.n_points

    # answering no keeps the layout and the points
    page.select_option("#layout-select", "ibug68")
    page.click("#confirm-cancel")
    page.wait_for_function("() => !document.querySelector('#confirm').open"
                           " && document.querySelector('#layout-select').value === 'dutreve21'")
    assert placed_count(page) == layout.n_points

    # saving an incomplete set is refused with the missing names, and nothing is sent
    page.click("#clear-points")
    page.click("#save-landmarks")
    assert "not placed" in page.inner_text("#error") and "brow_right_outer" in page.inner_text("#error")
    assert server.api("GET", f"/api/projects/{project['id']}/landmarks") == stored


def test_unsaved_points_survive_a_reload(server, page, face_file):
    project, face = upload_face(server, page, face_file, "editing")
    layout = get_layout("dutreve21")
    page.select_option("#layout-select", "dutreve21")
    for point in face.vertices[face.landmarks68[list(layout.ibug68[:5])]]:
        click_at(page, point)
    before = picked(page)
    # the draft reaches the server in the project's settings shortly after the last edit
    server.wait_for_project(project["id"], lambda p: p["settings"].get("draft") and sum(
        point is not None for point in p["settings"]["draft"]["points"]) == 5)
    page.reload()
    page.wait_for_function("() => window.app && window.app.projectId")
    page.evaluate("() => window.app.ready")
    assert picked(page) == before
    assert page.is_visible("#unsaved")
    assert page.inner_text("#next-point") == layout.point_names[5]
    assert server.api("GET", f"/api/projects/{project['id']}")["landmarks"] is None


def drop_file(page, name: str, data: bytes) -> None:
    """Drop a file on the view as a drag from the desktop would."""
    page.evaluate("""([name, b64]) => {
        const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
        const transfer = new DataTransfer();
        transfer.items.add(new File([bytes], name));
        const zone = document.querySelector('#drop-zone');
        for (const type of ['dragenter', 'dragover', 'drop'])
            zone.dispatchEvent(new DragEvent(type, {dataTransfer: transfer, bubbles: true, cancelable: true}));
    }""", [name, base64.b64encode(data).decode()])


def test_drop_a_mesh_on_the_view_keeps_the_landmarked_project(server, page, face_file):
    path, face = face_file
    before = server.api("GET", "/api/projects")  # the sample, and the projects of earlier tests
    sample = next(p for p in before if p["settings"].get("sample"))
    open_project(page, server, sample["id"])

    drop_file(page, "notes.docx", b"PK\x03\x04")
    page.wait_for_function("() => document.querySelector('#error').innerText.includes('.docx')")
    page.click("#error-close")
    assert not page.is_visible("#error")

    # the sample has landmarks and a rig: the dropped mesh goes into a new project
    drop_file(page, path.name, path.read_bytes())
    page.wait_for_function("id => window.app.projectId !== id && window.app.face && window.app.face"
                           ".mesh.geometry.attributes.position.count === 8430", arg=sample["id"], timeout=scaled_ms(30_000))
    page.evaluate("() => window.app.ready")
    projects = server.api("GET", "/api/projects")
    assert [p["name"] for p in projects] == [p["name"] for p in before] + [path.stem]
    assert projects[before.index(sample)] == sample
    assert page.evaluate("() => location.hash") == f"#p={projects[-1]['id']}"
    assert page.input_value("#project-select") == projects[-1]["id"]
    assert "new project" in page.inner_text("#landmarks-note")
