"""The muscles' played form (retarget.muscles.morphs): morph targets and a jaw joint."""

from __future__ import annotations

import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.muscles import place_muscles
from retarget.muscles.morphs import muscle_morphs, played_displacements, played_error
from retarget.sample_face import sample_face


@pytest.fixture(scope="module")
def model():
    face = sample_face()
    return place_muscles(face.vertices, face.faces, face.vertices[face.landmarks68])


def test_with_the_jaw_closed_the_played_form_is_the_exact_muscles(model):
    morphs = muscle_morphs(model)
    assert morphs.targets.shape == (21, len(model.rest), 3) and morphs.names == model.names[:-1]
    rng = np.random.default_rng(1)
    for _ in range(3):
        c = rng.uniform(model.limits[:, 0], model.limits[:, 1])
        c[-1] = 0.0
        assert np.allclose(played_displacements(morphs, model.rest, c), model.displacements(c), atol=1e-5)
    assert not played_displacements(morphs, model.rest, np.zeros(22)).any()


def test_the_jaw_joint_opens_the_mouth_as_the_model_does_and_the_error_is_bounded(model):
    morphs = muscle_morphs(model)
    c = np.zeros(22)
    c[-1] = model.limits[-1, 1]
    exact, played = model.displacements(c), played_displacements(morphs, model.rest, c)
    moving = np.linalg.norm(exact, axis=1) > 1e-3
    assert moving.sum() > 100
    cos = np.einsum("vi,vi->v", exact[moving], played[moving]) / (
        np.linalg.norm(exact[moving], axis=1) * np.linalg.norm(played[moving], axis=1))
    assert cos.min() > 0.95  # the same motion, blended where the model turns by a share of the angle
    assert played_error(model, n_samples=16) < 0.2
    with pytest.raises(RetargetError, match="22 values"):
        morphs.weights(np.zeros(5))


def test_correctives_add_each_muscles_exact_motion_to_the_open_jaw_and_halve_the_error(model):
    morphs, plain = muscle_morphs(model), muscle_morphs(model, correctives=False)
    assert len(plain.corrective_of) == 0 and plain.correctives.shape[0] == 0
    names = set(morphs.corrective_names)
    # the mouth muscles the jaw carries the lower lip through; nothing on the brows or eyes
    assert {"orbicularis_oris*jaw", "zygomatic_major_left*jaw", "depressor_anguli_oris_right*jaw"} <= names
    assert not any(n.startswith(("frontalis", "corrugator", "orbicularis_oculi")) for n in names)
    assert morphs.correctives.shape == (len(names), len(model.rest), 3)
    opened = np.zeros(22)
    opened[-1] = model.limits[-1, 1]
    jaw_off = played_displacements(morphs, model.rest, opened) - model.displacements(opened)
    for m in morphs.corrective_of:
        c = opened.copy()
        c[m] = model.limits[m, 1]
        off = played_displacements(morphs, model.rest, c) - model.displacements(c)
        assert np.abs(off - jaw_off).max() < 1e-4  # cm: the muscle's own part is exact
    assert np.allclose(morphs.corrective_weights(c), np.where(morphs.corrective_of == m, 1.0, 0.0))
    half = c * 0.5
    assert np.allclose(morphs.corrective_weights(half)[list(morphs.corrective_of).index(m)], 0.25)
    # closed jaw: the correctives weigh nothing, the form stays exact
    closed = c.copy()
    closed[-1] = 0.0
    assert np.allclose(played_displacements(morphs, model.rest, closed), model.displacements(closed),
                       atol=1e-5)
    with_, without = played_error(model, n_samples=16), played_error(model, n_samples=16, correctives=False)
    assert with_ < 0.6 * without
