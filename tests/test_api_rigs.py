"""Landmarks and rigs through the web API: validation against the stored mesh and the
layout, the background rig job, and the binary weights form."""

from __future__ import annotations

import struct
import threading
import time
from functools import lru_cache

import numpy as np
import pytest
from fastapi.testclient import TestClient

from retarget.landmarks import from_vertex_indices
from retarget.layouts import get_layout
from retarget.mesh import load_mesh, mesh_from_arrays, save_mesh
from retarget.sample_face import sample_face
from retarget.weights import compute_weights
from server.app import create_app
from server.jobs import JobBusy, JobRegistry


@lru_cache(maxsize=1)
def _face():
    return sample_face(1)


def decode_weights(data: bytes):
    magic, version, v, k, n = struct.unpack_from("<4sIIII", data)
    assert (magic, version) == (b"RTSW", 1)
    idx = np.frombuffer(data, "<u2", v * k, 20).reshape(v, k)
    start = 20 + 2 * v * k + (-(2 * v * k) % 4)
    assert start % 4 == 0 and start + 4 * v * k == len(data)
    return idx, np.frombuffer(data, "<f4", v * k, start).reshape(v, k), n


@pytest.fixture
def client(tmp_path):
    return TestClient(create_app(tmp_path / "data", sample=False))


@pytest.fixture
def face_project(client, tmp_path):
    """(project id, OBJ bytes) of a project holding the sample face."""
    path = tmp_path / "face.obj"
    save_mesh(mesh_from_arrays(_face().vertices, _face().faces), path)
    pid = client.post("/api/projects", json={"name": "face"}).json()["id"]
    r = client.put(f"/api/projects/{pid}/mesh", files={"file": ("face.obj", path.read_bytes())})
    assert r.status_code == 200
    return pid, path.read_bytes()


def ibug_json():
    return {"vertex_indices": _face().landmarks68.tolist(), "layout": "ibug68"}


def run_job(client, job_id, timeout=30.0):
    seen, deadline = [], time.monotonic() + timeout
    while True:
        state = client.get(f"/api/jobs/{job_id}").json()
        seen.append(state["progress"])
        if state["state"] != "running":
            return state, seen
        assert time.monotonic() < deadline, state
        time.sleep(0.01)


def test_landmarks_round_trip(client, face_project):
    pid, _ = face_project
    r = client.put(f"/api/projects/{pid}/landmarks", json=ibug_json())
    assert r.status_code == 200, r.text
    assert r.json() == ibug_json()
    assert client.get(f"/api/projects/{pid}/landmarks").json() == ibug_json()
    assert client.get(f"/api/projects/{pid}").json()["landmarks"] == {"layout": "ibug68",
                                                                      "n_points": 68}


def test_positions_are_snapped_to_the_surface(client, face_project):
    pid, _ = face_project
    face = _face()
    target = face.vertices[face.landmarks68[:5]] + [0.0, 0.0, 0.01]
    r = client.put(f"/api/projects/{pid}/landmarks", json={"positions": target.tolist()})
    assert r.status_code == 200, r.text
    stored = client.get(f"/api/projects/{pid}/landmarks").json()
    tri, bary = np.array(stored["triangles"]), np.array(stored["barycentric"])
    on_surface = np.einsum("kjd,kj->kd", face.vertices[tri], bary)
    np.testing.assert_allclose(on_surface, face.vertices[face.landmarks68[:5]], atol=0.02)


@pytest.mark.parametrize("body,detail", [
    ({"vertex_indices": list(range(10)), "layout": "ibug68"},
     "layout 'ibug68' has 68 points but 10 landmarks were given"),
    ({"vertex_indices": [0, 1, 99999]}, "vertex_indices[2] = 99999 is not a vertex"),
    ({"vertex_indices": [0, -1]}, "vertex_indices[1] = -1"),
    ({"vertex_indices": [0, 1], "layout": "nope"}, "unknown layout 'nope'"),
    ({"vertex_indices": [3, 3]}, "repeats vertex 3"),
    ({"vertex_indices": [0.5, 1]}, "non-empty list of integers"),
    ({"positions": [["a", "b", "c"]]}, "landmarks JSON is malformed"),
    ({"positions": [[0, 0]]}, "positions must have shape (K, 3)"),
    ({"layout": 5, "vertex_indices": [1]}, "'layout' must be a layout name"),
    ({"points": [1, 2]}, "needs 'vertex_indices', 'positions' or 'triangles'"),
])
def test_bad_landmarks_are_422_and_keep_the_old_ones(client, face_project, body, detail):
    pid, _ = face_project
    assert client.put(f"/api/projects/{pid}/landmarks", json=ibug_json()).status_code == 200
    r = client.put(f"/api/projects/{pid}/landmarks", json=body)
    assert r.status_code == 422, r.text
    assert detail in r.json()["detail"]
    assert client.get(f"/api/projects/{pid}/landmarks").json() == ibug_json()


def test_landmarks_need_a_mesh(client):
    pid = client.post("/api/projects", json={"name": "empty"}).json()["id"]
    r = client.put(f"/api/projects/{pid}/landmarks", json={"vertex_indices": [0]})
    assert r.status_code == 409 and "has no mesh yet" in r.json()["detail"]
    r = client.get(f"/api/projects/{pid}/landmarks")
    assert r.status_code == 404 and "no landmarks" in r.json()["detail"]


def test_rig_job_runs_to_done_and_matches_the_library(client, face_project):
    pid, obj = face_project
    client.put(f"/api/projects/{pid}/landmarks", json=ibug_json())
    r = client.post(f"/api/projects/{pid}/rig", json={"method": "biharmonic"})
    assert r.status_code == 202, r.text
    job = r.json()
    assert job["project_id"] == pid and 0.0 <= job["progress"] <= 1.0
    state, seen = run_job(client, job["id"])
    assert state["state"] == "done", state
    assert state["progress"] == 1.0 and seen == sorted(seen)
    assert "68 joints" in state["detail"]
    face = _face()
    assert client.get(f"/api/projects/{pid}/rig").json() == {
        "method": "biharmonic", "n_vertices": len(face.vertices), "n_joints": 68,
        "n_influences": 68}
    assert client.get(f"/api/projects/{pid}").json()["rig"] == {"method": "biharmonic"}
    r = client.get(f"/api/projects/{pid}/rig/weights")
    assert r.headers["content-type"] == "application/octet-stream"
    idx, w, n = decode_weights(r.content)
    assert idx.shape == w.shape == (len(face.vertices), 68) and n == 68
    mesh = load_mesh(obj, "obj")
    points = from_vertex_indices(face.landmarks68, mesh.n_vertices, "ibug68")
    expected = compute_weights("biharmonic", mesh.vertices, mesh.faces, points,
                               get_layout("ibug68"))
    np.testing.assert_array_equal(idx, expected.indices)
    np.testing.assert_array_equal(w, expected.weights)


def test_rig_job_with_k_and_a_method_without_progress(client, face_project):
    pid, _ = face_project
    client.put(f"/api/projects/{pid}/landmarks", json=ibug_json())
    job = client.post(f"/api/projects/{pid}/rig", json={"method": "ellipsoid", "k": 3}).json()
    state, _ = run_job(client, job["id"])
    assert state["state"] == "done" and state["progress"] == 1.0
    idx, w, n = decode_weights(client.get(f"/api/projects/{pid}/rig/weights").content)
    assert idx.shape == (len(_face().vertices), 3) and n == 68
    assert int(idx.max()) < 68 and np.all(w >= 0)


def test_new_landmarks_drop_the_rig(client, face_project):
    pid, _ = face_project
    client.put(f"/api/projects/{pid}/landmarks", json=ibug_json())
    run_job(client, client.post(f"/api/projects/{pid}/rig", json={"method": "ellipsoid"}).json()["id"])
    assert client.get(f"/api/projects/{pid}/rig").status_code == 200
    client.put(f"/api/projects/{pid}/landmarks", json={"vertex_indices": [1, 2, 3]})
    r = client.get(f"/api/projects/{pid}/rig")
    assert r.status_code == 404 and "no rig yet" in r.json()["detail"]


@pytest.mark.parametrize("body,code,detail", [
    ({"method": "magic"}, 422, "unknown rig method 'magic'"),
    ({"method": "biharmonic", "k": 0}, 422, None),
])
def test_bad_rig_requests(client, face_project, body, code, detail):
    pid, _ = face_project
    client.put(f"/api/projects/{pid}/landmarks", json=ibug_json())
    r = client.post(f"/api/projects/{pid}/rig", json=body)
    assert r.status_code == code
    if detail:
        assert detail in r.json()["detail"]


def test_rig_needs_landmarks_and_unknown_jobs_are_404(client, face_project):
    pid, _ = face_project
    r = client.post(f"/api/projects/{pid}/rig", json={})
    assert r.status_code == 409 and "no landmarks yet" in r.json()["detail"]
    r = client.get("/api/jobs/nope")
    assert r.status_code == 404 and r.json()["detail"] == "no job with id 'nope'"


def test_one_running_job_per_project():
    jobs, release = JobRegistry(), threading.Event()
    first = jobs.start("p", "rig", lambda job: release.wait(5) and "ok")
    with pytest.raises(JobBusy, match="already has a running job"):
        jobs.start("p", "rig", lambda job: "never")
    other = jobs.start("q", "rig", lambda job: "fine")  # other projects are not blocked
    release.set()
    jobs.wait(first.id, 5)
    jobs.wait(other.id, 5)
    assert first.as_json()["state"] == "done" and other.as_json()["detail"] == "fine"
    again = jobs.start("p", "rig", lambda job: (_ for _ in ()).throw(ValueError("bad input")))
    jobs.wait(again.id, 5)
    assert again.as_json()["state"] == "failed" and again.as_json()["detail"] == "bad input"


def test_weights_binary_pads_odd_counts_to_align_the_floats():
    from retarget.skin import SkinWeights
    from server.routers.rigs import weights_binary
    rig = SkinWeights(np.array([[0], [2], [1]], np.int32), np.array([[1.0], [0.5], [0.25]], np.float32), 3)
    data = weights_binary(rig)
    assert len(data) == 20 + 6 + 2 + 12 and data[26:28] == b"\0\0"
    idx, w, n = decode_weights(data)
    np.testing.assert_array_equal(idx[:, 0], [0, 2, 1])
    np.testing.assert_array_equal(w[:, 0], [1.0, 0.5, 0.25])
