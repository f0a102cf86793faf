"""Zero-click landmarks on the server (``POST .../landmarks/find``): a job finds the layout's
points on the project's mesh in a child process and stores them with their confidence,
unless that would overwrite the user's work; a mesh with no face fails the job with the
library's reason and the project keeps its landmarks.

The face is the project's sample face (`retarget.sample_face.sample_face`, cm), whose 68
landmark vertices are the truth, reached through each layout's ``ibug68`` column.
"""

from __future__ import annotations

import threading

import numpy as np
import pytest
import trimesh

from retarget.facemesh.placement import CHECK_BELOW
from retarget.landmarks import landmarks_from_json
from retarget.layouts import get_layout
from retarget.mesh import mesh_from_arrays, save_mesh
from retarget.sample_face import sample_face
from server.jobs import JobBusy, JobRegistry
from server.wire import weights_from_binary
from tests.waits import wait_job


@pytest.fixture(scope="module")
def face():
    return sample_face(1)


def _obj(folder, vertices, faces) -> bytes:
    path = folder / "mesh.obj"
    save_mesh(mesh_from_arrays(vertices, faces), path)
    return path.read_bytes()


@pytest.fixture(scope="module")
def face_obj(face, tmp_path_factory) -> bytes:
    return _obj(tmp_path_factory.mktemp("face"), face.vertices, face.faces)


@pytest.fixture(scope="module")
def sphere_obj(tmp_path_factory) -> bytes:
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=8.0)
    return _obj(tmp_path_factory.mktemp("sphere"), sphere.vertices, sphere.faces)


def _project(client, name: str, mesh: bytes) -> str:
    pid = client.post("/api/projects", json={"name": name}).json()["id"]
    r = client.put(f"/api/projects/{pid}/mesh", files={"file": (f"{name}.obj", mesh)})
    assert r.status_code == 200, r.text
    return pid


def _find(client, pid: str, **body) -> dict:
    r = client.post(f"/api/projects/{pid}/landmarks/find", json=body)
    assert r.status_code == 202, r.text
    assert r.json()["kind"] == "landmarks" and r.json()["state"] == "running"
    return r.json()


def _errors(stored: dict, face, layout_name: str) -> np.ndarray:
    """(N,) cm from each stored point to its true position on the sample face."""
    layout = get_layout(layout_name)
    placed = landmarks_from_json(stored, face.vertices, face.faces).positions(face.vertices)
    truth = face.vertices[face.landmarks68[np.asarray(layout.ibug68)]]
    return np.linalg.norm(placed - truth, axis=1)


@pytest.mark.parametrize("layout", [None, "ibug68"])
def test_points_found_on_the_sample_face_are_stored_with_their_confidence(client, face, face_obj, layout):
    pid = _project(client, f"found {layout}", face_obj)
    polled = []
    job = wait_job(client, _find(client, pid, **({} if layout is None else {"layout": layout}))["id"],
                   timeout_s=120, progress=polled)
    assert job["state"] == "done", job["detail"]
    assert polled == sorted(polled) and polled[-1] == 1.0
    name = layout or "dutreve22"  # a project without landmarks: the page's default layout
    result = job["result"]
    assert result["saved"] and result["reason"] is None
    assert result["layout"] == name and result["n_points"] == get_layout(name).n_points

    project = client.get(f"/api/projects/{pid}").json()
    assert project["landmarks"] == {"layout": name, "n_points": get_layout(name).n_points}
    stored = client.get(f"/api/projects/{pid}/landmarks").json()
    assert stored["layout"] == name and stored["check_below"] == CHECK_BELOW
    confidence = np.array(stored["confidence"])
    assert confidence.shape == (get_layout(name).n_points,) and np.all((0 <= confidence) & (confidence <= 1))
    flagged = confidence < CHECK_BELOW
    assert result["check"] == [p for p, f in zip(get_layout(name).point_names, flagged) if f]

    # the eyes, nose and lips lie within a few mm of the truth and are mostly trusted; the jaw
    # and the outer brows are flagged. The sample face has no brow in its geometry, so its
    # "true" brow points are a convention the detector cannot see (13 mm off, as in
    # tests/unit/test_facemesh_placement.py) and are not judged here
    error = _errors(stored, face, name)
    regions = np.array(get_layout(name).regions)
    features = np.isin(regions, ["eyes", "nose", "mouth_corners", "upper_lip", "lower_lip"])
    assert error[features].max() < 0.6 and error[features].mean() < 0.35, error[features]
    assert (~flagged[features]).mean() > 0.8, flagged[features]
    assert flagged[regions == "jaw"].any() and flagged[regions == "brows"].any()

    # a rig is computed from them as from points placed by hand
    rig = client.post(f"/api/projects/{pid}/rig", json={"method": "ellipsoid"})
    assert wait_job(client, rig.json()["id"], timeout_s=120)["state"] == "done"


def test_an_stl_scan_is_found_and_rigged_as_one_surface(client, face, tmp_path):
    # An STL stores each triangle's own three corners. Found and rigged on that soup, the
    # rig gave 99.9 % of the corners no weight (each triangle a surface of its own): the
    # face did not move. Now the corners at one position share their weights.
    path = tmp_path / "scan.stl"
    trimesh.Trimesh(face.vertices, face.faces, process=False).export(path)
    pid = client.post("/api/projects", json={"name": "stl"}).json()["id"]
    r = client.put(f"/api/projects/{pid}/mesh", files={"file": ("scan.stl", path.read_bytes())})
    assert r.status_code == 200, r.text
    assert r.json()["mesh"]["n_vertices"] == 3 * len(face.faces)
    job = wait_job(client, _find(client, pid, layout="ibug68")["id"], timeout_s=120)
    assert job["state"] == "done", job["detail"]
    rig = client.post(f"/api/projects/{pid}/rig", json={"method": "biharmonic"})
    assert wait_job(client, rig.json()["id"], timeout_s=120)["state"] == "done"
    weights = weights_from_binary(client.get(f"/api/projects/{pid}/rig/weights").content).dense()
    # the soup's corners are the indexed face's vertices, three per triangle
    corners = np.asarray(face.faces).ravel()
    at_vertex = np.zeros((len(face.vertices), weights.shape[1]))
    at_vertex[corners] = weights
    np.testing.assert_allclose(weights, at_vertex[corners], atol=1e-6)
    # and the face moves: its weights reach as far as those of the indexed face
    assert np.median(weights.sum(1)) > 0.1


def test_a_mesh_with_no_face_fails_the_job_and_keeps_the_landmarks(client, sphere_obj):
    pid = _project(client, "sphere", sphere_obj)
    placed = {"vertex_indices": list(range(0, 22 * 7, 7)), "layout": "dutreve22"}
    assert client.put(f"/api/projects/{pid}/landmarks", json=placed).status_code == 200
    before = client.get(f"/api/projects/{pid}").json()

    # landmarks placed by hand are not replaced unless asked
    r = client.post(f"/api/projects/{pid}/landmarks/find", json={})
    assert r.status_code == 409 and "placed by hand" in r.json()["detail"], r.text

    job = wait_job(client, _find(client, pid, replace=True)["id"], timeout_s=120)
    assert job["state"] == "failed" and job["result"] is None
    assert job["detail"].startswith("no face found on the mesh"), job["detail"]
    assert "place the points by hand" in job["detail"]
    assert client.get(f"/api/projects/{pid}").json() == before
    assert client.get(f"/api/projects/{pid}/landmarks").json() == placed


def test_unsaved_points_placed_by_hand_are_never_overwritten(client, face, face_obj):
    pid = _project(client, "drafted", face_obj)
    revision = client.get(f"/api/projects/{pid}").json()["revision"]
    draft = {"revision": revision, "layout": "dutreve22", "points": [[5, 6, 7, 1, 0, 0]] + [None] * 21}
    client.patch(f"/api/projects/{pid}", json={"settings": {"draft": draft}})

    job = wait_job(client, _find(client, pid)["id"], timeout_s=120)
    assert job["state"] == "done", job["detail"]
    assert not job["result"]["saved"] and "placed by hand" in job["result"]["reason"]
    assert "not saved" in job["detail"]
    project = client.get(f"/api/projects/{pid}").json()
    assert project["landmarks"] is None and project["settings"]["draft"] == draft

    # asked to replace them, it does; a draft of an older mesh revision is no one's work
    job = wait_job(client, _find(client, pid, replace=True)["id"], timeout_s=120)
    assert job["result"]["saved"], job
    assert client.get(f"/api/projects/{pid}").json()["landmarks"]["n_points"] == 22


def test_found_points_go_only_to_the_mesh_and_landmarks_they_were_found_for(app, client, face_obj):
    pid = _project(client, "stale", face_obj)
    store = app.state.store
    revision = store.get(pid)["revision"]
    found = {"vertex_indices": list(range(22)), "layout": "dutreve22", "confidence": [1.0] * 22}
    mine = {"vertex_indices": list(range(100, 122)), "layout": "dutreve22"}
    assert client.put(f"/api/projects/{pid}/landmarks", json=mine).status_code == 200
    why = store.put_found_landmarks(pid, found, n_points=22, layout="dutreve22", revision=revision,
                                    replace=True)
    assert "changed while the points were being found" in why
    assert client.get(f"/api/projects/{pid}/landmarks").json() == mine


def test_finding_runs_beside_a_rig_but_once_at_a_time(client, face_obj):
    pid = _project(client, "busy", face_obj)
    first = _find(client, pid)
    again = client.post(f"/api/projects/{pid}/landmarks/find", json={})
    assert again.status_code == 409 and "running landmarks job" in again.json()["detail"]
    assert wait_job(client, first["id"], timeout_s=120)["state"] == "done"

    # the registry's rule: a job that is not exclusive leaves the project free for the others
    jobs, release = JobRegistry(), threading.Event()
    jobs.start("p", "landmarks", lambda job: release.wait(5) and ("ok", None), exclusive=False)
    rig = jobs.start("p", "rig", lambda job: release.wait(5) and ("ok", None))
    with pytest.raises(JobBusy, match="already has a running landmarks job"):
        jobs.start("p", "landmarks", lambda job: ("ok", None), exclusive=False)
    with pytest.raises(JobBusy, match="already has a running job"):
        jobs.start("p", "track", lambda job: ("ok", None))
    release.set()
    jobs.wait(rig.id, 5)


def test_an_unknown_layout_is_refused(client, face_obj):
    pid = _project(client, "unknown", face_obj)
    r = client.post(f"/api/projects/{pid}/landmarks/find", json={"layout": "ibug69"})
    assert r.status_code == 422 and "unknown layout 'ibug69'" in r.json()["detail"]
