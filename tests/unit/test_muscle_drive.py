"""Driving a face by its muscles end to end (issue 15): the space transform's feature
displacements solved into contractions (`retarget.muscles.drive`), the face made by the
muscles, the expressions named (`retarget.muscles.expressions`), from the library and from
the command line (``retarget muscles``, ``transfer --drive muscles``, ``recognise``), on
the project's own sample faces (the presets were fitted on another face model, ICT's)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from retarget.cli import main
from retarget.mesh import mesh_from_arrays, save_mesh
from retarget.sample_face import sample_face

# the sample face's shapes making three of the six expressions (FACS-style), and neutral
SHOWN = {
    "neutral": {},
    "happiness": {"mouthSmile_L": 1.0, "mouthSmile_R": 1.0},
    "sadness": {"browInnerUp": 0.8, "mouthFrown_L": 0.8, "mouthFrown_R": 0.8},
    "surprise": {"browInnerUp": 0.8, "browOuterUp_L": 0.8, "browOuterUp_R": 0.8, "jawOpen": 0.5},
}
INTENSITIES = (0.5, 1.0)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The target mesh, its landmarks, and a performer's S0 and S (each expression of SHOWN
    at each intensity, neutral once), plus the labels of S's frames."""
    d = tmp_path_factory.mktemp("muscles")
    target = sample_face()
    source = sample_face(identity=[1.5, -1.2, 1.0, 1.2, -1.0])
    save_mesh(mesh_from_arrays(target.vertices, target.faces), d / "mesh.obj")
    (d / "t0.json").write_text(json.dumps({"vertex_indices": target.landmarks68.tolist(), "layout": "ibug68"}))
    (d / "t0_nolayout.json").write_text(json.dumps({"vertex_indices": target.landmarks68.tolist()}))
    weights, labels = [], []
    for label, recipe in SHOWN.items():
        for t in INTENSITIES[-1:] if label == "neutral" else INTENSITIES:
            weights.append([t * recipe.get(n, 0.0) for n in source.expression_names])
            labels.append(label)
    posed = source.vertices + np.einsum("fe,evd->fvd", np.array(weights), source.expressions)
    np.save(d / "s0.npy", source.vertices[source.landmarks68])
    np.save(d / "s.npy", posed[:, source.landmarks68])
    return {"dir": d, "target": target, "labels": labels, **{k: d / f"{k}.{e}" for k, e in (
        ("mesh", "obj"), ("t0", "json"), ("t0_nolayout", "json"), ("s0", "npy"), ("s", "npy"))}}


def _transfer(files, *extra):
    return ["transfer", "--target-mesh", str(files["mesh"]), "--target-landmarks", str(files["t0"]),
            "--source-neutral", str(files["s0"]), "--source-frames", str(files["s"]), "--quiet", *extra]


def test_muscles_drive_the_face_and_its_expressions_are_recognised(files, capsys):
    d, face = files["dir"], files["target"]
    assert main(["muscles", str(files["mesh"]), "--landmarks", str(files["t0"]), "--out", str(d / "m.json")]) == 0
    assert "21 muscles" in capsys.readouterr().out
    assert len(json.loads((d / "m.json").read_text())["muscles"]) == 21

    assert main(_transfer(files, "--out", str(d / "out.npy"), "--drive", "muscles", "--muscles",
                          str(d / "m.json"), "--contractions-out", str(d / "c.npy"))) == 0
    assert "with muscles" in capsys.readouterr().out
    out, c = np.load(d / "out.npy"), np.load(d / "c.npy")
    assert out.shape == (len(files["labels"]), len(face.vertices), 3) and c.shape == (len(out), 22)
    lm = face.landmarks68
    motion = np.linalg.norm(out[:, lm] - face.vertices[lm], axis=-1).max(1)
    labels = np.array(files["labels"])
    assert motion[labels == "neutral"].max() < 1e-6  # the neutral frame leaves the face at rest
    assert motion[labels != "neutral"].min() > 0.1   # cm: every expression moves it
    # the mouth corners rise in the smile (+y up), the chin drops in surprise (the jaw)
    smile = np.flatnonzero(labels == "happiness")[-1]
    assert (out[smile, lm[[48, 54]], 1] - face.vertices[lm[[48, 54]], 1]).min() > 0.1
    surprise = np.flatnonzero(labels == "surprise")[-1]
    assert out[surprise, lm[8], 1] < face.vertices[lm[8], 1] - 0.1

    # recognise from the contractions, and from the source points solved on the target
    assert main(["recognise", str(d / "c.npy"), "--out", str(d / "a.csv"), "--quiet"]) == 0
    assert main(["recognise", str(files["s"]), "--source-neutral", str(files["s0"]), "--target-mesh",
                 str(files["mesh"]), "--target-landmarks", str(files["t0"]), "--out", str(d / "b.csv"),
                 "--quiet"]) == 0
    for name in ("a.csv", "b.csv"):
        rows = list(csv.DictReader(open(d / name)))
        assert [r["expression"] for r in rows] == files["labels"]
        assert all(float(r["confidence"]) > 0 for r in rows)
        assert float(rows[1]["time_s"]) == pytest.approx(1 / 30, abs=1e-4)


@pytest.mark.parametrize("extra, message", [
    (["--drive", "muscles", "--deformer", "ellipsoid"], "not a rig"),
    (["--drive", "muscles", "--muscles", "missing.json"], "'missing.json' does not exist"),
    (["--drive", "muscles", "--muscles", "{t0}"], "muscle JSON is malformed"),
    (["--muscles", "{t0}"], "need drive 'muscles'"),
])
def test_muscle_refusals_name_the_problem(files, tmp_path, capsys, extra, message):
    extra = [e.format(t0=files["t0"]) for e in extra]
    assert main(_transfer(files, "--out", str(tmp_path / "o.npy"), *extra)) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "o.npy").exists()


def test_recognise_refusals_name_the_problem(files, tmp_path, capsys):
    np.save(tmp_path / "short.npy", np.zeros((3, 5)))
    assert main(["recognise", str(tmp_path / "short.npy"), "--out", str(tmp_path / "l.csv")]) == 2
    assert "must be (F, 22)" in capsys.readouterr().err
    assert main(["recognise", str(files["s"]), "--out", str(tmp_path / "l.csv")]) == 2
    assert "need --source-neutral, --target-mesh, --target-landmarks" in capsys.readouterr().err
    assert main(["muscles", str(files["mesh"]), "--landmarks", str(files["t0_nolayout"]),
                 "--out", str(tmp_path / "m.json")]) == 2
    assert "needs the landmarks' layout" in capsys.readouterr().err
