"""The product's main path in a real browser against a real server: upload a mesh the
test generates, click its 68 landmarks where they appear on screen, rig it, start the
demo performance and see the face move; restart the server and find it all again."""

from __future__ import annotations

import io
import json
import urllib.request

import numpy as np
import pytest
from PIL import Image

from retarget.landmarks import landmarks_from_json
from retarget.mesh import mesh_from_arrays, save_mesh
from retarget.sample_face import sample_face

_IDENTITY = np.array([-0.8, 0.6, -0.5, 0.4, 0.9])  # not the sample project's face


@pytest.fixture(scope="module")
def face_file(tmp_path_factory):
    """An OBJ of a generated face (cm) and its 68 landmark vertex indices."""
    face = sample_face(1, identity=_IDENTITY)
    path = tmp_path_factory.mktemp("meshes") / "my_face.obj"
    save_mesh(mesh_from_arrays(face.vertices, face.faces), path)
    return path, face


def api(server, method: str, path: str, body: dict | None = None):
    data = None if body is None else json.dumps(body).encode()
    request = urllib.request.Request(server.url + path, data=data, method=method,
                                     headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(request, timeout=30) as reply:
        return json.loads(reply.read() or b"null")


def open_project(page, server, project_id: str) -> None:
    page.goto(f"{server.url}/#p={project_id}")
    page.wait_for_function("() => window.app && window.app.projectId !== undefined")
    page.evaluate("() => window.app.ready")


def face_clip(page, points: np.ndarray) -> dict:
    """The screen rectangle around `points` (world), CSS pixels."""
    xy = np.array([list(page.evaluate("p => window.app.viewer.project(p)", p.tolist()).values())
                   for p in points])
    lo, hi = xy.min(0), xy.max(0)
    return {"x": float(lo[0]), "y": float(lo[1]), "width": float(hi[0] - lo[0]),
            "height": float(hi[1] - lo[1])}


def pixels(page, clip: dict) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(page.screenshot(clip=clip))).convert("RGB"), np.float32)


def test_upload_click_rig_and_watch_it_move_then_restart(server, page, face_file):
    path, face = face_file
    project = api(server, "POST", "/api/projects", {"name": "e2e face"})
    open_project(page, server, project["id"])

    # upload through the file picker; the mesh appears with the uploaded vertex count
    page.set_input_files("#file-input", str(path))
    page.wait_for_function("n => window.app.face && window.app.face.mesh.geometry"
                           ".attributes.position.count === n", arg=len(face.vertices), timeout=30_000)
    assert page.inner_text("#error").strip() == ""

    # click every landmark at its projected position, in layout order
    page.select_option("#layout-select", "ibug68")
    targets = face.vertices[face.landmarks68]
    for i, point in enumerate(targets):
        xy = page.evaluate("p => window.app.viewer.project(p)", point.tolist())
        page.mouse.click(xy["x"], xy["y"])
    page.click("#save-landmarks")
    page.wait_for_function("id => fetch(`/api/projects/${id}`).then(r => r.json())"
                           ".then(p => p.landmarks && p.landmarks.n_points === 68)", arg=project["id"])
    stored = api(server, "GET", f"/api/projects/{project['id']}/landmarks")
    placed = landmarks_from_json(stored, face.vertices, face.faces).positions(face.vertices)
    error = np.linalg.norm(placed - targets, axis=1)
    # a click lands within a few pixels: about 0.03 cm per pixel at this zoom
    assert error.max() < 0.15, f"landmark click error up to {error.max():.3f} cm"

    # rig with the default deformer; the progress bar finishes and the rig arrives
    page.click("#rig-button")
    page.wait_for_function("id => fetch(`/api/projects/${id}`).then(r => r.json())"
                           ".then(p => p.rig !== null)", arg=project["id"], timeout=60_000)
    page.wait_for_function("() => { const p = document.querySelector('#rig-progress');"
                           " return p.value >= p.max; }")

    # the demo performance moves the face: frames arrive and the face's pixels change
    page.click("#start-demo")
    page.wait_for_function("() => window.app.stream && window.app.stream.stats.frames > 30",
                           timeout=30_000)
    clip = face_clip(page, targets)
    shots = []
    for _ in range(4):
        shots.append(pixels(page, clip))
        page.wait_for_timeout(400)
    changes = [np.abs(a - b).mean() for a, b in zip(shots, shots[1:])]
    assert min(changes) > 0.5, f"face pixels barely change between frames: {changes}"
    stats = page.evaluate("() => window.app.stream.stats")
    assert stats["fps"] > 10 and stats["latencyMs"]["median"] < 1000
    assert page.inner_text("#fps").strip() != ""

    # a restart loses nothing: the project, its landmarks and its rig come back
    page.click("#stop-demo")
    server.restart()
    open_project(page, server, project["id"])
    again = api(server, "GET", f"/api/projects/{project['id']}")
    assert again["mesh"]["n_vertices"] == len(face.vertices)
    assert again["landmarks"]["n_points"] == 68 and again["rig"] is not None
    assert api(server, "GET", f"/api/projects/{project['id']}/landmarks") == stored
    page.wait_for_function("n => window.app.face && window.app.face.mesh.geometry"
                           ".attributes.position.count === n", arg=len(face.vertices))
