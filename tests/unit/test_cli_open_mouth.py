"""``retarget open-mouth`` on the built-in face with its lips welded
(`retarget.testing.welded`): the written mesh keeps the original vertices first and
unchanged, appends the cut's duplicates with their uv, and the written landmarks are valid
on it and where they were; lips that are already separate are refused with status 2."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from retarget.cli import main
from retarget.landmarks import load_landmarks
from retarget.layouts import get_layout
from retarget.lips import lip_crease, lips_joined
from retarget.mesh import load_mesh, mesh_from_arrays, save_mesh
from retarget.sample_face import sample_face
from retarget.testing.welded import welded_lips_face

IBUG = get_layout("ibug68")


@pytest.fixture(scope="module")
def welded(tmp_path_factory):
    """(folder, WeldedFace) with welded.obj (uv kept) and t0.json (ibug68 vertex indices)."""
    folder = tmp_path_factory.mktemp("open_mouth")
    face = welded_lips_face(1)
    save_mesh(mesh_from_arrays(face.vertices, face.faces, uv=face.uv), folder / "welded.obj")
    (folder / "t0.json").write_text(json.dumps({"vertex_indices": face.landmarks68.tolist(),
                                                "layout": "ibug68"}))
    return folder, face


def test_open_mouth_appends_the_cut_and_keeps_everything_else(welded, capsys):
    folder, face = welded
    status = main(["open-mouth", str(folder / "welded.obj"), "--landmarks", str(folder / "t0.json"),
                   "--out", str(folder / "opened.obj"), "--landmarks-out", str(folder / "t0_opened.json")])
    assert status == 0, capsys.readouterr().err
    assert "vertices on the lip contact line duplicated" in capsys.readouterr().out
    before = load_mesh(folder / "welded.obj")
    opened = load_mesh(folder / "opened.obj")
    v, k = before.n_vertices, len(face.welded)
    assert opened.n_vertices == v + k and opened.n_faces == before.n_faces
    # the originals first, unchanged and in order; the duplicates copy the contact line's
    # vertices (the welded ones), uv included, in the line's order
    np.testing.assert_array_equal(opened.vertices[:v], before.vertices)
    np.testing.assert_array_equal(opened.uv[:v], before.uv)
    t0 = load_landmarks(folder / "t0.json", before.vertices, before.faces)
    cut = lip_crease(before.vertices, before.faces, t0, IBUG)[0][1:-1]
    assert set(cut.tolist()) == set(face.welded.tolist())
    # a hair below (`CUT_GAP` mouth widths), so the rig's weld by position keeps them
    below = np.linalg.norm(opened.vertices[v:] - before.vertices[cut], axis=1)
    assert (below > 0).all() and (below < 0.01 * np.ptp(before.vertices[:, 0])).all()
    np.testing.assert_array_equal(opened.uv[v:], before.uv[cut])
    # the landmarks are valid on the opened mesh, at the same spots, and the lips now separate
    points = load_landmarks(folder / "t0_opened.json", opened.vertices, opened.faces)
    assert points.layout == "ibug68"
    np.testing.assert_allclose(points.positions(opened.vertices), before.vertices[face.landmarks68])
    assert not lips_joined(opened.vertices, opened.faces, points, IBUG)


def test_separate_lips_are_refused_without_a_traceback(tmp_path):
    face = sample_face(1)
    save_mesh(mesh_from_arrays(face.vertices, face.faces), tmp_path / "face.obj")
    (tmp_path / "t0.json").write_text(json.dumps({"vertex_indices": face.landmarks68.tolist()}))
    done = subprocess.run(
        [sys.executable, "-m", "retarget.cli", "open-mouth", str(tmp_path / "face.obj"),
         "--landmarks", str(tmp_path / "t0.json"), "--layout", "ibug68",
         "--out", str(tmp_path / "out.obj"), "--landmarks-out", str(tmp_path / "out.json")],
        capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert "retarget: error: the lips are already separate" in done.stderr
    assert "Traceback" not in done.stderr
    assert not (tmp_path / "out.obj").exists() and not (tmp_path / "out.json").exists()


def test_a_mesh_without_a_layout_or_to_stl_is_refused(welded, tmp_path, capsys):
    folder, face = welded
    (tmp_path / "bare.json").write_text(json.dumps({"vertex_indices": face.landmarks68.tolist()}))
    args = ["open-mouth", str(folder / "welded.obj"), "--landmarks-out", str(tmp_path / "o.json")]
    assert main(args + ["--landmarks", str(tmp_path / "bare.json"), "--out", str(tmp_path / "o.obj")]) == 2
    assert "give --layout" in capsys.readouterr().err
    assert main(args + ["--landmarks", str(folder / "t0.json"), "--out", str(tmp_path / "o.stl")]) == 2
    assert "STL keeps no vertex order" in capsys.readouterr().err
