"""ARKit's 52 blendshapes: the shipped reference, shapes on the sample face, the weight
solver, ARKit curves as a take, and ``retarget arkit``. Runs without ../shared; the one
test that reads the ICT data skips when it is absent."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from retarget.arkit.reference import (ARKIT_NAMES, ICT_SOURCES, REFERENCE, arkit_index,
                                      arkit_reference)
from retarget.arkit.shapes import arkit_shapes
from retarget.arkit.solve import ANTAGONISTS, MIRROR_PAIRS, ArkitSolver
from retarget.cli import main
from retarget.errors import RetargetError
from retarget.landmarks import SurfacePoints, from_vertex_indices
from retarget.layouts import LAYOUTS, get_layout
from retarget.mesh import mesh_from_arrays, save_mesh
from retarget.pipeline import Retargeter
from retarget.sample_face import sample_face
from retarget.sources import arkit_curves as curves_module
from retarget.sources.arkit_curves import head_rotations
from retarget.sources.files import read_take
from retarget.weights import compute_weights

ICT = Path(__file__).resolve().parents[3] / "shared" / "data" / "ict_face" / "ict_face.npz"
K = {name: k for k, name in enumerate(ARKIT_NAMES)}


@pytest.fixture(scope="module")
def face():
    f = sample_face(1)
    points = from_vertex_indices(f.landmarks68, len(f.vertices), "ibug68")
    rig = compute_weights("rbf", f.vertices, f.faces, points, get_layout("ibug68"))
    return f, points, rig


@pytest.fixture(scope="module")
def shapes(face):
    f, points, rig = face
    return arkit_shapes(f.vertices, f.faces, points, "ibug68", rig)


# --- names and the reference -----------------------------------------------------------

def test_names_are_arkits_52_with_ict_sources():
    assert len(ARKIT_NAMES) == len(set(ARKIT_NAMES)) == 52
    assert ARKIT_NAMES[0] == "eyeBlinkLeft" and ARKIT_NAMES[7] == "eyeBlinkRight"
    assert ARKIT_NAMES[-1] == "tongueOut"
    assert ICT_SOURCES["mouthSmileLeft"] == ("mouthSmile_L",)
    assert ICT_SOURCES["eyeLookDownRight"] == ("eyeLookDown_R",)
    assert ICT_SOURCES["jawLeft"] == ("jawLeft",) and ICT_SOURCES["mouthRight"] == ("mouthRight",)
    assert ICT_SOURCES["browInnerUp"] == ("browInnerUp_L", "browInnerUp_R")
    assert ICT_SOURCES["tongueOut"] == ()
    # every ICT shape but none used twice: 53 ICT shapes make 51 ARKit ones
    used = [s for sources in ICT_SOURCES.values() for s in sources]
    assert len(used) == len(set(used)) == 53
    assert arkit_index("EyeBlinkLeft") == 0 and arkit_index("TONGUEOUT") == 51 and arkit_index("x") == -1


def test_reference_table_is_small_licensed_and_left_is_the_subjects_left():
    assert REFERENCE.stat().st_size < 400_000
    with np.load(REFERENCE, allow_pickle=False) as z:
        assert "MIT License" in str(z["notice"]) and "ICT" in str(z["notice"])
    assert "MIT License" in (REFERENCE.parent / "NOTICE").read_text()
    for name, layout in LAYOUTS.items():
        ref = arkit_reference(layout)
        assert ref.neutral.shape == (layout.n_points, 3) and ref.motion.shape == (52, layout.n_points, 3)
        assert np.isfinite(ref.motion).all()
        assert not ref.motion[K["tongueOut"]].any()
        assert np.count_nonzero(np.abs(ref.motion).max(axis=(1, 2)) > 0) == 51
    # the face-mesh layouts read the face-mesh table (mediapipe68: the iBUG points off the mesh)
    dense = arkit_reference("mediapipe468")
    rows = list(get_layout("mediapipe68").mediapipe468)
    assert np.array_equal(arkit_reference("mediapipe68").motion, dense.motion[:, rows])
    ref = arkit_reference("ibug68")
    lay = get_layout("ibug68")
    for side, x_sign in (("Left", 1), ("Right", -1)):
        lid = [lay.index(f"eye_{side.lower()}_upper_inner"), lay.index(f"eye_{side.lower()}_upper_outer")]
        blink = ref.motion[K[f"eyeBlink{side}"]]
        assert np.sign(ref.neutral[lid, 0]).tolist() == [x_sign, x_sign]
        assert blink[lid, 1].max() < -0.5  # the lid comes down more than 5 mm
        other = [lay.mirror[i] for i in lid]
        assert np.abs(blink[other]).max() < 0.1 * np.abs(blink[lid]).max()
    corner = lay.index("mouth_corner_left")
    assert ref.motion[K["mouthSmileLeft"], corner, 0] > 0.2  # the subject's left corner goes out (+x)


@pytest.mark.skipif(not ICT.exists(), reason="ICT data set (../shared) not present")
def test_reference_table_matches_the_ict_model():
    with np.load(ICT) as d:
        names = [str(n) for n in d["expression_names"]]
        expressions = d["expressions"].astype(np.float64)
        landmarks = d["landmarks_68"]
        neutral = d["neutral"].astype(np.float64)
    ref = arkit_reference("ibug68")
    assert np.allclose(ref.neutral, neutral[landmarks], atol=1e-5)
    for k, name in enumerate(ARKIT_NAMES):
        truth = sum((expressions[names.index(s)][landmarks] for s in ICT_SOURCES[name]), np.zeros((68, 3)))
        assert np.abs(ref.motion[k] - truth).max() < 2e-3, name  # float16 of up to 4.2 cm


# --- shapes ----------------------------------------------------------------------------

def test_shapes_on_the_sample_face(face, shapes):
    f, points, rig = face
    assert shapes.names == ARKIT_NAMES
    assert shapes.deltas.shape == (52, len(f.vertices), 3) and shapes.deltas.dtype == np.float32
    assert shapes.at_points.shape == (52, 68, 3)
    assert not shapes.deltas[K["tongueOut"]].any()
    size = np.linalg.norm(shapes.deltas, axis=2)
    assert (size.max(axis=1) > 0).sum() == 51
    for side, sign in (("Left", 1), ("Right", -1)):
        blink = size[K[f"eyeBlink{side}"]]
        assert sign * (blink * f.vertices[:, 0]).sum() / blink.sum() > 2.0  # on the subject's own side
    # the jaw opens downward by centimetres on a face about ICT's size
    chin = f.landmarks68[8]
    assert shapes.deltas[K["jawOpen"], chin, 1] < -2.0
    # posed = neutral + sum w delta
    w = np.zeros(52)
    w[K["jawOpen"]] = 0.5
    expected = f.vertices + 0.5 * shapes.deltas[K["jawOpen"]]
    assert np.allclose(shapes.posed(f.vertices, w), expected, atol=1e-5)


def test_shapes_follow_the_faces_units_and_pose(face, shapes):
    """The space transform carries the reference onto a face in mm, turned and moved: the
    shapes come out in mm and turned the same way."""
    f, points, rig = face
    turn = head_rotations(np.array([[0.4, 0.1, -0.2]]))[0]
    moved = 10.0 * f.vertices @ turn.T + [30.0, -5.0, 100.0]
    other = arkit_shapes(moved, f.faces, points, "ibug68", rig)
    expected = 10.0 * shapes.deltas @ turn.T
    scale = np.abs(expected).max()
    assert np.abs(other.deltas - expected).max() < 0.03 * scale


def test_shapes_refuse_what_does_not_fit(face):
    f, points, rig = face
    with pytest.raises(RetargetError, match="has 22 points"):
        arkit_shapes(f.vertices, f.faces, points, "dutreve22", rig)
    first = SurfacePoints(points.vertex_indices[:22], points.barycentric[:22])
    small = compute_weights("rbf", f.vertices, f.faces, first, get_layout("dutreve22"))
    with pytest.raises(RetargetError, match="22 joints"):
        arkit_shapes(f.vertices, f.faces, points, "ibug68", small)


# --- the solver ------------------------------------------------------------------------

def test_solver_recovers_weights_and_matches_bounded_least_squares():
    rng = np.random.default_rng(3)
    basis = rng.standard_normal((52, 60, 3))
    truth = np.clip(rng.uniform(-0.5, 1.3, 52), 0, 1)
    d = np.tensordot(truth, basis, axes=1)
    exact = ArkitSolver(basis, ridge=0.0, symmetry=0.0, sparsity=0.0, exclusive=False)
    assert np.abs(exact.solve(d) - truth).max() < 1e-6
    # noisy: the box-constrained optimum, as scipy's bounded least squares finds it
    noisy = d + 0.5 * rng.standard_normal(d.shape)
    ours = exact.solve(noisy)
    theirs = lsq_linear(basis.reshape(52, -1).T, noisy.ravel(), bounds=(0, 1), tol=1e-12).x
    assert np.abs(ours - theirs).max() < 1e-6
    assert ((ours >= 0) & (ours <= 1)).all()
    # warm or cold, the same optimum (strictly convex)
    exact.reset()
    assert np.abs(exact.solve(noisy) - ours).max() < 1e-9


def test_solver_keeps_antagonists_exclusive_and_sides_together():
    rng = np.random.default_rng(4)
    basis = rng.standard_normal((52, 30, 3))
    smile, frown = K["mouthSmileLeft"], K["mouthFrownLeft"]
    basis[frown] = -basis[smile] + 0.3 * rng.standard_normal((30, 3))  # nearly opposite
    fight = 0.5 * basis[smile] + 0.3 * (basis[smile] + basis[frown])
    loose = ArkitSolver(basis, ridge=0.0, symmetry=0.0, sparsity=0.0, exclusive=False).solve(fight)
    assert loose[smile] > 0.5 and loose[frown] > 0.2  # both on, cancelling
    strict = ArkitSolver(basis).solve(fight)
    assert strict[smile] > 0.4 and strict[frown] == 0.0
    # a clean frame is not biased by it (but for the sparsity threshold, about 0.01)
    assert ArkitSolver(basis).solve(0.5 * basis[smile])[smile] == pytest.approx(0.49, abs=5e-3)
    # left and right of a symmetric expression share it
    left, right = K["eyeBlinkLeft"], K["eyeBlinkRight"]
    basis[right] = basis[left] + 0.01 * rng.standard_normal((30, 3))  # indistinguishable
    both = ArkitSolver(basis).solve(basis[left] + basis[right])
    assert both[left] == pytest.approx(both[right], abs=0.05)
    assert {a for pair in ANTAGONISTS for a in pair} <= set(ARKIT_NAMES)
    assert ("eyeBlinkLeft", "eyeBlinkRight") in MIRROR_PAIRS and ("jawLeft", "jawRight") not in MIRROR_PAIRS


def test_solver_lost_points_and_bad_input():
    rng = np.random.default_rng(5)
    basis = rng.standard_normal((52, 40, 3))
    truth = rng.uniform(0, 1, 52) * (rng.random(52) < 0.3)
    d = np.tensordot(truth, basis, axes=1)
    d[[3, 7]] = np.nan
    solver = ArkitSolver(basis, ridge=0.0, symmetry=0.0, sparsity=0.0, exclusive=False)
    assert np.abs(solver.solve(d) - truth).max() < 1e-6
    assert np.array_equal(solver.solve(np.full((40, 3), np.nan)), solver.weights_)
    with pytest.raises(RetargetError, match="shape \\(40, 3\\)"):
        solver.solve(np.zeros((41, 3)))
    with pytest.raises(RetargetError, match="52, N, 3"):
        ArkitSolver(np.zeros((51, 4, 3)))
    with pytest.raises(RetargetError, match="ridge"):
        ArkitSolver(basis, ridge=-1.0)


def test_round_trip_on_the_sample_face(face, shapes):
    """weights -> the reference face's points -> retargeted onto the sample face -> solved:
    the weights come back."""
    f, points, rig = face
    ref = arkit_reference("ibug68")
    weights = np.zeros((4, 52))
    weights[0, [K["jawOpen"], K["browInnerUp"]]] = [0.6, 0.8]
    weights[1, [K["mouthSmileLeft"], K["mouthSmileRight"], K["eyeBlinkLeft"]]] = [0.7, 0.7, 1.0]
    weights[2, [K["mouthPucker"], K["browDownRight"]]] = [0.9, 0.5]
    weights[3, [K["jawOpen"], K["mouthFunnel"], K["noseSneerLeft"]]] = [0.3, 0.5, 0.6]
    d = Retargeter().fit(ref.neutral, points.positions(f.vertices)).displacements(ref.points(weights))
    solved = ArkitSolver(shapes.at_points).solve_frames(d)
    assert np.abs(solved - weights).mean() < 0.01
    big = weights > 0
    assert np.abs(solved[big] - weights[big]).max() < 0.1


# --- ARKit curves as a take ------------------------------------------------------------

def _live_link_csv(weights: np.ndarray, yaw: float = 0.0, fps: int = 60) -> str:
    head = ["Timecode", "BlendShapeCount", *(n[0].upper() + n[1:] for n in ARKIT_NAMES),
            "HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll",
            "RightEyeYaw", "RightEyePitch", "RightEyeRoll"]
    rows = [",".join(head)]
    for i, w in enumerate(weights):
        s, ff = divmod(i, fps)
        rows.append(",".join([f"10:20:{30 + s:02d}:{ff:02d}.000", "61", *(f"{x:.6f}" for x in w),
                              f"{yaw}", "0", "0", *["0.1"] * 6]))
    return "\n".join(rows) + "\n"


def test_live_link_face_csv_reads_as_a_take():
    weights = np.zeros((70, 52))
    weights[10:, K["jawOpen"]] = 0.5
    weights[20:, K["eyeBlinkLeft"]] = 1.0
    take = read_take(_live_link_csv(weights).encode(), filename="take.csv")
    ref = arkit_reference("ibug68")
    assert take.layout == "ibug68" and take.points.shape == (70, 68, 3) and take.source == "arkit"
    assert take.fps == 60 and take.meta["format"] == "live_link_face" and not take.meta["fps_assumed"]
    assert np.allclose(take.frame_times()[:2], [0, 1 / 60])
    assert "LeftEyeYaw" in take.meta["ignored"]
    assert np.allclose(take.points[0], ref.neutral, atol=1e-5)
    assert np.allclose(take.points[30], ref.points(weights[30]), atol=1e-4)
    dense = read_take(_live_link_csv(weights).encode(), filename="take.csv", layout="mediapipe468")
    assert dense.points.shape == (70, 468, 3)
    # the head turns the points about the reference's origin
    turned = read_take(_live_link_csv(weights[:2], yaw=0.3).encode(), filename="take.csv")
    yaw = head_rotations(np.array([[0.3, 0.0, 0.0]]))[0]
    assert np.allclose(turned.points[0], ref.neutral @ yaw.T, atol=1e-4)
    assert turned.meta["head_rotation"] == "applied to the points"


def test_plain_csv_and_json_weights():
    csv_text = "time,jawOpen,mouthSmileLeft,other\n0,0.1,0.2,5\n0.05,0.3,0.4,5\n"
    take = read_take(csv_text.encode(), filename="w.csv", layout="dutreve22")
    assert take.points.shape == (2, 22, 3) and take.fps == pytest.approx(20.0)
    assert take.meta["ignored"] == ["other"] and take.meta["head_rotation"] == "none"
    doc = {"fps": 30, "weights": [{"jawOpen": 0.5, "_neutral": 0.2}, {"JawOpen": 1.0}]}
    take = read_take(json.dumps(doc).encode(), filename="w.json")
    ref = arkit_reference("ibug68")
    assert np.allclose(take.points[1], ref.points(np.eye(52)[K["jawOpen"]]), atol=1e-4)
    doc = {"names": ["jawOpen", "eyeBlinkRight"], "weights": [[0.2, 0.3]], "head": [[0, 0.1, 0]]}
    assert read_take(json.dumps(doc).encode(), filename="w.json").n_frames == 1
    # read a block of rows at a time
    long = "jawOpen\n" + "0.25\n" * 5000
    take = read_take(long.encode(), filename="long.csv", fps=60)
    assert take.n_frames == 5000 and np.allclose(take.points[-1], take.points[0])
    # a landmark table is still read as one
    landmark = "frame,a_x,a_y\n0,1,2\n"
    assert read_take(landmark.encode(), filename="l.csv").names == ("a",)


@pytest.mark.parametrize("text, message", [
    ("jawOpen,mouthClose\n0.1,nan\n", "row 2, column mouthClose: 'nan' is not a finite number"),
    ("jawOpen,mouthClose\n0.1,\n", "row 2, column mouthClose: '' is not a finite number"),
    ("jawOpen,mouthClose\n0.1,abc\n", "row 2, column mouthClose: 'abc'"),
    ("jawOpen,mouthClose\n0.1\n", "row 2 has 1 cells, the header 2"),
    ("jawOpen\n", "not followed by any frame"),
    ("jawOpen\n55\n", "jawOpen is 55; ARKit weights are in \\[0, 1\\] \\(a 0-100 scale"),
    ("jawOpen,HeadYaw,HeadPitch\n0,0,0\n", "it lacks HeadRoll"),
    ("jawOpen,HeadYaw,HeadPitch,HeadRoll\n0,45,0,0\n", "head yaw is 45; head angles are radians"),
    ("jawOpen,JawOpen\n0,0\n", "names an ARKit shape twice"),
    ("Timecode,jawOpen\n12:00:00:01,0\n12:00:00:00,0\n", "row 3: the timecode"),
    ("Timecode,jawOpen\nnoon,0\n", "row 2, column Timecode: 'noon'"),
])
def test_malformed_csv_is_refused_precisely(text, message):
    with pytest.raises(RetargetError, match=message):
        read_take(text.encode(), filename="bad.csv")


@pytest.mark.parametrize("doc, message", [
    ({"weights": []}, "non-empty list"),
    ({"weights": [{"jawOpen": None}]}, "frame 0, 'jawOpen' must be a finite number"),
    ({"weights": [{"foo": 1}]}, "none of the 52 ARKit shapes \\(they name foo\\)"),
    ({"weights": [[0.1]]}, "need \"names\""),
    ({"names": ["jawOpen"], "weights": [[0.1, 0.2]]}, "frame 0 of \"weights\" has 2 values"),
    ({"names": ["foo"], "weights": [[0.1]]}, "none of the 52 ARKit names"),
    ({"weights": [{"jawOpen": 0.1}], "times": [0, 1]}, "list of 1 numbers"),
    ({"weights": [{"jawOpen": 0.1}], "fps": -3}, "\"fps\" must be positive"),
    ({"weights": [{"jawOpen": 0.1}], "head": [[0, 0]]}, "\\[yaw, pitch, roll\\]"),
])
def test_malformed_json_is_refused_precisely(doc, message):
    with pytest.raises(RetargetError, match=message):
        read_take(json.dumps(doc).encode(), filename="bad.json")


def test_huge_tables_are_refused_before_their_arrays(monkeypatch):
    monkeypatch.setattr(curves_module, "MAX_TAKE_VALUES", 100)
    text = "jawOpen,mouthClose\n" + "0,0\n" * 60
    with pytest.raises(RetargetError, match="row 52 takes the table past 100 values"):
        read_take(text.encode(), filename="big.csv")
    with pytest.raises(RetargetError, match="exceed the 100 values"):
        read_take(json.dumps({"weights": [{"jawOpen": 0}] * 5}).encode(), filename="big.json")


# --- the command line ------------------------------------------------------------------

def test_cli_arkit_writes_the_shapes(face, shapes, tmp_path, capsys):
    f, points, rig = face
    save_mesh(mesh_from_arrays(f.vertices, f.faces), tmp_path / "face.obj")
    landmarks = {"vertex_indices": f.landmarks68.tolist(), "layout": "ibug68"}
    (tmp_path / "t0.json").write_text(json.dumps(landmarks))
    rig.save(tmp_path / "rig.npz")
    out = tmp_path / "shapes.npz"
    assert main(["arkit", str(tmp_path / "face.obj"), "--landmarks", str(tmp_path / "t0.json"),
                 "--rig", str(tmp_path / "rig.npz"), "--out", str(out)]) == 0
    assert "made 52 ARKit shapes" in capsys.readouterr().out
    with np.load(out) as z:
        assert tuple(z["names"]) == ARKIT_NAMES
        assert np.allclose(z["deltas"], shapes.deltas, atol=1e-5)
    (tmp_path / "bare.json").write_text(json.dumps({"vertex_indices": f.landmarks68.tolist()}))
    assert main(["arkit", str(tmp_path / "face.obj"), "--landmarks", str(tmp_path / "bare.json"),
                 "--out", str(out)]) == 2
    assert "give --layout" in capsys.readouterr().err


def test_default_rig_carries_the_dense_reference(face, shapes):
    """Without a rig the shapes come from the reference's 468 face-mesh points carried onto
    the face: the same motion where the layout's points are, and no motion lost."""
    f, points, rig = face
    dense = arkit_shapes(f.vertices, f.faces, points, "ibug68")
    assert dense.deltas.shape == shapes.deltas.shape and not dense.deltas[K["tongueOut"]].any()
    assert np.array_equal(dense.at_points, shapes.at_points)
    at = points.positions(dense.deltas.astype(np.float64))               # (52, 68, 3)
    scale = np.abs(dense.at_points).max(axis=(1, 2), keepdims=True) + 1e-9
    assert np.median(np.abs(at - dense.at_points) / scale) < 0.05
    size = np.linalg.norm(dense.deltas, axis=2)
    blink = size[K["eyeBlinkLeft"]]
    assert (blink * f.vertices[:, 0]).sum() / blink.sum() > 2.0
    assert dense.deltas[K["jawOpen"], f.landmarks68[8], 1] < -2.0


def test_solver_on_vertex_displacements(shapes):
    """The solver fits vertex displacements as well: a face posed by its own morph targets
    gives its weights back."""
    weights = np.zeros(52)
    weights[[K["jawOpen"], K["mouthSmileLeft"], K["browInnerUp"]]] = [0.4, 0.8, 0.6]
    posed = np.tensordot(weights, shapes.deltas, axes=1)
    solved = ArkitSolver(shapes.deltas).solve(posed)
    assert np.abs(solved - weights).max() < 0.03
