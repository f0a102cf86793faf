"""Units (issue 19): a mesh's unit guessed from its size (`retarget.units`), and the glTF
export in metres by default, its scale recorded and undone on reading (`retarget.gltf.units`).

The sample face is in centimetres (19.3 across): exported in metres, every length in the
file is 0.01 of the library's, and read back it is the same project in centimetres.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from retarget.cli import main
from retarget.clips import clip_at_rate
from retarget.errors import RetargetError
from retarget.gltf import export_gltf, read_gltf
from retarget.gltf.animation import drawn_vertices
from retarget.gltf.document import GltfDocument
from retarget.landmarks import from_vertex_indices
from retarget.layouts import get_layout
from retarget.mesh import mesh_from_arrays, save_mesh
from retarget.sample_face import demo_weights, posed_vertices, sample_face
from retarget.skin import skin_displacements
from retarget.units import guess_units, mesh_units, unit_scale
from retarget.weights import compute_weights
from tests.gltf_check import assert_valid_gltf

FPS = 30.0


@pytest.fixture(scope="module")
def face():
    f = sample_face(1)
    mesh = mesh_from_arrays(f.vertices, f.faces, uv=f.uv, name="face")
    points = from_vertex_indices(f.landmarks68, mesh.n_vertices, "ibug68")
    posed = posed_vertices(f, demo_weights(20, FPS))[:, f.landmarks68]
    clip = clip_at_rate("demo", posed - f.vertices[f.landmarks68], FPS)
    rigs = {m: compute_weights(m, mesh.vertices, mesh.faces, points, get_layout("ibug68"))
            for m in ("ellipsoid", "rbf")}
    return {"f": f, "mesh": mesh, "points": points, "clip": clip, "rigs": rigs}


def test_the_unit_is_guessed_from_the_face_size(face):
    v = face["mesh"].vertices                                 # 19.3 cm tall
    assert guess_units(v) == "cm"
    assert guess_units(v / 100) == "m" and guess_units(v * 10) == "mm"
    assert guess_units(v / 100 * 0.5) == "m" and guess_units(v * 3) == "cm"   # a head and shoulders
    assert guess_units(v / 2.54) == "cm"                      # inches are never guessed (ambiguous)
    assert guess_units(np.zeros((3, 3))) == "m"
    assert mesh_units("in", v) == "in" and mesh_units("guess", v * 10) == "mm"
    assert unit_scale("in") == 0.0254
    with pytest.raises(RetargetError, match="mesh units must be one of m, cm, mm, in; got 'furlong'"):
        mesh_units("furlong", v)


def _gltf(data) -> GltfDocument:
    return GltfDocument(data, "export", None)


def _drawn(gltf, t) -> np.ndarray:
    """(V, 3) what a glTF viewer draws at time t of the first animation, file units."""
    return drawn_vertices(gltf, [t])[0]


@pytest.mark.parametrize("method", ["ellipsoid", "rbf"])
def test_the_export_is_in_metres_and_reads_back_in_centimetres(face, method, tmp_path):
    mesh, points, clip, weights = face["mesh"], face["points"], face["clip"], face["rigs"][method]
    path = tmp_path / "face.glb"
    path.write_bytes(export_gltf(mesh, points, weights, [clip]))
    assert_valid_gltf(path)
    gltf = _gltf(path.read_bytes())
    recorded = gltf.doc.scenes[0].extras["retarget"]
    assert {k: recorded[k] for k in ("source_units", "scale_to_metres", "scale")} == {
        "source_units": "cm", "scale_to_metres": 0.01, "scale": 0.01}
    position = gltf.doc.accessors[gltf.doc.meshes[0].primitives[0].attributes.POSITION]
    np.testing.assert_allclose(position.min, 0.01 * mesh.vertices.min(0), rtol=1e-6)
    np.testing.assert_allclose(position.max, 0.01 * mesh.vertices.max(0), rtol=1e-6)
    # joint translations in metres
    neutral = points.positions(mesh.vertices)
    joints = np.array([gltf.doc.nodes[2 + i].translation for i in range(points.n_points)])
    np.testing.assert_allclose(joints, 0.01 * neutral, atol=1e-8)
    # a posed vertex in the file is the library's posed vertex times the scale (morph
    # targets, or the skin's joint motion, scaled alike)
    k = 12
    expected = mesh.vertices + skin_displacements(weights, clip.displacements[k])
    drawn = _drawn(gltf, clip.times[k])
    assert np.abs(drawn - 0.01 * expected).max() < 1e-7 * 20
    assert np.abs(expected - mesh.vertices).max() > 0.1
    # read back: centimetres again
    back = read_gltf(path)
    assert back.units == "cm"
    np.testing.assert_allclose(back.mesh.vertices, mesh.vertices, rtol=2.4e-7)
    np.testing.assert_allclose(back.clips[0].displacements, clip.displacements, atol=1e-5)
    np.testing.assert_allclose(back.weights.dense(), weights.dense(), atol=1e-6)


def test_units_keep_and_a_unit_given(face):
    mesh, points, weights = face["mesh"], face["points"], face["rigs"]["ellipsoid"]
    kept = _gltf(export_gltf(mesh, points, weights, units="keep"))
    assert kept.doc.scenes[0].extras["retarget"]["scale"] == 1.0
    assert kept.doc.scenes[0].extras["retarget"]["source_units"] == "cm"
    np.testing.assert_array_equal(kept.accessor(kept.doc.meshes[0].primitives[0].attributes.POSITION),
                                  mesh.vertices.astype(np.float32))
    inches = export_gltf(mesh, points, weights, mesh_units="in")
    assert read_gltf(inches).units == "in"
    position = _gltf(inches).doc.accessors[0]
    np.testing.assert_allclose(position.max, 0.0254 * mesh.vertices.max(0), rtol=1e-6)
    np.testing.assert_allclose(read_gltf(inches).mesh.vertices, mesh.vertices, rtol=2.4e-7)
    with pytest.raises(RetargetError, match="export units must be one of m, keep; got 'ft'"):
        export_gltf(mesh, points, weights, units="ft")


def test_cli_units_options(face, tmp_path, capsys):
    f = face["f"]
    save_mesh(mesh_from_arrays(f.vertices * 10, f.faces, name="mm"), tmp_path / "mm.obj")
    (tmp_path / "t0.json").write_text(json.dumps({"vertex_indices": list(map(int, f.landmarks68)),
                                                  "layout": "ibug68"}))
    common = ["export-gltf", "--mesh", str(tmp_path / "mm.obj"), "--landmarks", str(tmp_path / "t0.json"),
              "--deformer", "ellipsoid", "--quiet"]
    assert main([*common, "--out", str(tmp_path / "m.glb")]) == 0
    assert "in metres (the mesh in mm, x0.001)" in capsys.readouterr().out
    metres = _gltf((tmp_path / "m.glb").read_bytes())
    np.testing.assert_allclose(metres.doc.accessors[0].max, 0.01 * f.vertices.max(0), rtol=1e-6)
    assert main([*common, "--out", str(tmp_path / "k.glb"), "--units", "keep", "--mesh-units", "cm"]) == 0
    assert "in the mesh's cm" in capsys.readouterr().out
    assert read_gltf(tmp_path / "k.glb").units == "cm"
    assert main([*common, "--out", str(tmp_path / "x.glb"), "--mesh-units", "ft"]) == 2
    assert "--mesh-units" in capsys.readouterr().err
