"""The mesh's unit and the export's (issue 19): guessed at upload and stored in the project's
settings (``mesh_units``), changed by PATCH (a bad unit is 422 with the reason), and the
export in metres from it by default, ``?units=keep`` for the mesh's own numbers; with "turn
the head" on, the take's head rotations turn a ``head`` node."""

import io

import numpy as np
import pytest

from retarget.gltf import read_gltf
from retarget.gltf.document import GltfDocument
from retarget.mesh import mesh_from_arrays, save_mesh
from retarget.sample_face import sample_face


def obj_bytes(vertices, faces, tmp_path, name="face.obj") -> bytes:
    path = tmp_path / name
    save_mesh(mesh_from_arrays(vertices, faces), path)
    return path.read_bytes()


def positions(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """The POSITION accessor's (min, max) of an exported .glb."""
    gltf = GltfDocument(data, "export", None)
    accessor = gltf.doc.accessors[gltf.doc.meshes[0].primitives[0].attributes.POSITION]
    return np.array(accessor.min), np.array(accessor.max)


@pytest.mark.parametrize("factor, unit", [(10.0, "mm"), (0.01, "m")])
def test_the_unit_is_guessed_at_upload_and_changed(client, tmp_path, factor, unit):
    f = sample_face(1)
    pid = client.post("/api/projects", json={"name": f"units {unit}"}).json()["id"]
    r = client.put(f"/api/projects/{pid}/mesh",
                   files={"file": ("face.obj", obj_bytes(f.vertices * factor, f.faces, tmp_path))})
    assert r.status_code == 200, r.text
    settings = r.json()["settings"]
    assert settings["mesh_units"] == unit and settings["mesh_units_guess"]["unit"] == unit
    assert settings["mesh_units_guess"]["size"] == pytest.approx(19.27 * factor, rel=1e-3)
    r = client.patch(f"/api/projects/{pid}", json={"settings": {"mesh_units": "in"}})
    assert r.status_code == 200 and r.json()["settings"]["mesh_units"] == "in"
    assert client.get(f"/api/projects/{pid}").json()["settings"]["mesh_units"] == "in"
    r = client.patch(f"/api/projects/{pid}", json={"settings": {"mesh_units": "furlong"}})
    assert r.status_code == 422
    assert r.json()["detail"] == "mesh units must be one of m, cm, mm, in; got 'furlong'"
    assert client.get(f"/api/projects/{pid}").json()["settings"]["mesh_units"] == "in"


def test_the_export_is_in_metres_unless_kept(client, sample_id):
    mesh_units = client.get(f"/api/projects/{sample_id}").json()["settings"].get("mesh_units")
    assert mesh_units in ("cm", None)                      # the sample face: centimetres
    v = sample_face(1).vertices
    metres = client.get(f"/api/projects/{sample_id}/export.glb")
    assert metres.status_code == 200, metres.text
    low, high = positions(metres.content)
    np.testing.assert_allclose(low, 0.01 * v.min(0), rtol=1e-6)
    np.testing.assert_allclose(high, 0.01 * v.max(0), rtol=1e-6)
    kept = client.get(f"/api/projects/{sample_id}/export.glb", params={"units": "keep"})
    np.testing.assert_allclose(positions(kept.content)[1], v.max(0), rtol=1e-6)
    assert read_gltf(kept.content).units == read_gltf(metres.content).units == "cm"
    r = client.get(f"/api/projects/{sample_id}/export.glb", params={"units": "ft"})
    assert r.status_code == 422 and "units" in r.text
    # the unit the user chose is the one the export scales from
    client.patch(f"/api/projects/{sample_id}", json={"settings": {"mesh_units": "mm"}})
    try:
        low, high = positions(client.get(f"/api/projects/{sample_id}/export.glb").content)
        np.testing.assert_allclose(high, 0.001 * v.max(0), rtol=1e-6)
    finally:
        client.patch(f"/api/projects/{sample_id}", json={"settings": {"mesh_units": mesh_units}})


def test_turn_the_head_exports_a_head_node(client, sample_id):
    from tests.unit.test_export_head import turning_take

    take, _ = turning_take(20)
    buffer = io.BytesIO()
    np.save(buffer, take.points)
    r = client.post(f"/api/projects/{sample_id}/takes", files={"file": ("turn.npy", buffer.getvalue())},
                    data={"layout": "ibug68", "fps": "30"})
    assert r.status_code == 201, r.text
    take_id = r.json()["id"]
    settings = '{"neutral": {"mode": "frame", "frame": 0}, "apply_rotation": true}'
    for drive in ("points", "muscles"):
        data = client.get(f"/api/projects/{sample_id}/export.glb",
                          params={"takes": take_id, "settings": settings, "drive": drive}).content
        gltf = GltfDocument(data, "turn", None)
        head = gltf.doc.scenes[0].extras["retarget"]["head"]
        paths = {(c.target.node, c.target.path) for c in gltf.doc.animations[0].channels}
        assert (head["node"], "rotation") in paths, drive
    points = client.get(f"/api/projects/{sample_id}/export.glb", params={"takes": take_id, "settings": settings})
    assert read_gltf(points.content).clips[0].head_rotations.shape == (20, 4)
    plain = GltfDocument(client.get(f"/api/projects/{sample_id}/export.glb", params={"takes": take_id}).content,
                         "plain", None)
    assert "head" not in plain.doc.scenes[0].extras["retarget"]
    client.delete(f"/api/projects/{sample_id}/takes/{take_id}")

