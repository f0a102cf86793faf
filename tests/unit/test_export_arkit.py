"""ARKit weights as output (issue 16 §3): ``export-gltf --drive arkit`` (the 52 shapes as
named, sparse morph targets animated by the solved weights), ``transfer --drive arkit``,
and ``--weights-out`` as Live Link Face CSV.

What a glTF viewer draws is evaluated from the file by `retarget.gltf.animation` (the
specification's morphing and animation sampling; no code shared with the exporter). The take
is an ARKit take: known weights played through the shipped reference face
(`retarget.sources.arkit_curves`), retargeted onto the built-in sample face and solved back.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from retarget.arkit.clip import ArkitClip
from retarget.arkit.reference import ARKIT_NAMES, arkit_reference
from retarget.arkit.shapes import ArkitShapes, arkit_shapes
from retarget.cli import main
from retarget.errors import RetargetError
from retarget.gltf import export_arkit_gltf, read_gltf
from retarget.gltf.animation import animation_channels, drawn_vertices, mesh_instances
from retarget.gltf.arkit import TOLERANCE, arkit_tolerance
from retarget.gltf.document import GltfDocument
from retarget.landmarks import from_vertex_indices
from retarget.layouts import get_layout
from retarget.mesh import mesh_from_arrays, save_mesh
from retarget.sample_face import sample_face
from retarget.sources.arkit_curves import LIVE_LINK_COLUMNS, ArkitCurves, arkit_curves, live_link_csv
from retarget.sources.files import read_take
from retarget.weights import compute_weights
from tests.gltf_check import assert_valid_gltf

FPS = 30.0
K = {name: k for k, name in enumerate(ARKIT_NAMES)}


def arkit_take_weights(n_frames: int = 24) -> np.ndarray:
    """(F, 52) a second of face: the jaw opening and closing, a smile, a blink, brows up."""
    u = np.linspace(0.0, 1.0, n_frames)
    w = np.zeros((n_frames, 52))
    w[:, K["jawOpen"]] = 0.6 * np.sin(np.pi * u) ** 2
    w[:, K["mouthSmileLeft"]] = w[:, K["mouthSmileRight"]] = 0.7 * np.clip(np.sin(2 * np.pi * u), 0, 1)
    w[:, K["eyeBlinkLeft"]] = np.clip(np.cos(2 * np.pi * u), 0, 1)
    w[:, K["browInnerUp"]] = 0.5
    return w


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The sample face (OBJ, landmarks), its ARKit shapes made through an ellipsoid rig (local:
    most targets sparse; fast), and an ARKit take in Live Link Face CSV read as source points
    (S0: the reference neutral, S: the reference face making each frame)."""
    d = tmp_path_factory.mktemp("arkit_export")
    f = sample_face()
    mesh = mesh_from_arrays(f.vertices, f.faces, uv=f.uv, name="target")
    save_mesh(mesh, d / "target.obj")
    (d / "t0.json").write_text(json.dumps({"vertex_indices": np.asarray(f.landmarks68).tolist(),
                                           "layout": "ibug68"}))
    points = from_vertex_indices(f.landmarks68, len(f.vertices), "ibug68")
    rig = compute_weights("ellipsoid", f.vertices, f.faces, points, get_layout("ibug68"))
    rig.save(d / "rig.npz")
    shapes = arkit_shapes(f.vertices, f.faces, points, "ibug68", rig)
    shapes.save(d / "shapes.npz")
    weights = arkit_take_weights()
    text = live_link_csv(ArkitCurves(weights, FPS, None, None, {}))
    (d / "take.csv").write_text(text)
    take = read_take(text.encode(), filename="take.csv", fps=FPS)
    np.save(d / "s0.npy", arkit_reference("ibug68").neutral)
    np.save(d / "s.npy", take.points)
    return {"dir": d, "face": f, "mesh": mesh, "shapes": shapes, "weights": weights,
            "obj": d / "target.obj", "t0": d / "t0.json", "arkit": d / "shapes.npz", "rig": d / "rig.npz",
            "s0": d / "s0.npy", "s": d / "s.npy"}


@pytest.fixture(scope="module")
def exported(files):
    """``export-gltf --drive arkit --arkit SHAPES.npz`` of the take, with ``--weights-out``:
    (the .glb, the weights read back from the CSV)."""
    d = files["dir"]
    assert main(["export-gltf", "--mesh", str(files["obj"]), "--landmarks", str(files["t0"]),
                 "--out", str(d / "face.glb"), "--drive", "arkit", "--arkit", str(files["arkit"]),
                 "--source-neutral", str(files["s0"]), "--source-frames", str(files["s"]),
                 "--fps", str(FPS), "--weights-out", str(d / "w.csv"), "--quiet"]) == 0
    # under a second: the timecodes cannot show the rate, which the reader is told
    curves = arkit_curves((d / "w.csv").read_text(), "csv", "w.csv", fps=FPS)
    return d / "face.glb", curves


def _viewer(path, times) -> np.ndarray:
    """(F, V, 3) float64 positions a glTF viewer draws at `times` of the first animation, in
    the mesh's units (the file's, in metres, over the export's recorded scale)."""
    gltf = GltfDocument(path.read_bytes(), path.name, None)
    return drawn_vertices(gltf, times) / gltf.doc.scenes[0].extras["retarget"]["scale"]


def test_the_export_is_valid_with_52_named_targets_and_their_animation(exported):
    path, curves = exported
    info = assert_valid_gltf(path)["info"]
    assert info["animationCount"] == 1 and info["hasMorphTargets"] and not info["hasSkins"]
    doc = GltfDocument(path.read_bytes(), path.name, None).doc
    (mesh,) = doc.meshes
    (primitive,) = mesh.primitives
    assert mesh.extras["targetNames"] == list(ARKIT_NAMES) == primitive.extras["targetNames"]
    assert len(primitive.targets) == 52 and mesh.weights == [0.0] * 52
    assert len(doc.nodes) == 1 and not doc.skins
    (animation,) = doc.animations
    assert animation.name == "s"
    (channel,) = animation.channels
    assert (channel.target.node, channel.target.path) == (0, "weights")
    assert animation.samplers[0].interpolation == "LINEAR"
    assert doc.accessors[animation.samplers[0].output].count == 52 * len(curves.weights)
    assert doc.scenes[0].extras["retarget"]["deformation"] == "arkit"
    with pytest.raises(RetargetError, match="is an ARKit export"):
        read_gltf(path)


def test_targets_are_sparse_where_local_and_cost_at_most_the_tolerance(files, exported):
    """Each target holds only the vertices its shape moves by more than the tolerance (1e-4 of
    the face's size): the file is well under the dense size, and every target is its shape to
    within the tolerance."""
    path, _ = exported
    shapes, mesh = files["shapes"], files["mesh"]
    gltf = GltfDocument(path.read_bytes(), path.name, None)
    (instance,) = mesh_instances(gltf)
    scale = gltf.doc.scenes[0].extras["retarget"]["scale"]
    assert scale == 0.01                                                # centimetres to metres
    targets = instance["targets"] / scale                              # (52, V, 3) mesh units
    tolerance = arkit_tolerance(mesh.vertices)
    size = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
    assert tolerance == pytest.approx(TOLERANCE * size)
    error = np.linalg.norm(targets - shapes.deltas, axis=2).max(axis=1)  # (52,)
    assert error.max() <= tolerance * (1 + 1e-5) + 1e-6 * size        # + float32 rounding in metres
    accessors = [gltf.doc.accessors[t["POSITION"]] for t in gltf.doc.meshes[0].primitives[0].targets]
    sparse = [a.sparse.count if a.sparse is not None else (0 if a.bufferView is None else a.count)
              for a in accessors]
    assert sum(a.bufferView is None for a in accessors) == 52          # all sparse (or all zero)
    assert sparse[K["tongueOut"]] == 0 and 0 < sparse[K["eyeBlinkLeft"]] < 0.3 * mesh.n_vertices
    dense = 52 * mesh.n_vertices * 12
    n_bytes = path.stat().st_size
    print(f"ARKit export of {mesh.n_vertices} vertices: {n_bytes / 2**20:.2f} MiB, dense targets alone "
          f"{dense / 2**20:.2f} MiB; {sum(sparse)} of {52 * mesh.n_vertices} target rows kept; "
          f"largest target error {error.max() / size:.1e} of the face size")
    assert n_bytes < 0.5 * dense
    # tolerance 0 keeps every vertex that moves: exact to float32
    exact = export_arkit_gltf(mesh, shapes, tolerance=0.0, units="keep")
    (instance,) = mesh_instances(GltfDocument(exact, "exact", None))
    assert np.abs(instance["targets"] - shapes.deltas).max() == 0.0


def test_every_frame_plays_the_solved_weights(files, exported):
    """At its keys and between them a viewer draws ``v0 + sum_k w_k(t) delta_k`` of the solved
    weights (`ArkitShapes.posed`), to the targets' tolerance."""
    path, curves = exported
    shapes, v0 = files["shapes"], files["mesh"].vertices
    n = len(curves.weights)
    times = np.array([0.0, 5.0, 11.5, n - 1.0]) / FPS
    drawn = _viewer(path, times)
    solved = np.stack([np.interp(times * FPS, np.arange(n), curves.weights[:, k]) for k in range(52)], 1)
    expected = shapes.posed(v0, solved)
    bound = arkit_tolerance(v0) * solved.sum(axis=1).max() + 1e-5
    assert np.abs(drawn - expected).max() < bound
    assert np.abs(expected - v0).max() > 50 * bound                   # the face moves


def test_live_link_csv_round_trip():
    """The writer is the reader's inverse: the same weights to float32, the head, the times, and
    Live Link Face's own column order (JawRight before JawLeft, MouthRight before MouthLeft)."""
    rng = np.random.default_rng(0)
    weights = rng.uniform(0, 1, (75, 52)) * (rng.random((75, 52)) < 0.3)
    head = rng.uniform(-0.4, 0.4, (75, 3))
    text = live_link_csv(ArkitCurves(weights, 30.0, None, head, {}))
    header = text.splitlines()[0].split(",")
    assert tuple(header) == LIVE_LINK_COLUMNS and len(header) == 63
    assert header[16:20] == ["JawForward", "JawRight", "JawLeft", "JawOpen"]
    assert header[23:25] == ["MouthRight", "MouthLeft"] and header[-9] == "HeadYaw"
    assert text.splitlines()[31].startswith("00:00:01:00.000,61,")
    back = arkit_curves(text, "csv", "w.csv")
    assert np.array_equal(back.weights.astype(np.float32), weights.astype(np.float32))
    assert np.array_equal(back.head.astype(np.float32), head.astype(np.float32))
    assert back.fps == 30.0 and not back.meta["fps_assumed"] and back.meta["format"] == "live_link_face"
    np.testing.assert_allclose(back.times, np.arange(75) / 30.0, atol=1e-9)
    # a take's own times, and a short take read at its rate
    times = np.cumsum(rng.uniform(0.01, 0.03, 10))
    short = arkit_curves(live_link_csv(ArkitCurves(weights[:10], 60.0, times, None, {})), "csv", "s", fps=60)
    np.testing.assert_allclose(short.times, times - times[0], atol=0.5e-3 / 60)
    assert not short.head.any()
    with pytest.raises(RetargetError, match="ARKit weights are in \\[0, 1\\]"):
        live_link_csv(ArkitCurves(weights * 2, 30.0, None, None, {}))
    with pytest.raises(RetargetError, match="shape \\(F, 52\\)"):
        live_link_csv(ArkitCurves(weights[:, :51], 30.0, None, None, {}))


def test_an_arkit_take_comes_back_as_its_weights(files, exported):
    """ARKit take in -> the reference face's points -> retargeted onto the sample face -> solved
    -> weights out (CSV, and the glTF's animation): the take's own weights come back."""
    path, curves = exported
    truth = files["weights"]
    error = np.abs(curves.weights - truth)
    on = truth > 0.05
    print(f"ARKit round trip: mean |weight error| {error.mean():.4f} over all 52 weights, "
          f"{error[on].mean():.4f} over the shapes that are on, max {error.max():.3f}")
    assert error.mean() < 0.005 and error[on].mean() < 0.03 and error.max() < 0.06
    np.testing.assert_allclose(curves.times, np.arange(len(truth)) / FPS, atol=1e-6)
    gltf = GltfDocument(path.read_bytes(), path.name, None)
    (channel,) = animation_channels(gltf, gltf.doc.animations[0])
    np.testing.assert_allclose(channel[3], curves.weights, atol=1e-6)


def test_transfer_drive_arkit_makes_the_shapes_and_writes_the_weights(files, tmp_path, capsys):
    """``transfer --drive arkit --rig RIG.npz`` makes the shapes through the rig (the fixture's:
    the same shapes), solves the take and writes the face they make and the weights."""
    assert main(["transfer", "--target-mesh", str(files["obj"]), "--target-landmarks", str(files["t0"]),
                 "--source-neutral", str(files["s0"]), "--source-frames", str(files["s"]),
                 "--out", str(tmp_path / "out.npy"), "--drive", "arkit", "--rig", str(files["rig"]),
                 "--weights-out", str(tmp_path / "w.csv"), "--quiet"]) == 0
    assert "with arkit" in capsys.readouterr().out
    curves = arkit_curves((tmp_path / "w.csv").read_text(), "csv", "w.csv", fps=30)
    assert np.abs(curves.weights - files["weights"]).mean() < 0.005
    v0 = files["mesh"].vertices
    out = np.load(tmp_path / "out.npy")
    assert out.shape == (len(files["weights"]), len(v0), 3) and out.dtype == np.float32
    np.testing.assert_allclose(out, files["shapes"].posed(v0, curves.weights), atol=1e-4)
    frame = int(np.argmax(curves.weights[:, K["jawOpen"]]))
    chin = files["face"].landmarks68[8]
    assert out[frame, chin, 1] - v0[chin, 1] < -1.0                   # the jaw opens by centimetres


def test_refusals_name_the_problem(files, tmp_path, capsys):
    shapes = files["shapes"]
    ArkitShapes(shapes.names, shapes.deltas[:, :100], shapes.at_points).save(tmp_path / "small.npz")
    np.savez(tmp_path / "names.npz", names=np.array(ARKIT_NAMES[::-1]), deltas=shapes.deltas,
             at_points=shapes.at_points)
    (tmp_path / "bare.json").write_text(json.dumps({"vertex_indices": np.asarray(files["face"].landmarks68).tolist()}))
    base = ["export-gltf", "--mesh", str(files["obj"]), "--landmarks", str(files["t0"]),
            "--out", str(tmp_path / "x.glb"), "--quiet"]
    source = ["--source-neutral", str(files["s0"]), "--source-frames", str(files["s"])]
    for extra, message in (
            (["--drive", "arkit", "--arkit", str(tmp_path / "small.npz")],
             "move 100 vertices but the mesh has 8430"),
            (["--drive", "arkit", "--arkit", str(tmp_path / "names.npz")], "Apple's order"),
            (["--drive", "arkit", "--arkit", str(tmp_path / "none.npz")], "does not exist"),
            (["--drive", "arkit", "--deformer", "rbf"], "drop --deformer"),
            (["--drive", "arkit", "--arkit", str(files["arkit"]), "--rig", str(files["rig"])],
             "drop --rig, or drop --arkit"),
            (["--arkit", str(files["arkit"])], "need --drive arkit"),
            (["--weights-out", str(tmp_path / "w.csv"), *source], "need --drive arkit"),
            (["--drive", "arkit", "--arkit", str(files["arkit"]), "--weights-out", str(tmp_path / "w.csv")],
             "give --source-neutral and --source-frames"),
            (["--drive", "arkit", "--weights-out", str(tmp_path / "no" / "w.csv"), *source],
             "does not exist")):
        assert main(base + extra) == 2, extra
        assert message in capsys.readouterr().err, extra
    assert main(["export-gltf", "--mesh", str(files["obj"]), "--landmarks", str(tmp_path / "bare.json"),
                 "--out", str(tmp_path / "x.glb"), "--drive", "arkit", "--quiet"]) == 2
    assert "needs the landmarks' layout" in capsys.readouterr().err
    assert not (tmp_path / "x.glb").exists() and not (tmp_path / "w.csv").exists()
    with pytest.raises(RetargetError, match="move 8430 vertices but the mesh has 100"):
        export_arkit_gltf(mesh_from_arrays(files["mesh"].vertices[:100], [[0, 1, 2]]), shapes)
    with pytest.raises(RetargetError, match="weights must have shape \\(F, 52\\)"):
        ArkitClip("bad", np.zeros((3, 5)), [0.0, 0.1, 0.2])
    with pytest.raises(RetargetError, match="finite and in \\[0, 1\\]"):
        ArkitClip("bad", np.full((1, 52), 1.5), [0.0])
