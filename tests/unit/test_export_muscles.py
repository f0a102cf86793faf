"""glTF export in muscle mode (issue 15): `retarget.gltf.write_muscles_gltf` and
``retarget export-gltf --drive muscles``.

What a glTF viewer draws is evaluated from the file by `retarget.gltf.animation` (the
specification's morphing then skinning, and its animation sampling; it shares no code with
the exporter) and must be the played form, `retarget.muscles.morphs.played_displacements`,
of each frame's contractions. Inputs: the built-in sample face driven by another identity.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from retarget.cli import main
from retarget.clips import ContractionClip
from retarget.errors import RetargetError
from retarget.gltf import export_muscles_gltf, read_gltf
from retarget.gltf.animation import drawn_vertices
from retarget.gltf.document import GltfDocument
from retarget.mesh import mesh_from_arrays, save_mesh
from retarget.muscles import place_muscles
from retarget.muscles.morphs import muscle_morphs, played_displacements
from retarget.sample_face import sample_face
from tests.gltf_check import assert_valid_gltf

FPS = 24.0
# neutral, jaw open, smile, smile with the jaw half open, brows up and an eye closed
EXPRESSIONS = ({}, {"jawOpen": 1.0}, {"mouthSmile_L": 1.0, "mouthSmile_R": 1.0},
               {"jawOpen": 0.5, "mouthSmile_L": 0.8, "mouthSmile_R": 0.8},
               {"browInnerUp": 1.0, "eyeBlink_R": 1.0})


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The target mesh, its landmarks, S0 and S of another identity posed with EXPRESSIONS."""
    d = tmp_path_factory.mktemp("muscles_gltf")
    target = sample_face()
    source = sample_face(identity=[1.5, -1.2, 1.0, 1.2, -1.0])
    save_mesh(mesh_from_arrays(target.vertices, target.faces, uv=target.uv, name="target"),
              d / "target.obj")
    (d / "t0.json").write_text(json.dumps({"vertex_indices": np.asarray(target.landmarks68).tolist(),
                                           "layout": "ibug68"}))
    w = np.array([[e.get(n, 0.0) for n in source.expression_names] for e in EXPRESSIONS])
    posed = source.vertices + np.einsum("fe,evd->fvd", w, source.expressions)
    np.save(d / "s0.npy", source.vertices[source.landmarks68])
    np.save(d / "s.npy", posed[:, source.landmarks68])
    return {"dir": d, "target": target, "mesh": d / "target.obj", "t0": d / "t0.json",
            "s0": d / "s0.npy", "s": d / "s.npy"}


@pytest.fixture(scope="module")
def exported(files):
    """``export-gltf --drive muscles`` of the take and ``transfer --drive muscles`` of the
    same take's contractions: (path of the .glb, (F, D) contractions, the model)."""
    d = files["dir"]
    common = ["--source-neutral", str(files["s0"]), "--source-frames", str(files["s"]),
              "--drive", "muscles", "--quiet"]
    assert main(["export-gltf", "--mesh", str(files["mesh"]), "--landmarks", str(files["t0"]),
                 "--out", str(d / "face.glb"), "--fps", str(FPS), *common]) == 0
    assert main(["transfer", "--target-mesh", str(files["mesh"]), "--target-landmarks", str(files["t0"]),
                 "--out", str(d / "out.npy"), "--contractions-out", str(d / "c.npy"), *common]) == 0
    target = files["target"]
    model = place_muscles(target.vertices, target.faces, target.vertices[target.landmarks68])
    return d / "face.glb", np.load(d / "c.npy"), model


def _viewer(path, times) -> np.ndarray:
    """(F, V, 3) float64 positions a glTF viewer draws at `times` of the first animation, in
    the mesh's units (the file's, in metres, over the export's recorded scale)."""
    gltf = GltfDocument(path.read_bytes(), path.name, None)
    return drawn_vertices(gltf, times) / gltf.doc.scenes[0].extras["retarget"]["scale"]


def test_the_export_is_valid_and_names_its_targets_after_the_muscles(exported):
    path, contractions, model = exported
    info = assert_valid_gltf(path)["info"]
    assert info["animationCount"] == 1 and info["hasMorphTargets"] and info["hasSkins"]
    gltf = GltfDocument(path.read_bytes(), path.name, None).doc
    morphs = muscle_morphs(model)
    names = gltf.meshes[0].extras["targetNames"]
    assert names == list(model.names[:-1]) + [f"{model.names[m]}*jaw" for m in morphs.corrective_of]
    assert "orbicularis_oris*jaw" in names and len(gltf.meshes[0].primitives[0].targets) == len(names)
    (skin,) = gltf.skins
    assert [gltf.nodes[j].name for j in skin.joints] == ["root", "jaw"]
    assert gltf.scenes[0].extras["retarget"]["scale"] == 0.01  # the centimetre face in metres
    np.testing.assert_allclose(gltf.nodes[skin.joints[1]].translation, 0.01 * model.jaw.hinge_right, atol=1e-7)
    assert gltf.animations[0].name == "s"


def test_every_frame_plays_the_played_form_of_its_contractions(exported, files):
    path, contractions, model = exported
    morphs = muscle_morphs(model)
    times = np.arange(len(EXPRESSIONS)) / FPS
    drawn = _viewer(path, times) - files["target"].vertices
    for k, c in enumerate(contractions):
        np.testing.assert_allclose(drawn[k], played_displacements(morphs, model.rest, c), atol=1e-4)
    # the take moves the jaw and the mouth, and the played form stays near the exact muscles
    assert contractions[1, -1] > 0.1 and np.abs(drawn[1]).max() > 0.3
    exact = np.load(files["dir"] / "out.npy") - files["target"].vertices
    assert np.sqrt(((drawn - exact) ** 2).sum() / (exact ** 2).sum()) < 0.1


def test_a_clip_keys_products_and_slerps_the_jaw_about_its_axis(files):
    """Between keys glTF interpolates the morph weights linearly and the jaw's quaternion
    by slerp (about one axis: the angle, linearly)."""
    target = files["target"]
    mesh = mesh_from_arrays(target.vertices, target.faces)
    model = place_muscles(target.vertices, target.faces, target.vertices[target.landmarks68])
    morphs = muscle_morphs(model)
    c = np.zeros((2, model.n_dof))
    c[1, -1] = model.limits[-1, 1]
    path = files["dir"] / "jaw.glb"
    path.write_bytes(export_muscles_gltf(mesh, morphs, [ContractionClip("jaw", c, [0.0, 1.0])]))
    half = _viewer(path, np.array([0.5]))[0] - target.vertices
    np.testing.assert_allclose(half, played_displacements(morphs, model.rest, c.mean(0)), atol=1e-4)


def test_refusals_name_the_problem(files, exported, capsys):
    d = files["dir"]
    base = ["export-gltf", "--mesh", str(files["mesh"]), "--landmarks", str(files["t0"]),
            "--out", str(d / "x.glb"), "--quiet"]
    for extra, message in ((["--drive", "muscles", "--rig", "rig.npz"], "drop --deformer and --rig"),
                           (["--drive", "muscles", "--deformer", "rbf"], "drop --deformer and --rig"),
                           (["--muscles", "m.json"], "--muscles needs --drive muscles"),
                           (["--drive", "muscles", "--muscles", str(d / "none.json")], "does not exist")):
        assert main(base + extra) == 2
        assert message in capsys.readouterr().err
    assert not (d / "x.glb").exists()
    path, contractions, model = exported
    with pytest.raises(RetargetError, match="is a muscle export"):
        read_gltf(path)
    mesh = mesh_from_arrays(model.rest, files["target"].faces)
    with pytest.raises(RetargetError, match="has 5 dofs but the muscles have 22"):
        export_muscles_gltf(mesh, muscle_morphs(model, correctives=False),
                            [ContractionClip("short", np.zeros((2, 5)), [0.0, 1.0])])
    with pytest.raises(RetargetError, match="contractions hold NaN"):
        ContractionClip("nan", np.full((1, 22), np.nan), [0.0])
