"""A project's custom layouts (server/routers/layouts.py): saved, listed, refused with a
reason, and used like a built-in layout: landmarks, the rig, a take named by the markers,
partial retargeting, conditioning on the user's anchors and export.glb, across a restart."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
from fastapi.testclient import TestClient

from retarget import layouts as library_layouts
from retarget.gltf import read_gltf
from retarget.layouts import LAYOUTS, get_layout
from retarget.mesh import mesh_from_arrays, save_mesh
from retarget.sample_face import sample_face
from server.app import create_app
from server.store import MAX_PROJECT_LAYOUTS
from tests.waits import wait_job

IBUG = get_layout("ibug68")
MARKERS = (17, 19, 21, 22, 24, 26, 48, 54, 51, 57, 8, 30, 36, 45)
NAMES = [f"m{k:02d}" for k in range(len(MARKERS))]
BROWS = [k for k, i in enumerate(MARKERS) if IBUG.regions[i] == "brows"]
ANCHORS = {"m11", "m12", "m13"}
EVIL = "http://evil.example"


def markers_spec() -> dict:
    """The user's 14 markers, on iBUG spots of the sample face, named their way."""
    points = []
    for k, i in enumerate(MARKERS):
        point = {"name": NAMES[k], "region": IBUG.regions[i], "side": IBUG.sides[i]}
        if IBUG.mirror[i] != i:
            point["mirror"] = NAMES[MARKERS.index(IBUG.mirror[i])]
        if NAMES[k] in ANCHORS:
            point["anchor"] = True
        points.append(point)
    return {"description": "my markers", "points": points}


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return tmp_path_factory.mktemp("custom") / "data"


@pytest.fixture(scope="module")
def client(data):
    with TestClient(create_app(data, sample=False)) as c:
        yield c


@pytest.fixture(scope="module")
def project(client, tmp_path_factory):
    """A project holding the sample face, the layout saved as "markers", landmarks placed
    in it and a rig."""
    face = sample_face()
    path = tmp_path_factory.mktemp("mesh") / "face.obj"
    save_mesh(mesh_from_arrays(face.vertices, face.faces), path)
    pid = client.post("/api/projects", json={"name": "markers"}).json()["id"]
    assert client.put(f"/api/projects/{pid}/mesh", files={"file": ("face.obj", path.read_bytes())}).status_code == 200
    r = client.put(f"/api/projects/{pid}/layouts/markers", json=markers_spec())
    assert r.status_code == 201, r.text
    r = client.put(f"/api/projects/{pid}/landmarks", json={
        "vertex_indices": np.asarray(face.landmarks68)[list(MARKERS)].tolist(), "layout": "markers"})
    assert r.status_code == 200, r.text
    job = client.post(f"/api/projects/{pid}/rig", json={"method": "ellipsoid"}).json()
    assert wait_job(client, job["id"])["state"] == "done"
    return pid


def take_json(n_frames=40) -> bytes:
    """A take named by the markers: brows raised and jaw opened over the frames, and the
    whole head sliding 1 cm to the side (the anchors with it)."""
    face = sample_face(identity=[0.8, 0.5, -0.6, 1.0, 0.3])
    rows = np.asarray(face.landmarks68)[list(MARKERS)]
    w = np.zeros((n_frames, len(face.expression_names)))
    ramp = np.linspace(0, 1, n_frames)
    for name in ("browInnerUp", "browOuterUp_L", "browOuterUp_R", "jawOpen"):
        w[:, face.expression_names.index(name)] = ramp
    frames = face.vertices[rows] + np.einsum("fe,evd->fvd", w, face.expressions[:, rows])
    frames[..., 0] += ramp[:, None]
    return json.dumps({"names": NAMES, "frames": frames.round(5).tolist()}).encode()


def test_a_saved_layout_is_listed_with_the_built_in_ones(client, project):
    listed = client.get(f"/api/projects/{project}/layouts").json()
    assert [item["name"] for item in listed[:len(LAYOUTS)]] == list(LAYOUTS)
    (mine,) = listed[len(LAYOUTS):]
    assert mine["custom"] and mine["saved_as"] == "markers" and mine["name"].startswith("custom-")
    assert [p["name"] for p in mine["points"]] == NAMES
    assert mine["points"][0] == {"name": "m00", "region": "brows", "side": "right", "mirror": 5,
                                 "reference": None, "mediapipe468": -1}
    assert set(mine["anchors"]) == ANCHORS and mine["description"] == "my markers"
    by_hash = client.get(f"/api/projects/{project}/layouts/{mine['name']}").json()
    assert by_hash == client.get(f"/api/projects/{project}/layouts/markers").json() == mine
    assert client.get(f"/api/projects/{project}/layouts/dutreve22").json()["n_points"] == 22
    assert client.get(f"/api/projects/{project}/layouts/nothing").status_code == 404
    r = client.get(f"/api/layouts/{mine['name']}")  # the global list is the built-in layouts
    assert r.status_code == 422 and "unknown layout" in r.json()["detail"]
    # another project sees only the built-in layouts
    other = client.post("/api/projects", json={"name": "other"}).json()["id"]
    assert len(client.get(f"/api/projects/{other}/layouts").json()) == len(LAYOUTS)
    assert client.get(f"/api/projects/{other}/layouts/markers").status_code == 404


def _with(change):
    spec = markers_spec()
    change(spec)
    return spec


@pytest.mark.parametrize("name, spec, code, message", [
    ("bad", _with(lambda s: s["points"][0].update(name="m 00")), 422, "'m 00' is not a safe identifier"),
    ("bad", _with(lambda s: s["points"][0].update(region="ears")), 422, "region 'ears' is not one of"),
    ("bad", _with(lambda s: s["points"][1].update(name="m00")), 422, "'m00' is repeated"),
    ("bad", _with(lambda s: s["points"][0].update(mirror="m04")), 422, "asymmetric mirror: point 'm00'"),
    ("bad", _with(lambda s: s.update(points=s["points"][:2])), 422, "needs 3 to 1000 points, got 2"),
    ("bad", _with(lambda s: s.update(points=[{"name": f"p{i}"} for i in range(1001)])), 422,
     "needs 3 to 1000 points, got 1001"),
    ("bad", _with(lambda s: s["points"][0].update(name="x" * 65)), 422, "not a safe identifier"),
    ("ibug68", markers_spec(), 422, "layout name 'ibug68' is taken"),
    ("custom-0123456789abcdef", markers_spec(), 422, "is taken by the library's layouts"),
    ("a" * 65, markers_spec(), 422, "must be 1 to 64 letters"),
    ("a.b", markers_spec(), 422, "must be 1 to 64 letters"),
])
def test_a_bad_layout_is_refused_with_its_reason_and_nothing_is_saved(client, project, name, spec, code, message):
    before = client.get(f"/api/projects/{project}/layouts").json()
    r = client.put(f"/api/projects/{project}/layouts/{name}", json=spec)
    assert r.status_code == code and message in r.json()["detail"], r.text
    assert client.get(f"/api/projects/{project}/layouts").json() == before


def test_a_layout_from_another_origin_or_to_no_project_is_refused(client, project):
    r = client.put(f"/api/projects/{project}/layouts/evil", json=markers_spec(), headers={"Origin": EVIL})
    assert r.status_code == 403
    assert client.get(f"/api/projects/{project}/layouts/evil").status_code == 404
    assert client.put("/api/projects/AAAAAAAAAAAAAAAAAAAAAA/layouts/x", json=markers_spec()).status_code == 404
    assert client.put("/api/projects/..%2F..%2Fetc/layouts/x", json=markers_spec()).status_code == 404
    assert client.put(f"/api/projects/{project}/layouts/..%2Fx", json=markers_spec()).status_code in (404, 422)


def test_a_project_saves_a_bounded_number_of_layouts(client):
    pid = client.post("/api/projects", json={"name": "many"}).json()["id"]
    for k in range(MAX_PROJECT_LAYOUTS):
        assert client.put(f"/api/projects/{pid}/layouts/l{k}", json=markers_spec()).status_code == 201
    r = client.put(f"/api/projects/{pid}/layouts/one_more", json=markers_spec())
    assert r.status_code == 409 and "delete one first" in r.json()["detail"]
    assert client.put(f"/api/projects/{pid}/layouts/l0", json=markers_spec()).status_code == 200  # replaced
    assert client.delete(f"/api/projects/{pid}/layouts/l0").status_code == 204
    assert client.delete(f"/api/projects/{pid}/layouts/l0").status_code == 404
    assert client.put(f"/api/projects/{pid}/layouts/one_more", json=markers_spec()).status_code == 201


def test_landmarks_in_a_custom_layout_carry_its_spec(client, project):
    info = client.get(f"/api/projects/{project}").json()
    name = info["landmarks"]["layout"]
    assert name.startswith("custom-") and info["landmarks"]["n_points"] == len(NAMES)
    stored = client.get(f"/api/projects/{project}/landmarks").json()
    assert stored["layout"] == name and [p["name"] for p in stored["layout_spec"]["points"]] == NAMES
    r = client.put(f"/api/projects/{project}/landmarks", json={"vertex_indices": [1, 2, 3], "layout": "markers"})
    assert r.status_code == 422 and "has 14 points but 3 landmarks" in r.json()["detail"]
    r = client.put(f"/api/projects/{project}/landmarks", json={"vertex_indices": [1, 2, 3], "layout": "mine"})
    assert r.status_code == 422 and "this project's custom layouts markers" in r.json()["detail"]
    assert client.get(f"/api/projects/{project}/landmarks").json() == stored  # nothing lost
    r = client.post(f"/api/projects/{project}/landmarks/find", json={"layout": "markers", "replace": True})
    assert r.status_code == 422 and "no face-mesh vertex" in r.json()["detail"]


def test_a_take_named_by_the_markers_exports_with_partial_retargeting_and_conditioning(client, project):
    r = client.post(f"/api/projects/{project}/takes", files={"file": ("perf.json", take_json())},
                    data={"fps": "30"})
    assert r.status_code == 201, r.text
    take = r.json()
    assert take["n_points"] == len(NAMES)
    r = client.get(f"/api/projects/{project}/layouts/from-take/{take['id']}")
    assert r.json() == {"take": take["id"], "names": NAMES, "reference": None}  # 3D, not from stereo stickers: axes unknown, no reference
    assert client.get(f"/api/projects/{project}/layouts/from-take/AAAAAAAAAAAAAAAA").status_code == 404
    assert client.get(f"/api/projects/{project}/layouts/from-take/..%2F..").status_code == 404
    settings = json.dumps({"head_pose": "remove", "filter": "none",
                           "neutral": {"mode": "frame", "frame": 0}})
    whole = client.get(f"/api/projects/{project}/export.glb",
                       params={"takes": take["id"], "settings": settings})
    assert whole.status_code == 200, whole.text
    brows = client.get(f"/api/projects/{project}/export.glb",
                       params={"takes": take["id"], "settings": settings, "regions": "brows"})
    assert brows.status_code == 200, brows.text
    full, part = (read_gltf(io.BytesIO(r.content)) for r in (whole, brows))
    assert list(full.joint_names) == NAMES
    moved = np.abs(full.clips[0].displacements).max(axis=(0, 2))
    assert moved[BROWS].min() > 0.1 and moved[NAMES.index("m10")] > 0.1  # brows and chin
    anchors = [NAMES.index(a) for a in ANCHORS]
    assert moved[anchors].max() < 0.2  # the head's 1 cm slide is removed on the user's anchors
    kept = client.get(f"/api/projects/{project}/export.glb", params={
        "takes": take["id"], "settings": settings.replace('"remove"', '"keep"')})
    slid = np.abs(read_gltf(io.BytesIO(kept.content)).clips[0].displacements).max(axis=(0, 2))
    assert slid[anchors].min() > 0.8
    only = np.abs(part.clips[0].displacements).max(axis=(0, 2))
    assert only[BROWS].min() > 0.1 and np.delete(only, BROWS).max() == 0


def test_an_exported_glb_imports_with_its_custom_layout(client, project):
    glb = client.get(f"/api/projects/{project}/export.glb").content
    r = client.post("/api/projects/import", files={"file": ("markers.glb", glb)})
    assert r.status_code == 201, r.text
    imported = r.json()["project"]
    original = client.get(f"/api/projects/{project}/landmarks").json()
    landmarks = client.get(f"/api/projects/{imported['id']}/landmarks").json()
    assert landmarks["layout"] == original["layout"] and landmarks["layout_spec"] == original["layout_spec"]
    # its takes are read in it: the layout comes from the landmarks, though the project saved none
    r = client.post(f"/api/projects/{imported['id']}/takes", files={"file": ("perf.json", take_json(30))},
                    data={"fps": "30"})
    assert r.status_code == 201, r.text


def test_a_take_file_s_marker_names_are_read_without_storing_it(client, project):
    before = client.get(f"/api/projects/{project}/takes").json()
    names = ["a1", "b2", "c3"]
    data = json.dumps({"names": names, "frames": [[[0, 0, 0], [1, 0, 0], [0, 1, 0]]] * 3}).encode()
    r = client.post(f"/api/projects/{project}/layouts/from-take", files={"file": ("x.json", data)},
                    data={"fps": "30"})
    assert r.status_code == 200 and r.json() == {"take": None, "names": names, "reference": None}, r.text
    r = client.post(f"/api/projects/{project}/layouts/from-take", files={"file": ("x.json", b"{")})
    assert r.status_code == 422 and "x.json" in r.json()["detail"]
    r = client.post(f"/api/projects/{project}/layouts/from-take", files={"file": ("x.exe", data)})
    assert r.status_code in (415, 422)
    assert client.get(f"/api/projects/{project}/takes").json() == before


def test_markerless_tracking_refuses_markers_the_face_mesh_has_no_vertex_for(client, project):
    r = client.post(f"/api/projects/{project}/takes/track", data={"method": "markerless"},
                    files={"file": ("v.mp4", b"not read")})
    assert r.status_code == 422 and "no face-mesh vertex" in r.json()["detail"]


def test_a_restart_keeps_the_layouts_and_what_uses_them(client, project, data):
    listed = client.get(f"/api/projects/{project}/layouts").json()
    library_layouts._REGISTERED.clear()  # as a fresh process
    with TestClient(create_app(data, sample=False)) as second:
        assert second.get(f"/api/projects/{project}/layouts").json() == listed
        r = second.post(f"/api/projects/{project}/takes", files={"file": ("again.json", take_json(30))},
                        data={"fps": "30"})
        assert r.status_code == 201, r.text
        library_layouts._REGISTERED.clear()
        r = second.get(f"/api/projects/{project}/export.glb", params={"takes": r.json()["id"]})
        assert r.status_code == 200, r.text
        assert second.delete(f"/api/projects/{project}/layouts/markers").status_code == 204
        library_layouts._REGISTERED.clear()
        # the landmarks keep the spec: the rig and export still work without the saved layout
        job = second.post(f"/api/projects/{project}/rig", json={"method": "ellipsoid"}).json()
        assert wait_job(second, job["id"])["state"] == "done"
        assert second.get(f"/api/projects/{project}/export.glb").status_code == 200
