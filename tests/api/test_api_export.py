"""Export a project as glTF and import one (server/routers/exports.py): the export
validates with the Khronos validator and holds the project's mesh, landmarks, rig (painted
included) and takes as animations retargeted as the take player plays them (with
drive=muscles: its muscles, animated by the contractions solved from them); importing it
gives a project with the same mesh, landmarks and weights; bad input is refused with its
reason and makes no project."""

import io
import json
import struct

import numpy as np
import pytest
import trimesh
from fastapi.testclient import TestClient

from retarget.gltf import read_gltf
from retarget.gltf.animation import (animated_weights, animation_channels, mesh_instances,
                                       node_transforms, posed_vertices)
from retarget.gltf.document import GltfDocument
from retarget.landmarks import landmarks_from_json
from retarget.layouts import get_layout
from retarget.muscles import MuscleFace
from retarget.muscles.drive import MuscleDrive
from retarget.muscles.morphs import muscle_morphs, played_displacements
from retarget.sample_face import demo_weights, sample_face
from retarget.sources.conditioning import ConditionSettings
from server.app import create_app
from server.players import TakePlayer
from tests.gltf_check import assert_valid_gltf
from tests.waits import wait_job

FPS = 30.0


@pytest.fixture(scope="module")
def sample(client):
    """The sample project's id and a take uploaded to it: (pid, take info)."""
    pid = next(p["id"] for p in client.get("/api/projects").json() if p["landmarks"])
    face = sample_face(identity=np.array([0.8, 0.5, -0.6, 1.0, 0.3]))
    lm = np.asarray(face.landmarks68)
    frames = face.vertices[lm] + np.tensordot(demo_weights(60, FPS), face.expressions[:, lm], axes=1)
    r = client.post(f"/api/projects/{pid}/takes", files={"file": ("smile.npy", npy_bytes(frames))},
                    data={"layout": "ibug68", "fps": str(FPS)})
    assert r.status_code == 201, r.text
    return pid, r.json()


def npy_bytes(array) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, np.asarray(array, dtype=np.float32))
    return buffer.getvalue()


def mesh_arrays(client, pid):
    """(V, 3) float32 vertices and (F, 3) faces the browser gets (the RTMA format)."""
    data = client.get(f"/api/projects/{pid}/mesh/arrays").content
    v, f = struct.unpack_from("<II", data, 8)
    return (np.frombuffer(data, "<f4", 3 * v, 16).reshape(v, 3),
            np.frombuffer(data, "<u4", 3 * f, 16 + 12 * v).reshape(f, 3))


def export(client, pid, **params):
    return client.get(f"/api/projects/{pid}/export.glb", params=params)


def import_glb(client, data, filename="face.glb", **fields):
    return client.post("/api/projects/import", files={"file": (filename, data)}, data=fields)


def played(app, pid, take_id, settings=None):
    """(F, 68, 3) displacements and (F,) times of the take as the take player plays them."""
    store = app.state.store
    mesh = store.mesh(pid)
    points = landmarks_from_json(store.landmarks(pid), mesh.vertices, mesh.faces)
    player = TakePlayer(points.positions(mesh.vertices), "ibug68", store.take(pid, take_id),
                        ConditionSettings.from_dict(settings))
    return player.performance.displacements(player.cue.points), player.cue.times


@pytest.fixture(scope="module")
def exported(client, sample, tmp_path_factory):
    """The sample project exported with its take: (response, path of the .glb)."""
    pid, take = sample
    r = export(client, pid, takes="all")
    path = tmp_path_factory.mktemp("export") / "sample.glb"
    path.write_bytes(r.content)
    return r, path


def test_the_export_is_valid_gltf_with_the_project_and_its_take(app, client, sample, exported):
    pid, take = sample
    r, path = exported
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "model/gltf-binary"
    assert r.headers["content-disposition"] == 'attachment; filename="Sample-face.glb"'
    info = assert_valid_gltf(path)["info"]
    assert info["animationCount"] == 1 and info["hasMorphTargets"]  # biharmonic: negative weights
    face = read_gltf(path)
    store = app.state.store
    mesh = store.mesh(pid)
    # in metres in the file (the sample's mesh_units: cm), back in centimetres to float32 rounding
    assert face.units == "cm"
    np.testing.assert_allclose(face.mesh.vertices, mesh.vertices, rtol=2.4e-7)
    np.testing.assert_array_equal(face.mesh.faces, mesh.faces)
    assert face.points.to_json() == store.landmarks(pid)
    np.testing.assert_allclose(face.weights.dense(), store.rig(pid).dense(), atol=1e-6)
    # the take is the animation named after it, retargeted and timed as the player plays it
    (clip,) = face.clips
    d, times = played(app, pid, take["id"])
    # every frame of the 60-frame take: the neutral comes from its first 0.5 s, none is dropped
    assert clip.name == "smile" and clip.n_frames == len(times) == 60
    np.testing.assert_allclose(clip.times, times, atol=1e-6)
    np.testing.assert_allclose(clip.displacements, d, atol=1e-5)
    assert np.abs(d).max() > 0.1


def test_an_import_of_the_export_is_the_same_project(app, client, sample, exported):
    pid, take = sample
    r = import_glb(client, exported[1].read_bytes(), "sample.glb")
    assert r.status_code == 201, r.text
    answer = r.json()
    assert answer["deformation"] == "morph" and answer["animations"] == ["smile"]
    new = answer["project"]
    assert new["id"] != pid and new["name"] == "sample" and new["rig"] == {"method": "biharmonic"}
    assert client.get(f"/api/projects/{new['id']}").json() == new
    assert new["settings"]["mesh_units"] == "cm"
    (got, got_faces), (want, want_faces) = mesh_arrays(client, new["id"]), mesh_arrays(client, pid)
    np.testing.assert_allclose(got, want, rtol=2.4e-7)   # through metres: float32 rounding
    np.testing.assert_array_equal(got_faces, want_faces)
    assert client.get(f"/api/projects/{new['id']}/landmarks").json() == \
        client.get(f"/api/projects/{pid}/landmarks").json()
    store = app.state.store
    np.testing.assert_allclose(store.rig(new["id"]).dense(), store.rig(pid).dense(), atol=1e-6)
    assert client.get(f"/api/projects/{new['id']}/takes").json() == []  # animations are not takes
    named = import_glb(client, exported[1].read_bytes(), "sample.glb", name="  Copy ").json()
    assert named["project"]["name"] == "Copy"


def test_a_painted_ellipsoid_rig_exports_as_a_skin(app, client, sample, exported):
    """The rig in use is exported, painted rows included; a joint-based rig is a glTF skin."""
    pid, take = sample
    new = import_glb(client, exported[1].read_bytes(), "sample.glb").json()["project"]["id"]
    job = client.post(f"/api/projects/{new}/rig", json={"method": "ellipsoid"}).json()
    job = wait_job(client, job["id"], poll_s=0.05)
    assert job["state"] == "done", job
    store = app.state.store
    automatic = store.rig(new)
    vertex = int(np.flatnonzero(automatic.weights[:, 0] > 0.2)[0])
    version = client.get(f"/api/projects/{new}/rig").json()["version"]
    r = client.patch(f"/api/projects/{new}/rig/weights", json={
        "version": version, "vertices": [vertex], "indices": [automatic.indices[vertex].tolist()],
        "weights": [(0.5 * automatic.weights[vertex]).tolist()]})  # half as much motion
    assert r.status_code == 200 and r.json()["painted_vertices"] == 1, r.text
    painted = store.rig(new)
    assert not np.allclose(painted.dense()[vertex], automatic.dense()[vertex])
    client.post(f"/api/projects/{new}/takes", files={"file": ("smile.npy", npy_bytes(
        store.take(pid, take["id"]).points))}, data={"layout": "ibug68", "fps": str(FPS)})
    r = export(client, new, takes="all")
    assert r.status_code == 200, r.text
    info = assert_valid_gltf(write(r.content, exported[1].parent / "ellipsoid.glb"))["info"]
    assert info["hasSkins"] and not info["hasMorphTargets"] and info["animationCount"] == 1
    face = read_gltf(r.content)
    assert face.deformation == "skin"
    np.testing.assert_allclose(face.weights.dense(), painted.dense(), atol=1e-6)


def test_drive_muscles_exports_the_muscles_animated_by_the_takes_contractions(app, client, sample, exported):
    """drive=muscles: a morph target per muscle and a jaw joint, each frame the played form
    of the contractions the muscle IK solves from the take as the player plays it."""
    pid, take = sample
    r = export(client, pid, takes="all", drive="muscles")
    assert r.status_code == 200, r.text
    info = assert_valid_gltf(write(r.content, exported[1].parent / "muscles.glb"))["info"]
    assert info["hasSkins"] and info["hasMorphTargets"] and info["animationCount"] == 1
    store = app.state.store
    mesh = store.mesh(pid)
    points = landmarks_from_json(store.landmarks(pid), mesh.vertices, mesh.faces)
    model = MuscleFace.from_json(client.get(f"/api/projects/{pid}/muscles").json(), mesh.vertices)
    d, times = played(app, pid, take["id"])
    contractions = MuscleDrive(model, points).contractions(d)
    gltf = GltfDocument(r.content, "muscles.glb", None)
    assert gltf.doc.meshes[0].extras["targetNames"][:model.n_muscles] == list(model.names[:-1])
    (instance,) = mesh_instances(gltf)
    channels = animation_channels(gltf, gltf.doc.animations[0])
    k = int(np.argmax(np.abs(contractions[:, :-1]).sum(1)))      # the take's widest frame
    at = times[k:k + 1]
    drawn = posed_vertices(gltf, instance, np.arange(mesh.n_vertices),
                           node_transforms(gltf, gltf.doc.nodes, channels, at),
                           animated_weights(gltf, channels, at), at)[0] / 0.01   # metres to cm
    np.testing.assert_allclose(drawn - mesh.vertices,
                               played_displacements(muscle_morphs(model), model.rest, contractions[k]),
                               atol=1e-4)
    r = export(client, pid, drive="bones")
    assert r.status_code == 422 and "drive" in r.text


def write(data: bytes, path):
    path.write_bytes(data)
    return path


def test_conditioning_regions_and_takes_chosen(app, client, sample):
    """settings and regions reach the retargeting; takes are chosen by id, in order, and a
    take exported twice gets a numbered name."""
    pid, take = sample
    settings = '{"neutral": {"mode": "frame", "frame": 0}, "head_pose": "keep", "filter": "none"}'
    r = export(client, pid, takes=f"{take['id']},{take['id']}", settings=settings, regions="mouth")
    assert r.status_code == 200, r.text
    (clip,) = read_gltf(r.content).clips  # one take, named once
    d, times = played(app, pid, take["id"], {"neutral": {"mode": "frame", "frame": 0},
                                              "head_pose": "keep", "filter": "none"})
    assert clip.n_frames == len(times) == 60
    mouth = get_layout("ibug68").region_mask("mouth")
    np.testing.assert_allclose(clip.displacements[:, mouth], d[:, mouth], atol=1e-5)
    assert not clip.displacements[:, ~mouth].any() and np.abs(d[:, ~mouth]).max() > 0.05
    assert read_gltf(export(client, pid).content).clips == ()
    second = client.post(f"/api/projects/{pid}/takes", files={"file": ("smile.npy", npy_bytes(
        app.state.store.take(pid, take["id"]).points))}, data={"layout": "ibug68", "fps": "30"}).json()
    clips = read_gltf(export(client, pid, takes=f"{second['id']},{take['id']}").content).clips
    assert [c.name for c in clips] == ["smile", "smile (2)"]
    client.delete(f"/api/projects/{pid}/takes/{second['id']}")


def test_form_skin_rate_and_key_tolerance(app, client, sample, exported, tmp_path):
    """form=skin: a one-set skin a viewer draws as the fitted weights say, its error in the
    X-Retarget-Fit header and the file; rate and key_tolerance: keys on the grid, fewer of
    them, within the tolerance of the take; bad values are refused with the allowed ones."""
    pid, take = sample
    r = export(client, pid, takes="all", form="skin", rate="24", key_tolerance="0.05")
    assert r.status_code == 200, r.text
    path = tmp_path / "skin.glb"
    path.write_bytes(r.content)
    assert_valid_gltf(path)
    fit = json.loads(r.headers["x-retarget-fit"])
    gltf = GltfDocument(r.content, "skin", None)
    assert fit == gltf.doc.scenes[0].extras["retarget"]["fit"]
    d, times = played(app, pid, take["id"])
    grid = times[0] + np.arange(int((times[-1] - times[0]) * 24 + 1e-6) + 1) / 24
    assert fit["from"] == "morph" and 0 < fit["rms_relative"] < 0.1 and fit["frames"] == len(grid) == 48
    assert len(r.content) < len(exported[0].content) / 4
    attributes = vars(gltf.doc.meshes[0].primitives[0].attributes)
    assert attributes["JOINTS_0"] is not None and attributes.get("JOINTS_1") is None
    face = read_gltf(path)
    assert face.deformation == "skin"
    (clip,) = face.clips
    # the keys sit on the 24 fps grid; each joint within 0.05 mm (metres in the file, cm back)
    # of the take resampled there
    assert set(np.round(clip.times * 24, 3)) <= set(np.round(grid * 24, 3))
    resampled = np.stack([[np.interp(grid, times, d[:, i, a]) for a in range(3)] for i in range(68)], -1)
    joints = np.stack([[np.interp(grid, clip.times, clip.displacements[:, i, a]) for a in range(3)]
                       for i in range(68)], -1)
    assert np.abs(joints - resampled).max() <= 0.005 + 1e-5
    assert "X-Retarget-Fit" not in exported[0].headers
    for params, reason in [({"rate": "23"}, "24"), ({"key_tolerance": "-1"}, "greater than or equal to 0"),
                           ({"key_tolerance": "11"}, "less than or equal to 10"), ({"form": "joints"}, "skin"),
                           ({"form": "skin", "drive": "muscles"}, "form=skin shapes the rig's export")]:
        r = export(client, pid, **params)
        assert r.status_code == 422 and reason in str(r.json()["detail"]), (params, r.text)


def test_export_refusals(client, sample):
    pid, take = sample
    cases = [
        ({"takes": "nosuchtake0000"}, 404, "nosuchtake0000"),
        ({"takes": take["id"], "settings": "{neutral"}, 422, "query parameter 'settings' is not JSON"),
        ({"takes": take["id"], "settings": '{"speed": 2}'}, 422, "speed"),
        ({"takes": take["id"], "regions": "tail"}, 422, "tail"),
        ({"takes": take["id"], "settings": '{"neutral": {"mode": "first_seconds", "seconds": 9}}'},
         422, "take 'smile': the take (1.967 s) ends before its neutral capture"),
    ]
    for params, code, reason in cases:
        r = export(client, pid, **params)
        assert r.status_code == code and reason in r.json()["detail"], (params, r.text)
    empty = client.post("/api/projects", json={"name": "empty"}).json()["id"]
    r = export(client, empty)
    assert r.status_code == 409 and "has no mesh yet" in r.json()["detail"]
    box = trimesh.creation.box().export(file_type="obj").encode()
    client.put(f"/api/projects/{empty}/mesh", files={"file": ("box.obj", box)})
    r = export(client, empty)
    assert r.status_code == 409 and "has no landmarks yet" in r.json()["detail"]
    client.put(f"/api/projects/{empty}/landmarks", json={"vertex_indices": [0, 1, 2]})
    r = export(client, empty)
    assert r.status_code == 409 and "has no rig yet" in r.json()["detail"]
    client.delete(f"/api/projects/{empty}")


def test_import_refusals_make_no_project(client, exported, tmp_path):
    data = exported[1].read_bytes()
    before = client.get("/api/projects").json()
    box = trimesh.creation.box().export(file_type="glb")
    cases = [
        (("face.obj", data), 415, "upload one of: .glb"),
        (("face.glb", b""), 422, "'face.glb' is empty"),
        (("face.glb", b"solid ascii"), 422, "'face.glb' cannot be imported (only a .glb exported by "
                                            "this app can): the file is not a GLB file"),
        (("box.glb", box), 422, "'box.glb' cannot be imported (only a .glb exported by this app "
                                "can): the file: expected one root node holding the feature joints"),
        (("cut.glb", data[:len(data) // 2]), 422, "'cut.glb' cannot be imported (only a .glb "
                                                  "exported by this app can): the file is truncated"),
        (("bad.glb", data[:12] + b"\xff" * (len(data) - 12)), 422,
         "'bad.glb' cannot be imported (only a .glb exported by this app can): could not read the "
         "file as glTF"),
    ]
    for (name, body), code, reason in cases:
        r = import_glb(client, body, name)
        assert r.status_code == code and reason in r.json()["detail"], (name, r.text)
    small = TestClient(create_app(tmp_path / "small", sample=False, max_upload_bytes=len(data) - 1))
    r = import_glb(small, data)
    assert r.status_code == 413 and "over the limit" in r.json()["detail"]
    few = TestClient(create_app(tmp_path / "few", sample=False, max_vertices=1000))
    r = import_glb(few, data)
    assert r.status_code == 422 and "8430 vertices, over the server's limit of 1000" in r.json()["detail"]
    for other in (small, few):
        assert other.get("/api/projects").json() == []
    assert client.get("/api/projects").json() == before
