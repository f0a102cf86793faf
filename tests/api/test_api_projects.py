"""The web API's projects, the store under it, the sample project and restarts.

Everything runs in process with FastAPI's TestClient on a data dir in `tmp_path`.
"""

from __future__ import annotations

import json
import struct
import subprocess
import sys
from functools import lru_cache

import numpy as np
import pytest
from fastapi.testclient import TestClient

from retarget.mesh import load_mesh, mesh_from_arrays, save_mesh
from retarget.sample_face import sample_face
from server.app import create_app
from server.deps import get_store
from server.store import ProjectNotFound, ProjectStore, StaleRig
from tests.waits import wait_job


@lru_cache(maxsize=1)
def _face():
    return sample_face(1)


def face_obj(tmp_path) -> bytes:
    face = _face()
    path = tmp_path / "face_upload.obj"
    save_mesh(mesh_from_arrays(face.vertices, face.faces), path)
    return path.read_bytes()


def rigged_project(client: TestClient, tmp_path) -> str:
    """A project with the sample face as mesh, its 68 landmarks and a finished rig."""
    pid = client.post("/api/projects", json={"name": "rigged"}).json()["id"]
    r = client.put(f"/api/projects/{pid}/mesh",
                   files={"file": ("face.obj", face_obj(tmp_path), "model/obj")})
    assert r.status_code == 200, r.text
    r = client.put(f"/api/projects/{pid}/landmarks",
                   json={"vertex_indices": _face().landmarks68.tolist(), "layout": "ibug68"})
    assert r.status_code == 200, r.text
    job = client.post(f"/api/projects/{pid}/rig", json={"method": "biharmonic"}).json()
    state = wait_job(client, job["id"])
    assert state["state"] == "done", state
    return pid


def decode_weights(data: bytes):
    magic, version, v, k, n = struct.unpack_from("<4sIIII", data)
    assert (magic, version) == (b"RTSW", 1)
    idx = np.frombuffer(data, "<u2", v * k, 20).reshape(v, k)
    start = 20 + 2 * v * k + (-(2 * v * k) % 4)
    w = np.frombuffer(data, "<f4", v * k, start).reshape(v, k)
    assert start + 4 * v * k == len(data)
    return idx, w, n


@pytest.fixture
def client(tmp_path):
    return TestClient(create_app(tmp_path / "data", sample=False))


def test_create_list_get_patch_delete(client):
    assert client.get("/api/projects").json() == []
    r = client.post("/api/projects", json={"name": "  Alice  ", "settings": {"units": "cm"}})
    assert r.status_code == 201
    alice = r.json()
    assert alice["name"] == "Alice" and alice["settings"] == {"units": "cm"}
    assert alice["mesh"] is None and alice["landmarks"] is None and alice["rig"] is None
    assert len(alice["id"]) == 22
    bob = client.post("/api/projects", json={"name": "Bob"}).json()
    assert [p["id"] for p in client.get("/api/projects").json()] == [alice["id"], bob["id"]]
    assert client.get(f"/api/projects/{bob['id']}").json() == bob

    r = client.patch(f"/api/projects/{alice['id']}",
                     json={"name": "Alicia", "settings": {"fps": 30, "units": None}})
    assert r.status_code == 200
    assert r.json()["name"] == "Alicia" and r.json()["settings"] == {"fps": 30}
    assert r.json()["updated"] >= alice["updated"]
    assert client.get(f"/api/projects/{alice['id']}").json()["name"] == "Alicia"
    r = client.patch(f"/api/projects/{alice['id']}", json={"settings": {"units": "mm"}})
    assert r.status_code == 200
    assert r.json()["name"] == "Alicia" and r.json()["settings"] == {"fps": 30, "units": "mm"}
    assert client.patch(f"/api/projects/{alice['id']}", json={"name": " "}).status_code == 422
    assert client.patch(f"/api/projects/{alice['id']}", json={"settings": [1]}).status_code == 422

    assert client.delete(f"/api/projects/{alice['id']}").status_code == 204
    assert client.get(f"/api/projects/{alice['id']}").status_code == 404
    assert [p["id"] for p in client.get("/api/projects").json()] == [bob["id"]]


@pytest.mark.parametrize("body", [{}, {"name": ""}, {"name": "   "}, {"name": "x" * 201},
                                  {"name": "ok", "settings": [1]}])
def test_create_refuses_bad_bodies(client, body):
    r = client.post("/api/projects", json=body)
    assert r.status_code == 422
    assert client.get("/api/projects").json() == []


def test_delete_removes_the_folder_and_nothing_else(client, tmp_path):
    a = client.post("/api/projects", json={"name": "a"}).json()["id"]
    b = client.post("/api/projects", json={"name": "b"}).json()["id"]
    projects = tmp_path / "data" / "projects"
    assert (projects / a).is_dir() and (projects / b).is_dir()
    client.delete(f"/api/projects/{a}")
    assert not (projects / a).exists() and (projects / b).is_dir()
    assert client.delete(f"/api/projects/{a}").status_code == 404


@pytest.mark.parametrize("method,suffix", [
    ("GET", ""), ("PATCH", ""), ("DELETE", ""), ("GET", "/mesh"), ("GET", "/mesh/arrays"),
    ("GET", "/landmarks"), ("GET", "/rig"), ("GET", "/rig/weights")])
def test_unknown_project_is_404_naming_it(client, method, suffix):
    unknown = "A" * 22
    r = client.request(method, f"/api/projects/{unknown}{suffix}", json={"name": "x"})
    assert r.status_code == 404
    assert r.json()["detail"] == f"no project with id {unknown!r}"


@pytest.mark.parametrize("bad", ["..", "short", "A" * 23, "%2E%2E%2Fetc", "a.b" + "c" * 19,
                                 "..%2F..%2Fdata"])
def test_malformed_id_is_404_without_touching_the_filesystem(client, tmp_path, bad):
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    for method, suffix in (("GET", ""), ("DELETE", ""), ("GET", "/mesh")):
        r = client.request(method, f"/api/projects/{bad}{suffix}")
        assert r.status_code == 404
    r = client.put(f"/api/projects/{bad}/mesh", files={"file": ("m.obj", b"v 0 0 0\n")})
    assert r.status_code == 404
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before


@pytest.mark.parametrize("bad", ["../x", "../../" + "a" * 16, "a/b" + "c" * 19, "", None, "A" * 21 + "/"])
def test_store_refuses_malformed_ids_before_any_path(tmp_path, bad):
    store = ProjectStore(tmp_path)
    with pytest.raises(ProjectNotFound):
        store.folder(bad)
    with pytest.raises(ProjectNotFound):
        store.delete(bad)


def test_store_refuses_a_rig_for_changed_landmarks(tmp_path):
    from retarget.skin import SkinWeights
    store = ProjectStore(tmp_path)
    pid = store.create("p")["id"]
    rig = SkinWeights(np.zeros((3, 1), np.int32), np.ones((3, 1), np.float32), 1, "x")
    with pytest.raises(StaleRig):
        store.put_rig(pid, rig, revision=store.get(pid)["revision"] + 1)
    assert store.rig(pid) is None and not (tmp_path / "projects" / pid / "rig.npz").exists()
    store.put_rig(pid, rig, revision=store.get(pid)["revision"])
    assert store.rig(pid).method == "x"


def test_store_writes_leave_no_temporary_files(tmp_path):
    store = ProjectStore(tmp_path)
    pid = store.create("p")["id"]
    store.put_mesh(pid, b"v 0 0 0\n", "obj", filename="../x.obj", n_vertices=1, n_faces=0)
    store.put_landmarks(pid, {"vertex_indices": [0]}, n_points=1, layout="",
                        revision=store.get(pid)["revision"])
    names = sorted(p.name for p in (tmp_path / "projects" / pid).iterdir())
    assert names == ["landmarks-r2.json", "mesh-r1.obj"]
    assert store.get(pid)["mesh"]["filename"] == "../x.obj"  # display only


def test_crash_around_the_index_commit_leaves_old_or_new_state_whole(tmp_path, monkeypatch):
    """A replacing mesh must never pair the old landmarks with the new vertices,
    whether the process dies before the index commit or after it."""
    store = ProjectStore(tmp_path)
    pid = store.create("p")["id"]
    store.put_mesh(pid, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "obj", filename="a.obj",
                   n_vertices=3, n_faces=1)
    store.put_landmarks(pid, {"vertex_indices": [0, 1, 2]}, n_points=3, layout="",
                        revision=store.get(pid)["revision"])
    folder = tmp_path / "projects" / pid

    def power_cut(*args, **kwargs):
        raise KeyboardInterrupt("power cut")

    # dies inside the transaction after the new file is written: the index never names it
    state = (store.mesh_file(pid), store.landmarks(pid), store.get(pid)["revision"])
    monkeypatch.setattr("server.store._now", power_cut)
    with pytest.raises(KeyboardInterrupt):
        store.put_mesh(pid, b"v 9 9 9\n", "obj", filename="c.obj", n_vertices=1, n_faces=0)
    monkeypatch.undo()
    assert (store.mesh_file(pid), store.landmarks(pid), store.get(pid)["revision"]) == state
    assert store.mesh(pid).n_vertices == 3
    store.close()
    store = ProjectStore(tmp_path)  # opening sweeps the orphan the crash left
    assert sorted(p.name for p in folder.iterdir()) == ["landmarks-r2.json", "mesh-r1.obj"]

    # dies after the commit, before the replaced files are deleted: the new state is whole
    monkeypatch.setattr("server.store.ProjectStore._sweep", power_cut)
    with pytest.raises(KeyboardInterrupt):
        store.put_mesh(pid, b"v 5 5 5\n", "obj", filename="b.obj", n_vertices=1, n_faces=0)
    monkeypatch.undo()
    assert store.mesh_file(pid)[0].read_bytes() == b"v 5 5 5\n" and store.landmarks(pid) is None
    store.close()
    ProjectStore(tmp_path).close()
    assert sorted(p.name for p in folder.iterdir()) == ["mesh-r3.obj"]


def test_dependency_override_swaps_the_store(client, tmp_path):
    other = ProjectStore(tmp_path / "other")
    other.create("from the other store")
    client.app.dependency_overrides[get_store] = lambda: other
    try:
        assert [p["name"] for p in client.get("/api/projects").json()] == ["from the other store"]
    finally:
        client.app.dependency_overrides.clear()
    assert client.get("/api/projects").json() == []


def test_sample_project_on_first_start_only(tmp_path):
    data = tmp_path / "data"
    client = TestClient(create_app(data))
    (sample,) = client.get("/api/projects").json()
    face = _face()
    assert sample["name"] == "Sample face"
    assert sample["mesh"] == {"filename": "sample_face.obj", "format": "obj",
                              "n_vertices": len(face.vertices), "n_faces": len(face.faces)}
    assert sample["landmarks"] == {"layout": "ibug68", "n_points": 68}
    assert sample["rig"] == {"method": "biharmonic"}
    pid = sample["id"]
    mesh = load_mesh(client.get(f"/api/projects/{pid}/mesh").content, "obj")
    np.testing.assert_allclose(mesh.vertices, face.vertices, atol=1e-6)
    np.testing.assert_array_equal(mesh.faces, face.faces)
    landmarks = client.get(f"/api/projects/{pid}/landmarks").json()
    assert landmarks == {"vertex_indices": face.landmarks68.tolist(), "layout": "ibug68"}
    idx, w, n = decode_weights(client.get(f"/api/projects/{pid}/rig/weights").content)
    assert n == 68 and idx.shape[0] == len(face.vertices)
    # a feature's own vertex follows that feature alone
    rows = np.asarray(face.landmarks68)
    dense = np.zeros((len(rows), n))
    np.put_along_axis(dense, idx[rows].astype(int), w[rows], axis=1)
    np.testing.assert_allclose(dense, np.eye(68), atol=0.02)
    # a restart keeps it; deleting it means it stays deleted
    assert [p["id"] for p in TestClient(create_app(data)).get("/api/projects").json()] == [pid]
    client.delete(f"/api/projects/{pid}")
    assert TestClient(create_app(data)).get("/api/projects").json() == []


def test_restart_finds_everything(tmp_path):
    data = tmp_path / "data"
    first = TestClient(create_app(data, sample=False))
    pid = rigged_project(first, tmp_path)
    empty = first.post("/api/projects", json={"name": "empty", "settings": {"a": [1, 2]}}).json()
    listed = first.get("/api/projects").json()
    mesh = first.get(f"/api/projects/{pid}/mesh").content
    landmarks = first.get(f"/api/projects/{pid}/landmarks").json()
    weights = first.get(f"/api/projects/{pid}/rig/weights").content
    first.app.state.store.close()

    second = TestClient(create_app(data, sample=False))
    assert second.get("/api/projects").json() == listed
    assert second.get(f"/api/projects/{empty['id']}").json()["settings"] == {"a": [1, 2]}
    assert second.get(f"/api/projects/{pid}/mesh").content == mesh
    assert second.get(f"/api/projects/{pid}/landmarks").json() == landmarks
    assert second.get(f"/api/projects/{pid}/rig/weights").content == weights
    assert second.get(f"/api/projects/{pid}/rig").json()["method"] == "biharmonic"


def test_index_is_sqlite_in_wal_mode(tmp_path):
    import sqlite3
    ProjectStore(tmp_path).create("p")
    db = sqlite3.connect(tmp_path / "index.sqlite")
    assert db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert db.execute("SELECT name FROM projects").fetchall() == [("p",)]


def test_docs_are_served(client):
    assert client.get("/docs").status_code == 200
    paths = client.get("/openapi.json").json()["paths"]
    assert {"/api/projects", "/api/projects/{project_id}", "/api/projects/{project_id}/mesh",
            "/api/projects/{project_id}/mesh/arrays", "/api/projects/{project_id}/landmarks",
            "/api/projects/{project_id}/rig", "/api/projects/{project_id}/rig/weights",
            "/api/jobs/{job_id}"} <= set(paths)


def test_serve_command_is_wired_and_the_library_imports_without_web_code():
    from server.cli import build_parser
    args = build_parser().parse_args(["serve", "--port", "8123", "--data-dir", "d"])
    assert (args.host, args.port, args.data_dir) == ("127.0.0.1", 8123, "d")
    code = ("import sys, retarget, retarget.cli, retarget.weights, retarget.pipeline; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('server', 'fastapi', 'uvicorn', 'starlette')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout.replace("'", '"')) == []


def test_store_keeps_the_stereo_calibration_through_sweeps_and_adopts_the_old_fixed_name(tmp_path):
    import sqlite3
    store = ProjectStore(tmp_path)
    pid = store.create("stereo")["id"]
    assert store.stereo_calibration(pid) is None
    store.put_stereo_calibration(pid, {"rms": 0.1})
    store.put_stereo_calibration(pid, {"rms": 0.05})        # replaces: the first file is swept
    assert store.stereo_calibration(pid) == {"rms": 0.05}
    assert len(list(store.folder(pid).glob("stereo-calibration-*.json"))) == 1
    store.close()
    assert ProjectStore(tmp_path).stereo_calibration(pid) == {"rms": 0.05}   # a restart's sweep keeps it

    # a project from before the store kept it: the live router wrote a fixed name
    db = sqlite3.connect(tmp_path / "index.sqlite")
    db.execute("UPDATE projects SET stereo_calibration_file = NULL")
    db.commit()
    db.close()
    for path in (tmp_path / "projects" / pid).glob("stereo-calibration-*.json"):
        path.unlink()
    (tmp_path / "projects" / pid / "stereo-calibration.json").write_text('{"rms": 0.2}')
    assert ProjectStore(tmp_path).stereo_calibration(pid) == {"rms": 0.2}
