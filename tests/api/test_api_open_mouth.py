"""Joined lips through the web API, on the built-in face with its lips welded
(`retarget.testing.welded`): the project says its lips are joined, opening the mouth makes
a new mesh revision (originals first, the cut's duplicates appended, landmarks carried,
the rig dropped) whose lips are separate, and revert brings the welded mesh back."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from fastapi.testclient import TestClient

from retarget.landmarks import landmarks_from_json
from retarget.mesh import load_mesh, mesh_from_arrays, save_mesh
from retarget.sample_face import sample_face
from retarget.testing.welded import copies_of, welded_lips_face
from server.app import create_app
from tests.waits import wait_job


def _obj(tmp_path, face) -> bytes:
    path = tmp_path / "face.obj"
    save_mesh(mesh_from_arrays(face.vertices, face.faces, uv=getattr(face, "uv", None)), path)
    return path.read_bytes()


def _arrays(client, pid) -> tuple[np.ndarray, np.ndarray]:
    data = client.get(f"/api/projects/{pid}/mesh/arrays").content
    _, _, v, f = struct.unpack_from("<4sIII", data)
    return (np.frombuffer(data, "<f4", 3 * v, 16).reshape(v, 3),
            np.frombuffer(data, "<u4", 3 * f, 16 + 12 * v).reshape(f, 3))


@pytest.fixture
def client(tmp_path):
    with TestClient(create_app(tmp_path / "data", sample=False)) as c:
        yield c


def _project(client, tmp_path, face, layout="ibug68") -> str:
    pid = client.post("/api/projects", json={"name": "closed lips"}).json()["id"]
    r = client.put(f"/api/projects/{pid}/mesh", files={"file": ("head.obj", _obj(tmp_path, face))})
    assert r.status_code == 200, r.text
    r = client.put(f"/api/projects/{pid}/landmarks",
                   json={"vertex_indices": face.landmarks68.tolist(), "layout": layout})
    assert r.status_code == 200, r.text
    return pid


def test_welded_lips_open_into_a_new_revision_and_revert(client, tmp_path):
    face = welded_lips_face(1)
    pid = _project(client, tmp_path, face)
    lips = client.get(f"/api/projects/{pid}/mesh/lips").json()
    assert lips == {"joined": True,
                    "detail": "The lips are joined in one surface: the mouth cannot open."}
    r = client.post(f"/api/projects/{pid}/rig", json={"method": "ellipsoid"})
    assert r.status_code == 202
    assert wait_job(client, r.json()["id"])["state"] == "done"
    before = client.get(f"/api/projects/{pid}").json()
    assert before["rig"] and before["previous_mesh"] is None
    v0, f0 = _arrays(client, pid)

    r = client.post(f"/api/projects/{pid}/mesh/open-mouth")
    assert r.status_code == 200, r.text
    project = r.json()
    v, k = len(face.vertices), len(face.welded)
    assert project["mesh"]["n_vertices"] == v + k and project["mesh"]["n_faces"] == len(face.faces)
    assert project["rig"] is None and project["revision"] == before["revision"] + 1
    assert project["landmarks"] == {"layout": "ibug68", "n_points": 68}
    assert project["previous_mesh"] == {"n_vertices": v, "n_faces": len(face.faces)}
    # the originals first and unchanged, the duplicates copies of the welded line, uv kept
    v1, f1 = _arrays(client, pid)
    np.testing.assert_array_equal(v1[:v], v0)
    nearest, apart = copies_of(v1[v:], v0[face.welded])   # each a hair below its original
    assert sorted(nearest) == list(range(k)) and (apart > 0).all() and (apart < 0.02).all()
    stored = load_mesh(client.get(f"/api/projects/{pid}/mesh").content, "glb")
    np.testing.assert_allclose(stored.uv[:v], face.uv, atol=1e-6)
    assert stored.n_vertices == v + k
    # the landmarks are at the same spots, and the lips now separate
    points = landmarks_from_json(client.get(f"/api/projects/{pid}/landmarks").json(),
                                 stored.vertices, stored.faces)
    np.testing.assert_allclose(points.positions(stored.vertices), face.vertices[face.landmarks68], atol=1e-5)
    assert client.get(f"/api/projects/{pid}/mesh/lips").json()["joined"] is False
    again = client.post(f"/api/projects/{pid}/mesh/open-mouth")
    assert again.status_code == 422 and "already separate" in again.json()["detail"]

    # revert: the welded mesh and its landmarks again, as a new revision without a rig
    r = client.post(f"/api/projects/{pid}/mesh/revert")
    assert r.status_code == 200, r.text
    reverted = r.json()
    assert reverted["mesh"] == before["mesh"] and reverted["landmarks"] == before["landmarks"]
    assert reverted["previous_mesh"] is None and reverted["rig"] is None
    assert reverted["revision"] == project["revision"] + 1
    v2, f2 = _arrays(client, pid)
    np.testing.assert_array_equal(v2, v0)
    np.testing.assert_array_equal(f2, f0)
    assert client.get(f"/api/projects/{pid}/landmarks").json()["vertex_indices"] == face.landmarks68.tolist()
    assert client.get(f"/api/projects/{pid}/mesh/lips").json()["joined"] is True
    nothing = client.post(f"/api/projects/{pid}/mesh/revert")
    assert nothing.status_code == 409 and "no earlier mesh" in nothing.json()["detail"]


def test_separate_lips_and_missing_landmarks(client, tmp_path):
    face = sample_face(1)
    pid = _project(client, tmp_path, face)
    assert client.get(f"/api/projects/{pid}/mesh/lips").json() == {
        "joined": False, "detail": "The lips are separate: the mouth opens."}
    r = client.post(f"/api/projects/{pid}/mesh/open-mouth")
    assert r.status_code == 422 and "already separate" in r.json()["detail"]
    assert client.get(f"/api/projects/{pid}").json()["mesh"]["n_vertices"] == len(face.vertices)

    bare = client.post("/api/projects", json={"name": "no landmarks"}).json()["id"]
    client.put(f"/api/projects/{bare}/mesh", files={"file": ("head.obj", _obj(tmp_path, face))})
    for method, path in (("GET", "lips"), ("POST", "open-mouth")):
        r = client.request(method, f"/api/projects/{bare}/mesh/{path}")
        assert r.status_code == 409 and "no landmarks yet" in r.json()["detail"]


def test_a_new_upload_forgets_the_earlier_mesh(client, tmp_path):
    face = welded_lips_face(1)
    pid = _project(client, tmp_path, face)
    assert client.post(f"/api/projects/{pid}/mesh/open-mouth").status_code == 200
    client.put(f"/api/projects/{pid}/mesh", files={"file": ("other.obj", _obj(tmp_path, face))})
    assert client.get(f"/api/projects/{pid}").json()["previous_mesh"] is None
    assert client.post(f"/api/projects/{pid}/mesh/revert").status_code == 409
