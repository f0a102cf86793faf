"""Woodward's virtual muscles (retarget.muscles): placement from landmarks, each muscle's
motion, the jaw and the lips, the Jacobian, JSON, units, layouts and the linear form."""

import json

import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.layouts import get_layout
from retarget.muscles import (
    MUSCLE_TABLE,
    MuscleFace,
    dof_names,
    linearisation_error,
    place_muscles,
)
from retarget.sample_face import sample_face
from retarget.testing.seams import seam_split

# iBUG 68: subject's left brow 22 (inner) .. 26, right 21 .. 17; eyes 42-47 / 36-41;
# upper lids 43, 44 / 37, 38; lower lids 46, 47 / 40, 41; mouth corners 54 / 48
UPPER_LIP = [49, 50, 51, 52, 53, 61, 62, 63]
LOWER_LIP = [55, 56, 57, 58, 59, 65, 66, 67]


@pytest.fixture(scope="module")
def face():
    return sample_face()


@pytest.fixture(scope="module")
def model(face):
    return place_muscles(face.vertices, face.faces, face.vertices[face.landmarks68])


def _moved(model, face, **dofs):
    """(68, 3) landmark displacements for the named dofs (others 0)."""
    c = np.zeros(model.n_dof)
    for name, value in dofs.items():
        c[model.names.index(name)] = value
    return model.displacements(c)[face.landmarks68]


def test_table_and_dofs_follow_the_paper(model):
    assert sum(1 if r.side == "midline" else 2 for r in MUSCLE_TABLE) == 21
    assert sorted(n for r in MUSCLE_TABLE for n in r.numbers) == list(range(1, 22))
    assert model.names == dof_names() and model.n_dof == 22 and model.names[-1] == "jaw"
    assert "zygomatic_major_left" in model.names and "orbicularis_oris" in model.names
    assert model.limits.shape == (22, 2) and (model.limits[:, 0] <= 0).all() and (model.limits[:, 1] > 0).all()
    assert {m.kind for m in model.muscles} == {"linear", "sphincter"}


def test_zero_contraction_is_zero_displacement(model):
    c = np.zeros(model.n_dof)
    assert not model.displacements(c).any()
    assert model.displacements(c).shape == model.rest.shape


@pytest.mark.parametrize("side, sx, corner", [("left", 1, 54), ("right", -1, 48)])
def test_mouth_muscles_move_the_corner(model, face, side, sx, corner):
    d = _moved(model, face, **{f"zygomatic_major_{side}": 1.0})
    assert d[corner, 1] > 0.5 and d[corner, 2] < 0 and sx * d[corner, 0] > 0   # up, back, out
    assert np.abs(d[102 - corner]).max() < 1e-9                                  # not the other corner
    d = _moved(model, face, **{f"depressor_anguli_oris_{side}": 1.0})
    assert d[corner, 1] < -0.3
    d = _moved(model, face, **{f"levator_labii_superioris_{side}": 1.0})
    upper = 52 if side == "left" else 50
    assert d[upper, 1] > 0.3 and abs(d[8, 1]) < 1e-9
    d = _moved(model, face, **{f"levator_labii_superioris_alaeque_nasi_{side}": 1.0})
    ala = 35 if side == "left" else 31
    assert d[ala, 1] > 0.3


@pytest.mark.parametrize("side, sx", [("left", 1), ("right", -1)])
def test_brow_and_eye_muscles(model, face, side, sx):
    brow = {"inner": 22, "major": 23, "secondary": 24, "outer": 25}
    for part, k in brow.items():
        k = k if side == "left" else 43 - k
        d = _moved(model, face, **{f"frontalis_{part}_{side}": 1.0})
        assert d[k, 1] > 0.2, part                                            # raises the brow
        assert abs(d[8, 1]) < 1e-9 and np.abs(d[48:68]).max() < 1e-9
    d = _moved(model, face, **{f"corrugator_supercilii_{side}": 1.0})
    for k in (22, 23, 24) if side == "left" else (21, 20, 19):
        assert d[k, 1] < -0.05 and sx * d[k, 0] < 0                           # down and inward
    upper, lower = ((43, 44), (47, 46)) if side == "left" else ((38, 37), (40, 41))
    gap = face.vertices[face.landmarks68][list(upper), 1] - face.vertices[face.landmarks68][list(lower), 1]
    for c, narrower in ((1.0, True), (-1.0, False)):
        d = _moved(model, face, **{f"orbicularis_oculi_{side}": c})
        new_gap = gap + d[list(upper), 1] - d[list(lower), 1]
        assert (new_gap < gap).all() if narrower else (new_gap > gap).all()


def test_orbicularis_oris_purses(model, face):
    d = _moved(model, face, orbicularis_oris=1.0)
    assert d[48, 0] > 0.3 and d[54, 0] < -0.3                # corners in
    assert d[51, 1] < 0 and d[57, 1] > 0                      # lips together
    assert d[51, 2] > 0                                       # and forward


def test_jaw_opens_the_mouth_and_the_lips_part(model, face):
    lm = face.landmarks68
    d = _moved(model, face, jaw=0.3)
    assert d[8, 1] < -1.0                                     # chin down
    assert np.abs(d[UPPER_LIP]).max() < 1e-9                  # upper lip stays
    assert (d[LOWER_LIP, 1] < -0.7).all()                     # lower lip follows the jaw
    assert np.abs(d[17:48]).max() < 0.01 * np.abs(d[8]).max()   # brows, nose, eyes stay
    rest_gap = face.vertices[lm[62], 1] - face.vertices[lm[66], 1]
    assert rest_gap - (d[66, 1] - d[62, 1]) > rest_gap + 1.0  # the gap opens by > 1 cm
    w = model.jaw.weights
    assert w.min() == 0 and w.max() == 1 and (w[lm[UPPER_LIP]] == 0).all() and (w[lm[LOWER_LIP]] > 0.99).all()


def test_jaw_moves_vertices_out_of_mouth_muscle_zones(model, face):
    """§4.2: a lower-lip vertex the jaw carries out of the zygomatic's zone is left alone."""
    moved = np.zeros(model.n_dof)
    moved[model.names.index("zygomatic_major_left")] = 1.0
    open_ = moved.copy()
    open_[-1] = model.limits[-1, 1]
    jaw_only = np.zeros(model.n_dof)
    jaw_only[-1] = model.limits[-1, 1]
    lm = face.landmarks68
    at_rest = model.displacements(moved)[lm[[55, 65]]]
    with_jaw = model.displacements(open_)[lm[[55, 65]]] - model.displacements(jaw_only)[lm[[55, 65]]]
    assert (np.linalg.norm(at_rest, axis=1) > 0.3).all()
    assert (np.linalg.norm(with_jaw, axis=1) < 0.5 * np.linalg.norm(at_rest, axis=1)).all()


def test_jacobian_matches_finite_differences_and_restricted_matches_full(model, face):
    rng = np.random.default_rng(1)
    ids = face.landmarks68
    small = model.restricted(ids)
    for k in range(3):
        c = rng.uniform(model.limits[:, 0], model.limits[:, 1])
        c[-1] *= k > 0                                        # the first with the jaw closed
        np.testing.assert_allclose(small.displacements(c), model.displacements(c)[ids], atol=1e-12)
        j = small.jacobian(c)
        np.testing.assert_allclose(j, model.jacobian(c)[ids], atol=1e-10)
        fd = np.empty_like(j)
        for k in range(model.n_dof):
            h = np.zeros(model.n_dof)
            h[k] = 1e-6
            fd[:, :, k] = (small.displacements(c + h) - small.displacements(c - h)) / 2e-6
        assert np.abs(fd - j).max() <= 1e-5 * np.abs(j).max()


def test_json_round_trip(model, face):
    data = json.loads(json.dumps(model.to_json()))
    again = MuscleFace.from_json(data, face.vertices)
    assert again.names == model.names
    c = np.random.default_rng(2).uniform(model.limits[:, 0], model.limits[:, 1])
    np.testing.assert_allclose(again.displacements(c), model.displacements(c), atol=1e-12)
    np.testing.assert_array_equal(again.limits, model.limits)
    with pytest.raises(RetargetError, match="vertices"):
        MuscleFace.from_json(data, face.vertices[:100])
    one_value = json.loads(json.dumps(data))
    one_value["jaw"]["weights"]["values"] = [1.0]  # not one weight for every jaw vertex
    with pytest.raises(RetargetError, match="1 values for"):
        MuscleFace.from_json(one_value, face.vertices)


def test_units_and_orientation_follow_the_mesh(model, face):
    """A face in metres-times-100 (or rotated) gets the same muscles in its own units/axes."""
    rot = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])   # face lying on its side
    v = 100.0 * face.vertices @ rot.T
    other = place_muscles(v, face.faces, v[face.landmarks68])
    c = np.random.default_rng(3).uniform(model.limits[:, 0], model.limits[:, 1])
    np.testing.assert_allclose(other.displacements(c), 100.0 * model.displacements(c) @ rot.T, atol=1e-6)


def test_other_layouts(model, face):
    dense = get_layout("mediapipe468")
    other = place_muscles(face.vertices, face.faces, dense.reference_points(), dense)
    c = np.random.default_rng(4).uniform(model.limits[:, 0], model.limits[:, 1])
    np.testing.assert_allclose(other.displacements(c), model.displacements(c), atol=1e-9)
    few = get_layout("dutreve21")
    sparse = place_muscles(face.vertices, face.faces, few.reference_points(), few)
    c = np.zeros(22)
    c[sparse.names.index("zygomatic_major_left")] = 1
    assert sparse.displacements(c)[face.landmarks68[54], 1] > 0.5
    with pytest.raises(RetargetError, match="points"):
        place_muscles(face.vertices, face.faces, np.zeros((5, 3)), "ibug68")


def test_bad_contractions_are_refused(model):
    with pytest.raises(RetargetError, match="22"):
        model.displacements(np.zeros(21))
    with pytest.raises(RetargetError):
        model.jacobian(np.full(22, np.nan))
    with pytest.raises(RetargetError, match="vertex_ids"):
        model.restricted(np.array([len(model.rest)]))


def test_linearised_fields_and_their_error(model):
    fields = model.linearised()
    assert fields.shape == (22, len(model.rest), 3) and fields.dtype == np.float32
    j0 = model.jacobian(np.zeros(22))
    np.testing.assert_allclose(fields[:-1], (j0[:, :, :-1] * model.limits[:-1, 1]).transpose(2, 0, 1), atol=1e-5)
    err = linearisation_error(model, n_samples=8)
    assert 0.0 < err < 0.25


def test_a_uv_seam_through_the_lips_leaves_the_jaw_weights_as_they_were(model, face):
    # the lips' share of the jaw is found along the surface: a seam (glTF's copies of the
    # vertices along a uv cut) was a wall there, and the weights past it fell back to the
    # plain height rule
    vertices, faces, seam, copies = seam_split(face.vertices, face.faces, x=0.3)
    split = place_muscles(vertices, faces, vertices[face.landmarks68])
    w = split.jaw.weights
    np.testing.assert_allclose(w[: len(face.vertices)], model.jaw.weights, atol=1e-12)
    np.testing.assert_array_equal(w[copies], w[seam])
