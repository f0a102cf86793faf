"""The CLI with a custom layout: ``retarget layouts new/check`` make and check the file, and
rig, transfer (partial retargeting by the layout's regions) and export-gltf take a target
landmarks JSON whose layout is the user's (the spec inline, or ``--layout L.json``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from retarget.cli import main
from retarget.custom_layouts import layout_from_spec
from retarget.layouts import get_layout
from retarget.mesh import mesh_from_arrays, save_mesh
from retarget.sample_face import sample_face

IBUG = get_layout("ibug68")
# the user's 14 markers, on iBUG spots of the sample face but named and numbered their way
MARKERS = (17, 19, 21, 22, 24, 26, 48, 54, 51, 57, 8, 30, 36, 45)
NAMES = [f"m{k:02d}" for k in range(len(MARKERS))]
REGIONS = [IBUG.regions[i] for i in MARKERS]
SIDES = [IBUG.sides[i] for i in MARKERS]
MIRROR = ["-" if IBUG.mirror[i] == i else NAMES[MARKERS.index(IBUG.mirror[i])] for i in MARKERS]
ANCHORS = ["m11", "m12", "m13"]  # nose tip and the outer eye corners
BROWS = [k for k, r in enumerate(REGIONS) if r == "brows"]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The layout file, the target mesh, its T0 with the spec inline and without any
    layout, S0 and S (neutral, then brows raised with the jaw open)."""
    d = tmp_path_factory.mktemp("custom")
    layout_file = d / "L.json"
    assert main(["layouts", "new", "--names", ",".join(NAMES), "--regions", ",".join(REGIONS),
                 "--sides", ",".join(SIDES), "--mirror", ",".join(MIRROR),
                 "--anchors", ",".join(ANCHORS), "--description", "my 14 markers",
                 "--out", str(layout_file)]) == 0
    spec = json.loads(layout_file.read_text())
    layout_name = layout_from_spec(spec).name
    target = sample_face()
    save_mesh(mesh_from_arrays(target.vertices, target.faces), d / "target.obj")
    vertices = np.asarray(target.landmarks68)[list(MARKERS)].tolist()
    (d / "t0.json").write_text(json.dumps({"vertex_indices": vertices, "layout": layout_name,
                                           "layout_spec": spec}))
    (d / "t0_bare.json").write_text(json.dumps({"vertex_indices": vertices}))
    source = sample_face(identity=[1.5, -1.2, 1.0, 1.2, -1.0])
    w = np.zeros((2, len(source.expression_names)))
    for name in ("browInnerUp", "browOuterUp_L", "browOuterUp_R", "jawOpen"):
        w[1, source.expression_names.index(name)] = 1.0
    posed = source.vertices + np.einsum("fe,evd->fvd", w, source.expressions)
    rows = np.asarray(source.landmarks68)[list(MARKERS)]
    np.save(d / "s0.npy", source.vertices[rows])
    np.save(d / "s.npy", posed[:, rows])
    return {"dir": d, "layout": layout_file, "name": layout_name, "target": target,
            "mesh": d / "target.obj", "t0": d / "t0.json", "t0_bare": d / "t0_bare.json",
            "s0": d / "s0.npy", "s": d / "s.npy"}


def _transfer(files, out, *extra, t0="t0") -> np.ndarray:
    assert main(["transfer", "--target-mesh", str(files["mesh"]), "--target-landmarks",
                 str(files[t0]), "--source-neutral", str(files["s0"]), "--source-frames",
                 str(files["s"]), "--out", str(out), "--quiet",
                 *(() if "--rig" in extra else ("--deformer", "ellipsoid")), *extra]) == 0
    return np.load(out)


def test_layouts_new_writes_a_file_that_check_sums_up(files, capsys):
    assert main(["layouts", "check", str(files["layout"])]) == 0
    text = capsys.readouterr().out
    assert f"{files['name']}: 14 points  brows 6, eyes 2, nose 1, upper_lip 1, lower_lip 1, mouth_corners 2, jaw 1" in text
    assert "my 14 markers; 5 left/right pairs; head anchors: m11, m12, m13" in text
    assert main(["layouts", "check", str(files["t0"])]) == 0  # the spec a T0 carries
    assert files["name"] in capsys.readouterr().out


@pytest.mark.parametrize("args, message", [
    (["--names", "a,b,c", "--regions", "brows,nose"], "--regions has 2 values, --names has 3"),
    (["--names", "a,b,c", "--regions", "ears"], "point 0 ('a'): region 'ears' is not one of"),
    (["--names", "a,a,b", "--regions", "nose"], "'a' is repeated"),
    (["--names", "a,b,c", "--regions", "nose", "--sides", "right,left,center", "--mirror", "b,c,-"],
     "asymmetric mirror"),
    (["--names", "a,b,c", "--regions", "nose", "--anchors", "a,z"], "--anchors names points that --names lacks: z"),
    (["--names", "a,b", "--regions", "nose"], "needs 3 to 1000 points, got 2"),
    (["--names", "a;b,c,d", "--regions", "nose"], "'a;b' is not a safe identifier"),
    (["--regions", "nose"], "give one of --names or --names-from (with --regions), or --from"),
    (["--names", "a,b,c", "--from", "dutreve22"], "give one of --names"),
])
def test_layouts_new_refuses_a_bad_layout_in_one_line(tmp_path, capsys, args, message):
    out = tmp_path / "L.json"
    assert main(["layouts", "new", *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.startswith("retarget: error:")
    assert not out.exists()


def test_layouts_check_refuses_a_bad_file(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"points": [{"name": "a", "region": "nose", "side": "center"}] * 3}))
    assert main(["layouts", "check", str(bad)]) == 2
    assert "bad.json': layout point name 'a' is repeated" in capsys.readouterr().err


def test_rig_and_transfer_with_a_custom_layout_t0(files, tmp_path):
    rig = tmp_path / "rig.npz"
    assert main(["rig", str(files["mesh"]), "--landmarks", str(files["t0"]), "--out", str(rig),
                 "--method", "ellipsoid", "--quiet"]) == 0
    result = _transfer(files, tmp_path / "out.npy")
    reused = _transfer(files, tmp_path / "reused.npy", "--rig", str(rig))
    np.testing.assert_allclose(reused, result, atol=1e-5)
    target = files["target"]
    chin = target.landmarks68[8]
    assert np.linalg.norm(result[1, chin] - result[0, chin]) > 0.3  # the jaw opens


def test_partial_retargeting_by_the_custom_layout_s_regions(files, tmp_path):
    target = files["target"]
    lm = np.asarray(target.landmarks68)
    brows = _transfer(files, tmp_path / "brows.npy", "--mask", "brows")
    moved = np.linalg.norm(brows[1] - brows[0], axis=-1)
    assert moved[lm[[MARKERS[k] for k in BROWS]]].min() > 0.1
    assert moved[lm[8]] < 1e-6  # the chin stays: the mouth and jaw are masked out
    by_name = _transfer(files, tmp_path / "m00.npy", "--mask", "m00")
    assert np.linalg.norm(by_name[1, lm[17]] - by_name[0, lm[17]]) > 0.1


def test_layout_file_given_with_layout_for_a_bare_t0(files, tmp_path, capsys):
    with_spec = _transfer(files, tmp_path / "a.npy", "--mask", "mouth")
    with_file = _transfer(files, tmp_path / "b.npy", "--mask", "mouth", "--layout",
                          str(files["layout"]), t0="t0_bare")
    np.testing.assert_allclose(with_file, with_spec, atol=1e-6)
    assert main(["transfer", "--target-mesh", str(files["mesh"]), "--target-landmarks",
                 str(files["t0_bare"]), "--source-neutral", str(files["s0"]), "--source-frames",
                 str(files["s"]), "--out", str(tmp_path / "c.npy"), "--layout", "nope.json"]) == 2
    assert "could not read layout file 'nope.json'" in capsys.readouterr().err


def test_export_gltf_names_the_joints_after_the_markers_and_carries_the_layout(files, tmp_path, capsys):
    from retarget import layouts
    from retarget.gltf import read_gltf

    out = tmp_path / "face.glb"
    assert main(["export-gltf", "--mesh", str(files["mesh"]), "--landmarks", str(files["t0"]),
                 "--source-neutral", str(files["s0"]), "--source-frames", str(files["s"]),
                 "--deformer", "ellipsoid", "--out", str(out), "--quiet"]) == 0
    assert "14 feature joints" in capsys.readouterr().out
    layouts._REGISTERED.pop(files["name"])  # as a fresh process reading the file
    back = read_gltf(out)
    assert back.joint_names == tuple(NAMES) or list(back.joint_names) == NAMES
    assert back.points.layout == files["name"] and get_layout(files["name"]).point_names == tuple(NAMES)


def test_layouts_new_takes_the_names_of_a_take_s_markers(tmp_path, capsys):
    take = tmp_path / "perf.json"
    take.write_text(json.dumps({"names": ["LBRO", "RBRO", "NOSE"], "frames": [[[1, 0, 0], [-1, 0, 0], [0, 0, 1]]]}))
    out = tmp_path / "L.json"
    assert main(["layouts", "new", "--names-from", str(take), "--regions", "brows,brows,nose",
                 "--sides", "left,right,center", "--mirror", "RBRO,LBRO,-", "--out", str(out)]) == 0
    spec = json.loads(out.read_text())
    assert [p["name"] for p in spec["points"]] == ["LBRO", "RBRO", "NOSE"]
    assert spec["points"][0]["mirror"] == "RBRO"
    assert main(["layouts", "new", "--names-from", str(tmp_path / "none.json"), "--regions", "nose",
                 "--out", str(out)]) == 2
    assert "none.json" in capsys.readouterr().err


def test_condition_reads_a_take_named_by_the_markers_into_the_custom_layout(files, tmp_path, capsys):
    """The user's take (columns named m00..m13, the head turning) conditioned in their layout:
    the neutral is the first frame and the head motion is removed on their anchors."""
    s0, s = np.load(files["s0"]), np.load(files["s"])
    turn = np.array([[np.cos(0.2), 0.0, np.sin(0.2)], [0.0, 1.0, 0.0], [-np.sin(0.2), 0.0, np.cos(0.2)]])
    frames = np.stack([s0, s0 @ turn.T, s[1] @ turn.T])  # rest, the head turned, then brows + jaw too
    take = tmp_path / "take.json"
    take.write_text(json.dumps({"names": NAMES, "frames": frames.tolist()}))
    out, neutral = tmp_path / "frames.npy", tmp_path / "neutral.npy"
    settings = tmp_path / "settings.json"
    settings.write_text(json.dumps({"neutral": {"mode": "frame", "frame": 0}, "head_pose": "remove"}))
    assert main(["condition", str(take), "--layout", str(files["layout"]), "--settings", str(settings),
                 "--neutral-out", str(neutral), "--out", str(out), "--fps", "30"]) == 0
    got = np.load(out)
    np.testing.assert_allclose(np.load(neutral), s0, atol=1e-4)
    np.testing.assert_allclose(got[1], s0, atol=1e-3)  # the turn alone is head motion: removed
    # with the expression the anchors move a little too (the sample face's eye corners rise
    # with the brows), so the frame comes back by the rigid fit of its anchors to the
    # neutral's (Kabsch), here computed independently of the library
    anchors = [NAMES.index(a) for a in ANCHORS]
    a, b = frames[2][anchors], s0[anchors]
    u, _, vt = np.linalg.svd((a - a.mean(0)).T @ (b - b.mean(0)))
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    rot = (u @ d @ vt).T
    expected = (frames[2] - a.mean(0)) @ rot.T + b.mean(0)
    np.testing.assert_allclose(got[2], expected, atol=1e-3)
    assert np.abs(got[2] - s0).max() > 0.3  # the expression stays
    assert files["name"] in capsys.readouterr().out
