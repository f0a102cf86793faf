"""Expression recognition from contraction vectors (retarget.muscles.expressions)."""

from __future__ import annotations

import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.muscles.expressions import (EXPRESSIONS, ExpressionRecogniser, default_recogniser,
                                          paper_presets)
from retarget.muscles.table import dof_names

NAMES = dof_names()


def test_the_paper_presets_recognise_themselves_at_any_intensity_and_rest_is_neutral():
    rec = paper_presets(NAMES)
    for k, e in enumerate(EXPRESSIONS[1:], start=1):
        for t in (0.4, 0.7, 1.0):
            assert rec.recognise(t * rec.presets[k]).labels[0] == e
    out = rec.recognise(np.zeros(len(NAMES)))
    assert out.labels[0] == "neutral" and out.distances[0, 0] == 0.0
    assert 0.0 < out.confidence[0] <= 1.0
    # a faint expression, under t_min of its preset, is still neutral
    assert rec.recognise(0.1 * rec.presets[EXPRESSIONS.index("fear")]).labels[0] == "neutral"


def test_a_segment_distance_beats_the_paper_s_point_distance_on_faint_expressions():
    rec = paper_presets(NAMES)
    smile = 0.45 * rec.presets[EXPRESSIONS.index("happiness")]
    assert rec.recognise(smile).labels[0] == "happiness"
    point = np.linalg.norm(smile - rec.presets, axis=1)  # the paper's distance, t = 1 only
    assert EXPRESSIONS[int(np.argmin(point))] != "happiness"


def test_fitted_presets_learn_directions_and_spread_and_survive_json():
    rng = np.random.default_rng(0)
    truth = paper_presets(NAMES).presets
    rows, labels, levels = [], [], []
    for k, e in enumerate(EXPRESSIONS):
        for t in (0.5, 0.75, 1.0) * 4:
            rows.append(t * truth[k] + rng.normal(0, 0.03, len(NAMES)))
            labels.append(e)
            levels.append(0.0 if e == "neutral" else t)
    rec = ExpressionRecogniser.fit(NAMES, np.array(rows), labels, levels)
    assert np.abs(rec.presets - truth).max() < 0.05
    assert np.allclose(rec.scale, 0.03, rtol=0.35)
    test = [t * truth[k] + rng.normal(0, 0.03, len(NAMES)) for k in range(7) for t in (0.6, 0.9)]
    want = [e for e in EXPRESSIONS for _ in range(2)]
    assert list(rec.recognise(np.array(test)).labels) == want
    again = ExpressionRecogniser.from_json(rec.to_json())
    assert np.allclose(again.distances(np.array(test)), rec.distances(np.array(test)), atol=1e-5)


def test_the_shipped_recogniser_matches_the_model_s_dofs():
    rec = default_recogniser(NAMES)
    assert rec.names == NAMES and rec.labels == EXPRESSIONS
    assert np.all(rec.presets[0] == 0)


def test_bad_input_is_refused_with_a_reason():
    rec = paper_presets(NAMES)
    with pytest.raises(RetargetError, match="22 values"):
        rec.distances(np.zeros(5))
    with pytest.raises(RetargetError, match="no samples of"):
        ExpressionRecogniser.fit(NAMES, np.zeros((2, len(NAMES))), ["neutral", "fear"], [0, 1])
    with pytest.raises(RetargetError, match="no DOF named"):
        paper_presets(NAMES[:5])
