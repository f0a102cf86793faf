"""The ``retarget`` command line, in process through `main` and once as installed.

Inputs are the built-in sample face (no data files): the target is the default identity,
the source another identity posed with a few known expression weights, so the target
posed with the same weights is the ground truth.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path


import numpy as np
import pytest

from retarget.cli import main
from retarget.layouts import get_layout
from retarget.mesh import mesh_from_arrays, save_mesh
from retarget.sample_face import sample_face
from retarget.skin import SkinWeights

IBUG = get_layout("ibug68")
BROWS = np.flatnonzero(IBUG.region_mask("brows"))
LIPS = np.flatnonzero(IBUG.region_mask(["upper_lip", "lower_lip"]))
CHIN = IBUG.index("chin")
# frames: neutral, jaw open, brows up, smile, all at once
EXPRESSION_FRAMES = (
    {},
    {"jawOpen": 1.0},
    {"browInnerUp": 1.0, "browOuterUp_L": 1.0, "browOuterUp_R": 1.0},
    {"mouthSmile_L": 1.0, "mouthSmile_R": 1.0},
    {"jawOpen": 0.5, "browInnerUp": 0.7, "mouthSmile_L": 0.6, "eyeBlink_R": 1.0},
)
NEUTRAL, JAW, BROW = 0, 1, 2


def _posed(face, frames) -> np.ndarray:
    """(F, V, 3) the face with each frame's expression weights (linear shapes)."""
    w = np.array([[f.get(n, 0.0) for n in face.expression_names] for f in frames])
    return face.vertices + np.einsum("fe,evd->fvd", w, face.expressions)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Paths of the target mesh, its landmarks (two JSON forms), S0 and S (2D and 3D)."""
    d = tmp_path_factory.mktemp("cli")
    target = sample_face()
    source = sample_face(identity=[1.5, -1.2, 1.0, 1.2, -1.0])
    lm = np.asarray(target.landmarks68)
    save_mesh(mesh_from_arrays(target.vertices, target.faces), d / "target.obj")
    (d / "t0.json").write_text(json.dumps({"vertex_indices": lm.tolist(), "layout": "ibug68"}))
    (d / "t0_positions.json").write_text(json.dumps({"positions": target.vertices[lm].tolist(), "layout": "ibug68"}))
    s0 = source.vertices[source.landmarks68]
    s = _posed(source, EXPRESSION_FRAMES)[:, source.landmarks68]
    np.save(d / "s0.npy", s0)
    np.save(d / "s.npy", s)
    np.save(d / "s0_2d.npy", s0[:, :2])
    np.save(d / "s_2d.npy", s[..., :2])
    return {
        "dir": d,
        "target": target,
        "mesh": d / "target.obj",
        "t0": d / "t0.json",
        "t0_positions": d / "t0_positions.json",
        "s0": d / "s0.npy",
        "s": d / "s.npy",
        "s0_2d": d / "s0_2d.npy",
        "s_2d": d / "s_2d.npy",
    }


def _transfer_args(files, out, *extra, t0="t0", s0="s0", s="s", deformer="ellipsoid"):
    args = ["transfer", "--target-mesh", str(files["mesh"]),
            "--target-landmarks", str(files[t0]) if t0 in files else str(t0),
            "--source-neutral", str(files[s0]) if s0 in files else str(s0),
            "--source-frames", str(files[s]) if s in files else str(s),
            "--out", str(out), "--quiet", *extra]
    if deformer is not None:
        args += ["--deformer", deformer]
    return args


def _run(files, out, *extra, **kw) -> np.ndarray:
    assert main(_transfer_args(files, out, *extra, **kw)) == 0
    return np.load(out)


def _motion(result, target, vertices) -> np.ndarray:
    """(F, len(vertices)) distance of those vertices from their rest place, cm."""
    return np.linalg.norm(result[:, vertices] - target.vertices[vertices], axis=-1)


# ---------------------------------------------------------------------------------------
# demo and layouts


def test_demo_writes_its_files_and_reports_the_error(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--frames", "4", "--quiet"]) == 0
    text = capsys.readouterr().out
    face = sample_face()
    v = len(face.vertices)
    result = np.load(out / "out.npy")
    assert result.shape == (4, v, 3) and result.dtype == np.float32
    assert np.load(out / "source_neutral.npy").shape == (68, 3)
    assert np.load(out / "source_frames.npy").shape == (4, 68, 3)
    landmarks = json.loads((out / "target_landmarks.json").read_text())
    assert landmarks == {"vertex_indices": np.asarray(face.landmarks68).tolist(), "layout": "ibug68"}
    assert (out / "target.obj").is_file()
    mean = float(re.search(r"mean ([0-9.]+) cm", text).group(1))
    worst = float(re.search(r"max ([0-9.]+) cm", text).group(1))
    relative = float(re.search(r"relative ([0-9.]+) %", text).group(1))
    assert 0 < mean <= worst
    assert 0 < relative < 100
    assert str(out / "out.npy") in text


def test_layouts_lists_every_layout(capsys):
    assert main(["layouts"]) == 0
    text = capsys.readouterr().out
    assert re.search(r"^ibug68\s+68 points .*brows 10", text, re.MULTILINE)
    assert re.search(r"^dutreve21\s+21 points", text, re.MULTILINE)


# ---------------------------------------------------------------------------------------
# transfer


def test_transfer_from_vertex_indices(files, tmp_path, capsys):
    result = _run(files, tmp_path / "out.npy")
    target = files["target"]
    assert result.shape == (len(EXPRESSION_FRAMES), len(target.vertices), 3)
    assert result.dtype == np.float32
    np.testing.assert_allclose(result[NEUTRAL], target.vertices, atol=1e-5)
    chin = target.landmarks68[CHIN]
    assert result[JAW, chin, 1] - target.vertices[chin, 1] < -0.5  # jaw open: chin drops
    summary = capsys.readouterr().out
    assert f"{len(EXPRESSION_FRAMES)} frames onto {len(target.vertices)} vertices" in summary
    assert "68 points with ellipsoid" in summary and "frames/s" in summary


def test_transfer_from_positions_matches_vertex_indices(files, tmp_path):
    # rbf: dense weights, continuous in the landmark places (ellipsoid's top-4 cut is not,
    # and snapping may land a hair off the vertex)
    by_index = _run(files, tmp_path / "a.npy", deformer="rbf")
    by_position = _run(files, tmp_path / "b.npy", t0="t0_positions", deformer="rbf")
    np.testing.assert_allclose(by_position, by_index, atol=1e-4)
    assert np.abs(by_index[JAW] - files["target"].vertices).max() > 0.5


def test_transfer_from_a_2d_source(files, tmp_path):
    result = _run(files, tmp_path / "out.npy", s0="s0_2d", s="s_2d")
    target = files["target"]
    np.testing.assert_allclose(result[NEUTRAL], target.vertices, atol=1e-5)
    chin = target.landmarks68[CHIN]
    assert result[JAW, chin, 1] - target.vertices[chin, 1] < -0.5
    brows = target.landmarks68[BROWS]
    assert (result[BROW, brows, 1] - target.vertices[brows, 1]).mean() > 0.2  # brows go up


def test_mask_brows_moves_only_the_brows(files, tmp_path):
    target = files["target"]
    brows, lips = target.landmarks68[BROWS], target.landmarks68[LIPS]
    full = _run(files, tmp_path / "full.npy")
    masked = _run(files, tmp_path / "brows.npy", "--mask", "brows")
    assert _motion(full, target, lips)[JAW].min() > 0.05     # without the mask lips move
    assert _motion(masked, target, lips).max() < 1e-5        # with it they stay at rest
    np.testing.assert_allclose(masked[BROW][brows], full[BROW][brows], atol=0.01)
    assert _motion(masked, target, brows)[BROW].min() > 0.2
    by_index = _run(files, tmp_path / "idx.npy", "--mask", *map(str, BROWS))
    np.testing.assert_array_equal(by_index, masked)


def test_mask_union_of_region_and_point(files, tmp_path):
    target = files["target"]
    lips = target.landmarks68[LIPS]
    chin = target.landmarks68[CHIN]
    result = _run(files, tmp_path / "out.npy", "--mask", "brows", "--mask", "chin")
    assert _motion(result, target, [chin])[JAW, 0] > 0.5
    assert _motion(result, target, lips).max() < 1e-5


# ---------------------------------------------------------------------------------------
# rig


def test_rig_writes_loadable_weights(files, tmp_path, capsys):
    v = len(files["target"].vertices)
    out = tmp_path / "rig.npz"
    assert main(["rig", str(files["mesh"]), "--landmarks", str(files["t0"]), "--out", str(out),
                 "--method", "ellipsoid", "--quiet"]) == 0
    rig = SkinWeights.load(out)
    assert rig.indices.shape == rig.weights.shape == (v, 4)
    assert rig.n_joints == 68 and rig.method == "ellipsoid"
    assert f"{v} vertices, 68 joints, 4 influences" in capsys.readouterr().out
    assert main(["rig", str(files["mesh"]), "--landmarks", str(files["t0"]), "--out", str(out),
                 "--method", "rbf", "--k", "6", "--quiet"]) == 0
    rig = SkinWeights.load(out)
    assert rig.indices.shape == (v, 6) and rig.method == "rbf"


def test_rig_reuse_gives_the_computed_result(files, tmp_path):
    rig = tmp_path / "rig.npz"
    assert main(["rig", str(files["mesh"]), "--landmarks", str(files["t0"]), "--out", str(rig),
                 "--method", "rbf", "--quiet"]) == 0
    computed = _run(files, tmp_path / "a.npy", deformer="rbf")
    reused = _run(files, tmp_path / "b.npy", "--rig", str(rig), deformer=None)
    np.testing.assert_array_equal(reused, computed)


# ---------------------------------------------------------------------------------------
# refusals: exit status 2, one "retarget: error:" line, nothing written


@pytest.fixture(scope="module")
def bad_inputs(files):
    d = files["dir"]
    s0 = np.load(files["s0"])
    s = np.load(files["s"])
    np.save(d / "s0_51.npy", s0[17:])
    np.save(d / "s_67.npy", s[:, 1:])
    s0_nan = s0.copy()
    s0_nan[5, 1] = np.nan
    np.save(d / "s0_nan.npy", s0_nan)
    (d / "not_npy.npy").write_text("this is not an array\n")
    (d / "t0_no_layout.json").write_text(
        json.dumps({"vertex_indices": files["target"].landmarks68.tolist()}))
    (d / "broken.json").write_text('{"vertex_indices": [1, 2,')
    (d / "t0_21.json").write_text(json.dumps(
        {"vertex_indices": files["target"].landmarks68[list(get_layout("dutreve21").ibug68)].tolist()}))
    return d


@pytest.mark.parametrize(("kw", "extra", "message"), [
    ({"s0": "s0_51.npy"}, (), "source neutral has 51 points but target landmarks have 68"),
    ({"s": "s_67.npy"}, (), "source frames have 67 points but source neutral has 68"),
    ({"s0": "s0_2d"}, (), "source frames are 3D but source neutral is 2D"),
    ({"s": "missing.npy"}, (), "source frames '{dir}/missing.npy' does not exist"),
    ({"t0": "missing.json"}, (), "target landmarks '{dir}/missing.json' does not exist"),
    ({"s0": "s0_nan.npy"}, (), "source neutral has 1 point(s) with NaN"),
    ({"s": "not_npy.npy"}, (), "could not read source frames '{dir}/not_npy.npy' as .npy"),
    ({"t0": "broken.json"}, (), "could not read landmarks JSON '{dir}/broken.json'"),
    ({"deformer": "nope"}, (), "argument --deformer: invalid choice: 'nope'"),
    ({}, ("--kernel", "cubic"), "argument --kernel: invalid choice: 'cubic'"),
    ({}, ("--smoothing", "-1"), "argument --smoothing: expected a finite number >= 0"),
    ({}, ("--mask", "mouht"), "Layout 'ibug68': 'mouht' is not a region"),
    ({}, ("--mask", "68"), "--mask index 68 is outside the 68 feature points"),
    ({"t0": "t0_no_layout.json"}, ("--mask", "mouth"), "--mask 'mouth' is a name, which needs a layout"),
    ({}, ("--layout", "dutreve21"),
     "layout 'dutreve21' (from --layout) has 21 points but target landmarks have 68"),
    ({}, ("--layout", "ibug99"), "argument --layout: invalid choice: 'ibug99'"),
    ({}, ("--rig", "rig.npz"), "argument --deformer: not allowed with argument --rig"),
    ({"deformer": None}, ("--rig", "{dir}/missing.npz"), "rig '{dir}/missing.npz' does not exist"),
    ({}, ("--out", "{dir}/no/such/dir/out.npy"),
     "cannot write '{dir}/no/such/dir/out.npy': directory '{dir}/no/such/dir' does not exist"),
])
def test_transfer_refusals(files, bad_inputs, tmp_path, capsys, kw, extra, message):
    d = str(bad_inputs)
    kw = {k: v if k == "deformer" or v in files else f"{d}/{v}" for k, v in kw.items()}
    extra = [e.format(dir=d) for e in extra]
    assert main(_transfer_args(files, tmp_path / "out.npy", *extra, **kw)) == 2
    captured = capsys.readouterr()
    assert f"retarget: error: {message.format(dir=d)}" in captured.err
    assert captured.out == ""
    assert not (tmp_path / "out.npy").exists()


def test_rig_with_the_wrong_joint_count_is_refused(files, bad_inputs, tmp_path, capsys):
    rig = tmp_path / "rig21.npz"
    assert main(["rig", str(files["mesh"]), "--landmarks", str(bad_inputs / "t0_21.json"),
                 "--out", str(rig), "--method", "ellipsoid", "--quiet"]) == 0
    assert main(_transfer_args(files, tmp_path / "out.npy", "--rig", str(rig), deformer=None)) == 2
    assert f"rig '{rig}' has 21 joints but target landmarks have 68" in capsys.readouterr().err


def test_usage_errors_return_2(capsys):
    assert main([]) == 2
    assert "retarget: error: the following arguments are required: COMMAND" in capsys.readouterr().err
    assert main(["rig", "mesh.obj"]) == 2
    assert "required: --landmarks, --out" in capsys.readouterr().err
    assert main(["demo", "--frames", "0"]) == 2
    assert "argument --frames: expected a positive integer, got 0" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------
# as installed


def _installed() -> list[str]:
    script = Path(sys.executable).with_name("retarget")
    found = str(script) if script.is_file() else shutil.which("retarget")
    return [found] if found else [sys.executable, "-m", "retarget.cli"]


def test_installed_script_transfers_and_refuses(files, tmp_path):
    out = tmp_path / "out.npy"
    done = subprocess.run(_installed() + _transfer_args(files, out), capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert np.load(out).shape == (len(EXPRESSION_FRAMES), len(files["target"].vertices), 3)
    assert "frames/s" in done.stdout

    missing = tmp_path / "nothing.obj"
    args = _transfer_args(files, tmp_path / "x.npy")
    args[args.index("--target-mesh") + 1] = str(missing)
    done = subprocess.run([sys.executable, "-m", "retarget.cli", *args], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.strip() == f"retarget: error: target mesh '{missing}' does not exist"


# ---------------------------------------------------------------------------------------
# export-gltf


def _export_args(files, out, *extra, source=True):
    args = ["export-gltf", "--mesh", str(files["mesh"]), "--landmarks", str(files["t0"]),
            "--out", str(out), "--quiet", *extra]
    if source:
        args += ["--source-neutral", str(files["s0"]), "--source-frames", str(files["s"])]
    return args


def test_export_gltf_skin_form_rate_and_key_tolerance(files, tmp_path, capsys):
    """--form skin makes the default (biharmonic, morph-target) rig a one-set skin, says its
    fitted error; --rate puts the keys on a 24 fps grid; --key-tolerance drops keys."""
    from retarget.gltf.document import GltfDocument
    from tests.gltf_check import assert_valid_gltf

    exact, small = tmp_path / "exact.glb", tmp_path / "small.glb"
    assert main(_export_args(files, exact, "--fps", "30")) == 0
    assert main(_export_args(files, small, "--fps", "30", "--form", "skin", "--rate", "24",
                             "--key-tolerance", "0.05")) == 0
    text = capsys.readouterr().out
    assert "morph targets (biharmonic)" in text
    assert "four influences a vertex, fitted: " in text and "% RMS error" in text
    assert_valid_gltf(small)
    assert small.stat().st_size < exact.stat().st_size / 4
    gltf = GltfDocument(small.read_bytes(), "small", None)
    record = gltf.doc.scenes[0].extras["retarget"]
    assert record["rate"] == 24.0 and record["key_tolerance_mm"] == 0.05 and record["fit"]["from"] == "morph"
    assert f"{100 * record['fit']['rms_relative']:.1f} % RMS error" in text
    for sampler in gltf.doc.animations[0].samplers:
        keys = gltf.accessor(sampler.input)[:, 0]
        np.testing.assert_allclose(keys * 24, np.round(keys * 24), atol=1e-3)
    assert main(_export_args(files, small, "--rate", "23")) == 2
    assert "argument --rate: invalid choice: 23.0" in capsys.readouterr().err
    assert main(_export_args(files, tmp_path / "m.glb", "--form", "skin", "--drive", "muscles")) == 2
    assert "--form skin shapes the rig's export: it goes with --drive points" in capsys.readouterr().err


def test_export_gltf_animates_what_transfer_computes(files, tmp_path, capsys):
    """The .glb's clip, skinned with its own weights, is the transfer's result."""
    from retarget.gltf import read_gltf
    from retarget.skin import skin_displacements
    from tests.gltf_check import assert_valid_gltf

    out = tmp_path / "face.glb"
    assert main(_export_args(files, out, "--deformer", "ellipsoid", "--fps", "24")) == 0
    text = capsys.readouterr().out
    assert f"68 feature joints of a skin (ellipsoid), {len(EXPRESSION_FRAMES)} frames at 24 fps" in text
    assert str(out) in text
    assert_valid_gltf(out)
    back = read_gltf(out)
    assert back.deformation == "skin" and back.joint_names == IBUG.point_names
    (clip,) = back.clips
    assert clip.name == "s"
    np.testing.assert_allclose(clip.times, np.arange(len(EXPRESSION_FRAMES)) / 24, rtol=1e-6)
    transferred = _run(files, tmp_path / "out.npy")
    animated = back.mesh.vertices + skin_displacements(back.weights, clip.displacements)
    np.testing.assert_allclose(animated, transferred, atol=1e-4)
    assert np.abs(transferred[JAW] - transferred[NEUTRAL]).max() > 0.3


def test_export_gltf_partial_morph_targets(files, tmp_path):
    """A dense rig exports as morph targets; --mask brows moves only the brows' joints."""
    from retarget.gltf import read_gltf

    out = tmp_path / "brows.glb"
    assert main(_export_args(files, out, "--deformer", "rbf", "--mask", "brows")) == 0
    back = read_gltf(out)
    assert back.deformation == "morph" and back.weights.method == "rbf"
    moved = np.abs(back.clips[0].displacements).max(axis=(0, 2))
    assert moved[BROWS].min() > 0.1
    assert np.delete(moved, BROWS).max() == 0


def test_export_gltf_of_a_rig_without_animation(files, tmp_path, capsys):
    from retarget.gltf import read_gltf

    rig = tmp_path / "rig.npz"
    assert main(["rig", str(files["mesh"]), "--landmarks", str(files["t0"]), "--out", str(rig),
                 "--method", "geodesic", "--quiet"]) == 0
    out = tmp_path / "rig.glb"
    assert main(_export_args(files, out, "--rig", str(rig), source=False)) == 0
    assert "no animation" in capsys.readouterr().out
    back = read_gltf(out)
    assert back.clips == () and back.deformation == "skin"
    np.testing.assert_allclose(back.weights.dense(), SkinWeights.load(rig).dense(), atol=1e-7)


@pytest.mark.parametrize(("extra", "source", "message"), [
    (("--source-neutral", "{s0}"), False, "--source-neutral and --source-frames go together"),
    (("--mask", "brows"), False, "--mask, --kernel and --smoothing shape the animation"),
    (("--fps", "0"), True, "argument --fps: expected a positive number, got 0"),
    (("--rig", "{dir}/missing.npz"), True, "rig '{dir}/missing.npz' does not exist"),
    (("--deformer", "rbf", "--rig", "x.npz"), True, "argument --rig: not allowed with argument --deformer"),
    (("--out", "{dir}/no/such.glb"), True, "cannot write '{dir}/no/such.glb'"),
])
def test_export_gltf_refusals(files, tmp_path, capsys, extra, source, message):
    fill = {"s0": files["s0"], "dir": tmp_path}
    extra = [e.format(**fill) for e in extra]
    out = tmp_path / "out.glb"
    assert main(_export_args(files, out, *extra, source=source)) == 2
    captured = capsys.readouterr()
    assert f"retarget: error: {message.format(**fill)}" in captured.err
    assert captured.out == "" and not out.exists()
