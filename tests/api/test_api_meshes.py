"""Mesh upload and download through the web API: byte-identical round trips, the binary
arrays form, and refused uploads that leave every stored mesh as it was."""

from __future__ import annotations

import os
import struct
from functools import lru_cache

import numpy as np
import pytest
from fastapi.testclient import TestClient

from retarget.mesh import load_mesh, mesh_from_arrays, save_mesh
from retarget.sample_face import sample_face
from server.app import create_app

MAX_VERTICES = 10_000
MAX_BYTES = 1_500_000


@lru_cache(maxsize=1)
def _face():
    return sample_face(1)


def _saved(tmp_path, name, vertices, faces) -> bytes:
    path = tmp_path / name
    save_mesh(mesh_from_arrays(vertices, faces), path)
    data = path.read_bytes()
    path.unlink()
    return data


def face_obj(tmp_path) -> bytes:
    return _saved(tmp_path, "face.obj", _face().vertices, _face().faces)


def octahedron():
    v = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    f = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4],
                  [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    return v * [1.0, 2.0, 3.0] + 0.25, f


def decode_arrays(data: bytes):
    magic, version, v, f = struct.unpack_from("<4sIII", data)
    assert (magic, version) == (b"RTMA", 1)
    assert len(data) == 16 + 12 * v + 12 * f
    vertices = np.frombuffer(data, "<f4", 3 * v, 16).reshape(v, 3)
    faces = np.frombuffer(data, "<u4", 3 * f, 16 + 12 * v).reshape(f, 3)
    return vertices, faces


@pytest.fixture
def client(tmp_path):
    return TestClient(create_app(tmp_path / "data", sample=False,
                                 max_vertices=MAX_VERTICES, max_upload_bytes=MAX_BYTES))


def new_project(client, name="p") -> str:
    return client.post("/api/projects", json={"name": name}).json()["id"]


def upload(client, pid, name, data):
    return client.put(f"/api/projects/{pid}/mesh", files={"file": (name, data)})


def test_obj_upload_round_trips_byte_identical(client, tmp_path):
    pid = new_project(client)
    data = face_obj(tmp_path)
    r = upload(client, pid, "My Face.OBJ", data)
    assert r.status_code == 200, r.text
    face = _face()
    assert r.json()["mesh"] == {"filename": "My Face.OBJ", "format": "obj",
                                "n_vertices": len(face.vertices), "n_faces": len(face.faces)}
    got = client.get(f"/api/projects/{pid}/mesh")
    assert got.status_code == 200 and got.content == data
    assert got.headers["content-type"].startswith("model/obj")
    vertices, faces = decode_arrays(client.get(f"/api/projects/{pid}/mesh/arrays").content)
    np.testing.assert_allclose(vertices, face.vertices, atol=1e-5)
    np.testing.assert_array_equal(faces, face.faces)


@pytest.mark.parametrize("ext,media", [("ply", "application/octet-stream"),
                                       ("glb", "model/gltf-binary"), ("stl", "model/stl"),
                                       ("off", "application/octet-stream")])
def test_other_formats_round_trip(client, tmp_path, ext, media):
    pid = new_project(client)
    v, f = octahedron()
    data = _saved(tmp_path, f"o.{ext}", v, f)
    r = upload(client, pid, f"octa.{ext}", data)
    assert r.status_code == 200, r.text
    got = client.get(f"/api/projects/{pid}/mesh")
    assert got.content == data and got.headers["content-type"].startswith(media)
    vertices, faces = decode_arrays(client.get(f"/api/projects/{pid}/mesh/arrays").content)
    expected = load_mesh(data, ext)  # the library's reading is the reference
    assert r.json()["mesh"]["n_vertices"] == expected.n_vertices == len(vertices)
    np.testing.assert_array_equal(vertices, expected.vertices.astype(np.float32))
    np.testing.assert_array_equal(faces, expected.faces)
    np.testing.assert_allclose(np.sort(np.unique(vertices, axis=0), axis=0),
                               np.sort(v, axis=0), atol=1e-6)


def _nan_obj():
    return b"v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n"


def _over_cap(tmp_path):
    rng = np.random.default_rng(0)
    n = MAX_VERTICES + 3
    return _saved(tmp_path, "big.ply", rng.normal(size=(n, 3)), np.arange(n - n % 3).reshape(-1, 3))


BAD_UPLOADS = {
    "not a mesh": ("x.obj", lambda t: np.random.default_rng(1).bytes(4000), 422,
                   "uploaded mesh 'x.obj' refused"),
    "empty": ("e.obj", lambda t: b"", 422, "the uploaded file 'e.obj' is empty"),
    "nan": ("n.obj", lambda t: _nan_obj(), 422, "NaN"),
    "vertex cap": ("big.ply", _over_cap, 422, f"max_vertices={MAX_VERTICES}"),
    "byte cap": ("huge.obj", lambda t: b"#" * (MAX_BYTES + 1), 413,
                 f"over the limit of {MAX_BYTES} bytes"),
    "extension": ("face.exe", lambda t: b"v 0 0 0\n", 415, "'.exe'"),
    "no extension": ("face", lambda t: b"v 0 0 0\n", 415, "no extension"),
}


@pytest.mark.parametrize("case", BAD_UPLOADS)
def test_bad_uploads_are_refused_and_change_nothing(client, tmp_path, case):
    name, make, code, detail = BAD_UPLOADS[case]
    other = new_project(client, "other")
    v, f = octahedron()
    other_data = _saved(tmp_path, "o.ply", v, f)
    assert upload(client, other, "o.ply", other_data).status_code == 200
    pid = new_project(client)
    previous = face_obj(tmp_path)
    assert upload(client, pid, "face.obj", previous).status_code == 200
    r = client.put(f"/api/projects/{pid}/landmarks", json={"vertex_indices": [0, 5, 9]})
    assert r.status_code == 200
    before = {p: client.get(f"/api/projects/{p}").json() for p in (pid, other)}
    folder = sorted(os.listdir(tmp_path / "data" / "projects" / pid))

    r = upload(client, pid, name, make(tmp_path))
    assert r.status_code == code, r.text
    assert detail in r.json()["detail"]

    for p in (pid, other):
        assert client.get(f"/api/projects/{p}").json() == before[p]
    assert client.get(f"/api/projects/{pid}/mesh").content == previous
    assert client.get(f"/api/projects/{other}/mesh").content == other_data
    assert client.get(f"/api/projects/{pid}/landmarks").json() == {"vertex_indices": [0, 5, 9]}
    assert sorted(os.listdir(tmp_path / "data" / "projects" / pid)) == folder


def test_nan_detail_is_precise(client):
    pid = new_project(client)
    detail = upload(client, pid, "n.obj", _nan_obj()).json()["detail"]
    assert detail.startswith("uploaded mesh 'n.obj' refused: ")
    assert "the given bytes" not in detail


def test_traversal_file_name_is_stored_under_a_safe_name(client, tmp_path):
    pid = new_project(client)
    data = face_obj(tmp_path)
    r = upload(client, pid, "../../evil.obj", data)
    assert r.status_code == 200, r.text
    assert r.json()["mesh"]["filename"] == "../../evil.obj"  # display only
    assert sorted(os.listdir(tmp_path / "data" / "projects" / pid)) == ["mesh-r1.obj"]
    assert not list(tmp_path.rglob("*evil*"))
    assert client.get(f"/api/projects/{pid}/mesh").content == data


def test_new_mesh_replaces_the_old_file_and_drops_landmarks(client, tmp_path):
    pid = new_project(client)
    assert upload(client, pid, "a.obj", face_obj(tmp_path)).status_code == 200
    client.put(f"/api/projects/{pid}/landmarks", json={"vertex_indices": [0, 1, 2]})
    v, f = octahedron()
    ply = _saved(tmp_path, "o.ply", v, f)
    project = upload(client, pid, "b.ply", ply).json()
    assert project["mesh"]["format"] == "ply" and project["landmarks"] is None
    assert sorted(os.listdir(tmp_path / "data" / "projects" / pid)) == ["mesh-r3.ply"]
    assert client.get(f"/api/projects/{pid}/mesh").content == ply
    assert client.get(f"/api/projects/{pid}/landmarks").status_code == 404


def test_the_store_parses_a_mesh_once_and_a_new_one_anew(client, tmp_path):
    store = client.app.state.store
    pid = new_project(client)
    upload(client, pid, "a.obj", face_obj(tmp_path))
    assert store.mesh(pid) is store.mesh(pid)
    v, f = octahedron()
    upload(client, pid, "b.ply", _saved(tmp_path, "o.ply", v, f))
    vertices, _ = decode_arrays(client.get(f"/api/projects/{pid}/mesh/arrays").content)
    np.testing.assert_allclose(vertices, v.astype(np.float32))


def test_mesh_routes_without_a_mesh(client):
    pid = new_project(client)
    r = client.get(f"/api/projects/{pid}/mesh")
    assert r.status_code == 404 and "has no mesh yet" in r.json()["detail"]
    r = client.get(f"/api/projects/{pid}/mesh/arrays")
    assert r.status_code == 409 and "upload one" in r.json()["detail"]


def test_upload_needs_a_file_field(client):
    pid = new_project(client)
    assert client.put(f"/api/projects/{pid}/mesh").status_code == 422
