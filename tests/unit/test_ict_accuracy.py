"""Cross-identity retargeting on the ICT face model (skips when ../shared is absent).

The benchmark's own code (bench/accuracy.py) on a small expression set: the default
pipeline must beat the paper's method in every source condition, keep the lips apart, and
be blind to the performer's scale, rotation and translation.
"""

import numpy as np
import pytest

from bench.ict import DATA

pytestmark = pytest.mark.skipif(not DATA.exists(), reason="ICT data set (../shared) not present")


@pytest.fixture(scope="module")
def rows():
    from bench.accuracy import run
    from retarget.pipeline import DEFAULT_KERNEL
    from retarget.weights import DEFAULT_METHOD

    out = run(seed=3, n_random=4, methods=[DEFAULT_METHOD], kernel=DEFAULT_KERNEL,
              smoothing=None, true_motion=True)
    return {(r["setup"], r["condition"]): r for r in out}


def test_default_beats_the_paper_in_every_condition(rows):
    from retarget.weights import DEFAULT_METHOD

    for cond in ("same", "foreign", "2d"):
        ours, paper = rows[(DEFAULT_METHOD, cond)], rows[("paper", cond)]
        assert ours["rel"] < paper["rel"] - 0.08, cond
        assert ours["mouth"] < paper["mouth"], cond


def test_default_keeps_the_lips_apart_and_the_paper_does_not(rows):
    from retarget.weights import DEFAULT_METHOD

    ours, paper = rows[(DEFAULT_METHOD, "same")], rows[("paper", "same")]
    assert ours["leak_upper"] == 0.0 and ours["leak_lower"] == 0.0
    assert paper["leak_upper"] > 0.2


def test_performer_pose_and_size_do_not_matter(rows):
    from retarget.weights import DEFAULT_METHOD

    same, foreign = rows[(DEFAULT_METHOD, "same")], rows[(DEFAULT_METHOD, "foreign")]
    assert np.isclose(same["rel"], foreign["rel"], rtol=1e-4)


def test_our_transfer_adds_less_error_than_the_papers(rows):
    """Transfer error = error with transferred features minus error with the true ones."""
    from retarget.weights import DEFAULT_METHOD

    def added(setup):
        return rows[(setup, "same")]["rel"] - rows[(setup, "true")]["rel"]

    assert 0.0 <= added(DEFAULT_METHOD) < 0.8 * added("paper")
