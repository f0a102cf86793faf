"""Landmarks and rigs through the web API: validation against the stored mesh and the
layout, the background rig job, and the binary weights form."""

from __future__ import annotations

import re
import shutil
import struct
import threading
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
from server.wire import quantised_weights, weights_from_binary
from tests.waits import wait_job


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


def run_job(client, job_id):
    """(the stopped job, the progress figure of every poll)."""
    seen = []
    return wait_job(client, job_id, poll_s=0.01, progress=seen), seen


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
        "n_influences": 68, "version": 1, "painted_vertices": 0}
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
    # stored on the grid of version 2 (the page's download), within its step / 2
    np.testing.assert_array_equal(w, quantised_weights(expected).weights)
    assert 0 < np.abs(w - expected.weights).max() <= 2.0 ** -19
    # version 2, what the page reads: quantised, dense (no indices), gzip-encoded on request
    raw = client.get(f"/api/projects/{pid}/rig/weights", params={"version": 2},
                     headers={"Accept-Encoding": "identity"})
    assert "content-encoding" not in raw.headers
    r = client.get(f"/api/projects/{pid}/rig/weights", params={"version": 2},
                   headers={"Accept-Encoding": "gzip"})
    assert r.headers["content-encoding"] == "gzip" and r.content == raw.content
    assert len(raw.content) == 28 + 3 * w.size  # no indices, 3 bytes a weight
    assert int(r.headers["content-length"]) < len(raw.content) / 3
    v2 = weights_from_binary(r.content)
    np.testing.assert_array_equal(v2.indices, expected.indices)
    np.testing.assert_array_equal(v2.weights, w)  # the stored rig exactly
    assert client.get(f"/api/projects/{pid}/rig/weights", params={"version": 3}).status_code == 422


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
    first = jobs.start("p", "rig", lambda job: release.wait(5) and ("ok", None))
    with pytest.raises(JobBusy, match="already has a running job"):
        jobs.start("p", "rig", lambda job: ("never", None))
    other = jobs.start("q", "rig", lambda job: ("fine", {"n": 1}))  # other projects are not blocked
    release.set()
    jobs.wait(first.id, 5)
    jobs.wait(other.id, 5)
    assert first.as_json()["state"] == "done" and other.as_json()["detail"] == "fine"
    assert other.as_json()["result"] == {"n": 1}
    again = jobs.start("p", "rig", lambda job: (_ for _ in ()).throw(ValueError("bad input")))
    jobs.wait(again.id, 5)
    assert again.as_json()["state"] == "failed" and again.as_json()["detail"] == "bad input"


def test_weights_binary_pads_odd_counts_to_align_the_floats():
    from retarget.skin import SkinWeights
    from server.wire import weights_binary
    rig = SkinWeights(np.array([[0], [2], [1]], np.int32), np.array([[1.0], [0.5], [0.25]], np.float32), 3)
    data = weights_binary(rig)
    assert len(data) == 20 + 6 + 2 + 12 and data[26:28] == b"\0\0"
    idx, w, n = decode_weights(data)
    np.testing.assert_array_equal(idx[:, 0], [0, 2, 1])
    np.testing.assert_array_equal(w[:, 0], [1.0, 0.5, 0.25])


# -- weight painting ------------------------------------------------------------------------

def encode_edit(version, vertices, indices, weights, n_joints=68, magic=b"RTSE") -> bytes:
    """The binary weight edit of server/routers/rigs.py."""
    indices, weights = np.asarray(indices), np.asarray(weights)
    r, k = indices.shape
    index_bytes = indices.astype("<u2").tobytes()
    return (struct.pack("<4sIIIII", magic, 1, r, k, n_joints, version)
            + np.asarray(vertices, "<u4").tobytes() + index_bytes + b"\0" * (-len(index_bytes) % 4)
            + weights.astype("<f4").tobytes())


def patch_edit(client, pid, body: bytes):
    return client.patch(f"/api/projects/{pid}/rig/weights", content=body,
                        headers={"Content-Type": "application/octet-stream"})


def stored_rig(client, pid):
    from retarget.skin import SkinWeights
    idx, w, n = decode_weights(client.get(f"/api/projects/{pid}/rig/weights").content)
    return SkinWeights(idx.astype(np.int32), w.copy(), n)


@pytest.fixture(scope="module")
def rigged_data(tmp_path_factory):
    """(data dir, project id) holding the sample face with a non-negative ellipsoid rig,
    k = 4; built once, copied by `rigged`."""
    data = tmp_path_factory.mktemp("rigged") / "data"
    app = create_app(data, sample=False)
    client = TestClient(app)
    pid = client.post("/api/projects", json={"name": "face"}).json()["id"]
    path = data.parent / "face.obj"
    save_mesh(mesh_from_arrays(_face().vertices, _face().faces), path)
    client.put(f"/api/projects/{pid}/mesh", files={"file": ("face.obj", path.read_bytes())})
    client.put(f"/api/projects/{pid}/landmarks", json=ibug_json())
    job = client.post(f"/api/projects/{pid}/rig", json={"method": "ellipsoid", "k": 4}).json()
    assert run_job(client, job["id"])[0]["state"] == "done"
    app.state.store.close()
    return data, pid


@pytest.fixture
def rigged(tmp_path, rigged_data):
    """(client, project id, automatic rig) on a copy of `rigged_data` in tmp_path/data."""
    shutil.copytree(rigged_data[0], tmp_path / "data")
    client = TestClient(create_app(tmp_path / "data", sample=False))
    return client, rigged_data[1], stored_rig(client, rigged_data[1])


def nose_paint(rig, joint=30, value=0.9):
    """(vertices, (R, N) painted rows) raising `joint` near the nose tip as a brush would."""
    from retarget.weights.painting import automatic_rows, with_weight
    face = _face()
    tip = face.vertices[face.landmarks68[30]]
    vertices = np.flatnonzero(np.linalg.norm(face.vertices - tip, axis=1) < 1.0)
    return vertices, with_weight(automatic_rows(rig, vertices), joint, value)


def test_a_painted_edit_is_stored_normalised_and_survives_a_restart(rigged, tmp_path):
    client, pid, auto = rigged
    info = client.get(f"/api/projects/{pid}/rig").json()
    assert info["painted_vertices"] == 0
    vertices, rows = nose_paint(auto)
    joints = np.broadcast_to(np.arange(68), rows.shape)
    r = patch_edit(client, pid, encode_edit(info["version"], vertices, joints, rows))
    assert r.status_code == 200, r.text
    painted = stored_rig(client, pid)
    assert r.json() == {**info, "version": info["version"] + 1,
                        "painted_vertices": int(np.count_nonzero(np.abs(painted.dense() - auto.dense()).max(1) > 1e-6))}
    assert 0 < r.json()["painted_vertices"] <= len(vertices)
    after = painted.dense()
    np.testing.assert_allclose(after[vertices, 30], 0.9 * np.ones(len(vertices)), atol=0.05)  # top-4 rescales a little
    assert after.min() >= 0 and after.sum(1).max() <= 1 + 1e-5
    assert np.count_nonzero(after, axis=1).max() <= 4
    others = np.setdiff1d(np.arange(len(after)), vertices)
    np.testing.assert_array_equal(after[others], auto.dense()[others])

    from retarget.weights.painting import WeightEdit
    stored, = (tmp_path / "data" / "projects" / pid).glob("paint-*.npz")  # only the painted rows
    assert WeightEdit.load(stored).n_rows == r.json()["painted_vertices"]

    again = TestClient(create_app(tmp_path / "data", sample=False))  # a restart on the same data
    assert again.get(f"/api/projects/{pid}/rig").json() == r.json()
    np.testing.assert_array_equal(stored_rig(again, pid).dense(), after)


def test_a_json_edit_does_the_same(rigged):
    client, pid, auto = rigged
    vertices, rows = nose_paint(auto, joint=33, value=0.0)
    version = client.get(f"/api/projects/{pid}/rig").json()["version"]
    body = {"version": version, "vertices": vertices.tolist(),
            "indices": [list(range(68))] * len(vertices), "weights": rows.tolist()}
    r = client.patch(f"/api/projects/{pid}/rig/weights", json=body)
    assert r.status_code == 200, r.text
    after = stored_rig(client, pid).dense()
    np.testing.assert_allclose(after[vertices, 33], 0.0, atol=1e-7)
    from retarget.skin import SkinWeights
    np.testing.assert_allclose(after[vertices], SkinWeights.from_dense(rows, 4).dense(), atol=1e-6)


def test_a_stale_edit_is_refused_and_changes_nothing(rigged):
    client, pid, auto = rigged
    version = client.get(f"/api/projects/{pid}/rig").json()["version"]
    vertices, rows = nose_paint(auto)
    joints = np.broadcast_to(np.arange(68), rows.shape)
    assert patch_edit(client, pid, encode_edit(version, vertices, joints, rows)).status_code == 200
    painted = stored_rig(client, pid).dense()
    # a second page still on `version`: its edit would overwrite the first blindly
    _, other = nose_paint(auto, joint=31, value=1.0)
    r = patch_edit(client, pid, encode_edit(version, vertices, joints, other))
    assert r.status_code == 409
    assert r.json()["detail"] == (f"the rig changed (now version {version + 1}) since version {version} "
                                  f"that this edit was made on: reload the weights and paint again")
    np.testing.assert_array_equal(stored_rig(client, pid).dense(), painted)
    # recomputing the rig makes the painted one's version stale too, and drops the paint
    job = client.post(f"/api/projects/{pid}/rig", json={"method": "ellipsoid", "k": 4}).json()
    run_job(client, job["id"])
    assert client.get(f"/api/projects/{pid}/rig").json()["painted_vertices"] == 0
    r = patch_edit(client, pid, encode_edit(version + 1, vertices, joints, rows))
    assert r.status_code == 409 and f"now version {version + 2}" in r.json()["detail"]


@pytest.mark.parametrize("change, detail", [
    (lambda e: {**e, "weights": np.where(e["weights"] > 0.5, np.nan, e["weights"])},
     r"weight nan \(row \d+, vertex \d+, joint 30\) is not a finite number"),
    (lambda e: {**e, "weights": e["weights"] - 0.01 * (e["weights"] == 0)},
     r"weight -0.01 \(row 0, vertex \d+, joint \d+\) is negative; vertex \d+'s automatic weights"),
    (lambda e: {**e, "vertices": e["vertices"] + 9000}, r"vertex index \d+ \(row 0\) is out of range: "
                                                      r"the mesh has 8430 vertices \(0..8429\)"),
    (lambda e: {**e, "indices": e["indices"][:, ::-1] + 1},
     r"joint index 68 \(row 0, vertex \d+, slot 0\) is out of range: the rig has 68 joints \(0..67\)"),
    (lambda e: {**e, "weights": e["weights"] * 1.05},
     r"row \d+ \(vertex \d+\) sums to [\d.]+, over 1: a vertex's feature weights sum to at most 1"),
    (lambda e: {**e, "n_joints": 51}, r"weight edit is for 51 joints; the rig has 68"),
    (lambda e: {**e, "magic": b"RTSW"}, r"weight edit: expected magic b'RTSE' version 1, got b'RTSW' version 1"),
    (lambda e: {**e, "truncate": 6}, r"weight edit: \d+ rows of 68 influences need \d+ bytes; got \d+"),
    (lambda e: {**e, "truncate": 10**6}, r"weight edit: \d+ bytes is shorter than its 24-byte header"),
])
def test_bad_edits_are_422_with_the_reason_and_change_nothing(rigged, change, detail):
    client, pid, auto = rigged
    version = client.get(f"/api/projects/{pid}/rig").json()["version"]
    vertices, rows = nose_paint(auto)
    edit = change({"vertices": vertices, "indices": np.broadcast_to(np.arange(68), rows.shape),
                   "weights": rows, "n_joints": 68, "magic": b"RTSE", "truncate": 0})
    body = encode_edit(version, edit["vertices"], edit["indices"], edit["weights"], edit["n_joints"], edit["magic"])
    body = body[:max(len(body) - edit["truncate"], 10)]
    r = patch_edit(client, pid, body)
    assert r.status_code == 422, r.text
    assert re.search(detail, r.json()["detail"]), r.json()["detail"]
    assert client.get(f"/api/projects/{pid}/rig").json()["version"] == version
    np.testing.assert_array_equal(stored_rig(client, pid).dense(), auto.dense())


def test_bad_json_edits_are_422(rigged):
    client, pid, _ = rigged
    url = f"/api/projects/{pid}/rig/weights"
    r = client.patch(url, json={"version": 1, "vertices": [1], "indices": [[0, 1]]})
    assert r.status_code == 422
    assert r.json()["detail"] == "body field 'weights': Field required"
    r = client.patch(url, json={"version": 1, "vertices": [1, 2], "indices": [[0, 1], [0]],
                                "weights": [[0.5, 0.1], [0.5]]})
    assert r.status_code == 422 and "must be rectangular (R, K) arrays" in r.json()["detail"]


def test_resetting_one_joint_then_all_goes_back_to_the_automatic_rig(rigged, tmp_path):
    client, pid, auto = rigged
    version = client.get(f"/api/projects/{pid}/rig").json()["version"]
    vertices, rows = nose_paint(auto, joint=30, value=1.0)
    joints = np.broadcast_to(np.arange(68), rows.shape)
    patch_edit(client, pid, encode_edit(version, vertices, joints, rows))
    face = _face()
    brow = face.vertices[face.landmarks68[19]]
    brow_vertices = np.flatnonzero(np.linalg.norm(face.vertices - brow, axis=1) < 0.8)
    from retarget.weights.painting import automatic_rows, with_weight
    brow_rows = with_weight(automatic_rows(stored_rig(client, pid), brow_vertices), 19, 0.0)
    r = patch_edit(client, pid, encode_edit(version + 1, brow_vertices, joints[:len(brow_vertices)], brow_rows))
    assert r.status_code == 200, r.text
    assert r.json()["painted_vertices"] == len(np.union1d(vertices, brow_vertices))

    r = client.post(f"/api/projects/{pid}/rig/reset", json={"joints": [30]})
    assert r.status_code == 200, r.text
    after = stored_rig(client, pid).dense()
    np.testing.assert_allclose(after[:, 30], auto.dense()[:, 30], atol=1e-6)
    np.testing.assert_allclose(after[vertices], auto.dense()[vertices], atol=1e-6)  # the brow is far
    assert r.json()["painted_vertices"] == len(brow_vertices) and r.json()["version"] == version + 3
    assert np.all(after[brow_vertices, 19] == 0)

    r = client.post(f"/api/projects/{pid}/rig/reset", json={"joints": None, "version": version + 3})
    assert r.status_code == 200 and r.json()["painted_vertices"] == 0
    np.testing.assert_array_equal(stored_rig(client, pid).dense(), auto.dense())
    folder = tmp_path / "data" / "projects" / pid
    assert len(list(folder.glob("rig-*.npz"))) == 1 and not list(folder.glob("paint-*"))  # painted rows gone


@pytest.mark.parametrize("body, code, detail", [
    ({"joints": [68]}, 422, "joint 68 is not a joint index: the rig has 68 joints (0..67)"),
    ({"joints": []}, 422, "joints must name at least one joint to reset (null resets all)"),
    ({}, 422, None),
    ({"joints": None, "version": 0}, 409, "the rig changed (now version 1) since version 0"),
])
def test_bad_resets(rigged, body, code, detail):
    client, pid, _ = rigged
    r = client.post(f"/api/projects/{pid}/rig/reset", json=body)
    assert r.status_code == code, r.text
    if detail:
        assert detail in r.json()["detail"]


def test_painting_needs_a_rig(client, face_project):
    pid, _ = face_project
    r = patch_edit(client, pid, encode_edit(0, [1], [[0]], [[0.5]]))
    assert r.status_code == 404 and "has no rig yet" in r.json()["detail"]
    r = client.post(f"/api/projects/{pid}/rig/reset", json={"joints": None})
    assert r.status_code == 404 and "has no rig yet" in r.json()["detail"]


def test_a_too_large_edit_is_413(tmp_path):
    client = TestClient(create_app(tmp_path / "small", sample=False, max_upload_bytes=1000))
    pid = client.post("/api/projects", json={"name": "p"}).json()["id"]
    r = patch_edit(client, pid, encode_edit(0, np.arange(100), np.zeros((100, 4)), np.zeros((100, 4))))
    assert r.status_code == 413 and "at most 1000 bytes" in r.json()["detail"]


def test_a_signed_rig_is_painted_and_reset_within_its_envelope(tmp_path):
    """The sample project's biharmonic rig has negative weights: painting keeps them where
    the brush does not reach and only shrinks them where it does."""
    client = TestClient(create_app(tmp_path / "data"))
    pid = client.get("/api/projects").json()[0]["id"]
    auto = stored_rig(client, pid)
    vertices, rows = nose_paint(auto, joint=30, value=0.2)
    assert rows.min() < 0  # the brush reaches negative weights
    version = client.get(f"/api/projects/{pid}/rig").json()["version"]
    joints = np.broadcast_to(np.arange(68), rows.shape)
    assert patch_edit(client, pid, encode_edit(version, vertices, joints, rows)).status_code == 200
    after, before = stored_rig(client, pid).dense(), auto.dense()
    np.testing.assert_allclose(after[vertices], rows, atol=1e-6)
    assert np.all(after[vertices] >= np.minimum(before[vertices], 0) - 1e-6)
    deeper = rows.copy()
    deeper[rows < 0] *= 1.5
    r = patch_edit(client, pid, encode_edit(version + 1, vertices, joints, deeper))
    assert r.status_code == 422 and "painting may shrink negative weights, not deepen them" in r.json()["detail"]
    assert client.post(f"/api/projects/{pid}/rig/reset", json={"joints": [30]}).status_code == 200
    np.testing.assert_allclose(stored_rig(client, pid).dense()[:, 30], before[:, 30], atol=1e-6)


def test_a_store_from_before_painting_keeps_its_rig_as_the_automatic_one(rigged, tmp_path):
    import sqlite3
    client, pid, auto = rigged
    client.app.state.store.close()
    db = sqlite3.connect(tmp_path / "data" / "index.sqlite")
    db.execute("ALTER TABLE projects DROP COLUMN painted_file")
    db.execute("ALTER TABLE projects DROP COLUMN rig_version")
    db.execute("ALTER TABLE projects DROP COLUMN rig_painted")
    db.commit()
    db.close()
    again = TestClient(create_app(tmp_path / "data", sample=False))
    info = again.get(f"/api/projects/{pid}/rig").json()
    assert info["version"] == 0 and info["painted_vertices"] == 0
    vertices, rows = nose_paint(auto)
    joints = np.broadcast_to(np.arange(68), rows.shape)
    assert patch_edit(again, pid, encode_edit(0, vertices, joints, rows)).status_code == 200
    assert again.post(f"/api/projects/{pid}/rig/reset", json={"joints": None}).status_code == 200
    np.testing.assert_array_equal(stored_rig(again, pid).dense(), auto.dense())
