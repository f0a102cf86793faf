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
