"""Muscle IK (`retarget.muscles.ik`, Woodward §7): known contractions are recovered, the limits
hold, warm starts pay, lost points are ignored, both solvers converge.

A stand-in model (`StandInFace`: 21 smooth displacement fields, mildly non-linear in the
contraction, then a jaw rotation about an axis) honours the `MuscleFace` contract of
the project's muscle spec, so the solvers are tested apart from the muscle model; the same
properties are checked on the real model (`place_muscles` on the built-in sample face).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
import pytest

from retarget.errors import RetargetError
from retarget.muscles import place_muscles
from retarget.muscles.ik import IKResult, MuscleIK, solve
from retarget.sample_face import sample_face


class StandInFace:
    """A `MuscleFace` stand-in: D = 22 DOFs, 21 "muscles" then a "jaw".

    Muscle m moves vertex v by (c_m + 0.5 c_m^2) F[m, v] (F: (21, V, 3) cm, a Gaussian bump
    pulling toward an origin), then the jaw rotates each vertex by w_v * theta about the x
    axis through `pivot` (w_v: 1 low on the face, 0 high): non-linear in c and coupled.
    """

    def __init__(self, rest, fields, weights, pivot):
        self.rest = rest
        self.fields = fields
        self.weights = weights
        self.pivot = pivot
        self.names = tuple(f"muscle_{i}" for i in range(len(fields))) + ("jaw",)
        self.limits = np.array([[0.0, 1.0]] * len(fields) + [[0.0, 0.35]])

    @classmethod
    def build(cls, n_vertices: int = 400, seed: int = 0) -> StandInFace:
        rng = np.random.default_rng(seed)
        rest = rng.uniform([-7, -10, 0], [7, 8, 3], size=(n_vertices, 3))
        centres = rng.uniform([-6, -8, 1], [6, 6, 2], size=(21, 3))
        origins = centres + rng.normal(size=(21, 3)) * [3, 3, 0.5]
        radius = rng.uniform(2.5, 4.5, size=21)
        pull = origins[:, None] - rest[None]                       # (21, V, 3) toward origin
        pull /= np.linalg.norm(pull, axis=2, keepdims=True)
        fall = np.exp(-(np.linalg.norm(rest[None] - centres[:, None], axis=2) / radius[:, None]) ** 2)
        fields = 0.8 * fall[..., None] * pull                      # up to 8 mm at full contraction
        weights = np.clip((-rest[:, 1] - 1.0) / 4.0, 0.0, 1.0)      # jaw: below y = -1 cm
        return cls(rest, fields, weights, np.array([0.0, 2.0, -8.0]))

    @property
    def n_dof(self) -> int:
        return len(self.limits)

    def _muscled(self, c):
        return self.rest + np.einsum("m,mvk->vk", c[:-1] + 0.5 * c[:-1] ** 2, self.fields)

    def _rotation(self, theta):
        """(V, 3, 3) per-vertex rotation about x by w_v * theta (jaw opening: chin down)."""
        phi = -self.weights * theta
        cos, sin = np.cos(phi), np.sin(phi)
        r = np.zeros((len(phi), 3, 3))
        r[:, 0, 0] = 1.0
        r[:, 1, 1], r[:, 1, 2], r[:, 2, 1], r[:, 2, 2] = cos, -sin, sin, cos
        return r

    def displacements(self, c):
        c = np.asarray(c, float)
        p = self._muscled(c) - self.pivot
        return np.einsum("vij,vj->vi", self._rotation(c[-1]), p) + self.pivot - self.rest

    def jacobian(self, c):
        c = np.asarray(c, float)
        r = self._rotation(c[-1])
        j = np.empty((len(self.rest), 3, self.n_dof))
        j[:, :, :-1] = np.einsum("vij,mvj->vim", r, self.fields) * (1.0 + c[:-1])
        q = np.einsum("vij,vj->vi", r, self._muscled(c) - self.pivot)
        # d/dtheta of R(-w theta) q0 about x: -w * (x_axis cross q)
        j[:, :, -1] = -self.weights[:, None] * np.cross([1.0, 0.0, 0.0], q)
        return j

    def restricted(self, vertex_ids):
        ids = np.asarray(vertex_ids)
        return StandInFace(self.rest[ids], self.fields[:, ids], self.weights[ids], self.pivot)


@pytest.fixture(scope="module")
def standin():
    return StandInFace.build()


def _real_face():
    """The muscles placed on the built-in face, and its 68 marked (landmark) vertex ids."""
    face = sample_face()
    ids = face.landmarks68
    return place_muscles(face.vertices, face.faces, face.vertices[ids], "ibug68"), ids


@pytest.fixture(scope="module", params=["standin", "real"])
def face(request, standin):
    """(whole model, (68,) marked vertex ids)."""
    if request.param == "standin":
        return standin, np.arange(0, 400, 400 // 68)[:68]
    return _real_face()


def _contractions(model, rng, scale=0.6):
    """(D,) random contractions inside the limits, jaw included, away from the bounds."""
    low, high = model.limits.T
    return low + (high - low) * rng.uniform(0.05, scale, size=len(low))


def test_standin_jacobian_matches_finite_differences(standin):
    # The stand-in must honour the contract itself, or the tests below prove nothing.
    c = _contractions(standin, np.random.default_rng(1))
    j = standin.jacobian(c)
    h = 1e-6
    fd = np.stack([(standin.displacements(c + h * e) - standin.displacements(c - h * e)) / (2 * h)
                   for e in np.eye(standin.n_dof)], axis=-1)
    assert np.allclose(j, fd, rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("method", ["dls", "transpose"])
def test_recovers_known_contractions(face, method):
    model, ids = face
    sub = model.restricted(ids)
    rng = np.random.default_rng(2)
    for _ in range(3):
        truth = _contractions(model, rng)
        targets = sub.rest + sub.displacements(truth)
        result = solve(sub, targets, method=method, tol=1e-10,
                       max_iterations=None if method == "dls" else 5000)
        assert isinstance(result, IKResult)
        scale = np.abs(sub.displacements(truth)).max()
        # Exactly representable targets: DLS lands on them; the transpose (steepest descent,
        # slow on overlapping muscles) gets within a few thousandths of the motion.
        if method == "dls":
            assert result.residual < 1e-6 * scale
            assert np.abs(result.c - truth).max() < 1e-4
        else:
            assert result.residual < 5e-3 * scale
            assert np.abs(result.c - truth).max() < 0.1


@pytest.mark.parametrize("method", ["dls", "transpose"])
def test_respects_limits_when_target_asks_for_more(face, method):
    model, ids = face
    sub = model.restricted(ids)
    low, high = model.limits.T
    rng = np.random.default_rng(3)
    truth = _contractions(model, rng)
    beyond = truth.copy()
    beyond[[0, 5]] = high[[0, 5]] + 0.8 * (high - low)[[0, 5]]   # more than the muscle can give
    beyond[-1] = high[-1] * 1.5                                   # the jaw past its hinge's range
    wanted = sub.displacements(beyond)
    result = solve(sub, sub.rest + wanted, method=method)
    assert np.all(result.c >= low) and np.all(result.c <= high)
    # The answer is the best one within range: as good as a general bounded least-squares
    # solver's (SciPy's trust-region reflective), and the DOFs pushed past their range end
    # at the bound (not those the jaw's pull on the muscles' zones lets stop short of it).
    def residual(c):
        return (sub.displacements(c) - wanted).ravel()

    best = least_squares(residual, truth, bounds=(low, high), jac=lambda c: sub.jacobian(c).reshape(-1, len(low)))
    assert np.linalg.norm(residual(result.c)) <= np.linalg.norm(residual(best.x)) * (1 + 1e-3)
    assert result.c[-1] > high[-1] - 0.05 * (high - low)[-1]
    # And a target below the range (negative contractions) stops at the lower bound.
    below = solve(sub, sub.rest - 0.5 * sub.displacements(truth), method=method)
    assert np.all(below.c >= low) and np.all(below.c <= high)


def _trajectory(model, n_frames, rng):
    """(F, D) smooth contractions: random sines per DOF inside the limits (30 fps, 0.2-0.6 Hz)."""
    low, high = model.limits.T
    t = np.arange(n_frames)[:, None] / 30.0
    f = rng.uniform(0.2, 0.6, size=len(low))
    phase = rng.uniform(0, 2 * np.pi, size=len(low))
    return low + (high - low) * (0.35 + 0.3 * np.sin(2 * np.pi * f * t + phase))


@pytest.mark.parametrize("method", ["dls", "transpose"])
def test_warm_start_needs_fewer_iterations(face, method):
    model, ids = face
    truth = _trajectory(model, 12, np.random.default_rng(4))
    # Both stop at the same accuracy (10 um RMS on a face in cm), so iterations compare.
    options = dict(method=method, atol=1e-3, max_iterations=2000)
    ik = MuscleIK(model, ids, **options)
    sub = ik.model_
    warm, cold = [], []
    for c in truth:
        d = sub.displacements(c)
        ik.push(d)
        warm.append(ik.result_.iterations)
        cold.append(solve(sub, sub.rest + d, **options).iterations)
        assert ik.result_.residual <= 1e-3
    # The first frame starts from rest either way; after it, each frame starts next to its answer.
    assert warm[0] == cold[0]
    assert sum(warm[1:]) < 0.7 * sum(cold[1:])


@pytest.mark.parametrize("method", ["dls", "transpose"])
def test_nan_rows_are_ignored(face, method):
    model, ids = face
    ik = MuscleIK(model, ids, method=method, tol=1e-10,
                  max_iterations=None if method == "dls" else 5000)
    sub = ik.model_
    truth = _contractions(model, np.random.default_rng(5))
    d = sub.displacements(truth)
    kept = np.ones(len(d), bool)
    kept[::4] = kept[1] = False                   # a quarter of the points lost, and one more
    lost = d.copy()
    lost[::4] = np.nan
    lost[1, 2] = np.inf                           # one bad coordinate loses the whole row
    garbled = d.copy()
    garbled[~kept] += 1.0                         # what the lost rows would do if they counted
    scale = np.abs(d).max()

    def kept_error(c):
        return np.abs(sub.displacements(c)[kept] - d[kept]).max()

    c = ik.push(lost)
    assert np.isfinite(c).all() and np.isfinite(ik.result_.residual)
    # The kept points are still matched as if the lost ones never existed (the contractions
    # themselves need not come back: without those points some muscles may be unobservable).
    assert kept_error(c) < (1e-5 if method == "dls" else 5e-3) * scale
    assert ik.result_.residual < (1e-5 if method == "dls" else 5e-3) * scale
    ik.reset()
    assert kept_error(ik.push(garbled)) > 10 * kept_error(c)
    # No point at all: hold the last frame.
    before = ik.c_.copy()
    held = ik.push(np.full_like(d, np.nan))
    assert np.array_equal(held, before) and ik.result_.iterations == 0


def test_dls_and_transpose_converge_to_the_same_answer(face):
    model, ids = face
    sub = model.restricted(ids)
    truth = _contractions(model, np.random.default_rng(6))
    # Tracker-like noise: the answer is a least-squares compromise, not exactly representable.
    targets = sub.rest + sub.displacements(truth) + np.random.default_rng(7).normal(0, 0.02, sub.rest.shape)
    dls = solve(sub, targets, method="dls", tol=1e-12)
    tr = solve(sub, targets, method="transpose", tol=1e-12, max_iterations=20000)
    assert dls.residual <= tr.residual * (1 + 1e-3)
    assert tr.residual <= dls.residual * 1.05
    assert np.abs(dls.c - truth).max() < 0.1


def test_rest_jacobian_chord_method_converges(standin):
    ids = np.arange(0, 400, 400 // 68)[:68]
    ik = MuscleIK(standin, ids, method="dls", jacobian="rest", tol=1e-10, max_iterations=200)
    truth = _contractions(standin, np.random.default_rng(8))
    c = ik.push(ik.model_.displacements(truth))
    assert np.abs(c - truth).max() < 1e-4


def test_bad_input_is_refused(standin):
    sub = standin.restricted(np.arange(10))
    with pytest.raises(RetargetError, match="targets"):
        solve(sub, np.zeros((9, 3)))
    with pytest.raises(RetargetError, match="method"):
        solve(sub, sub.rest, method="newton")
    with pytest.raises(RetargetError, match="c0"):
        solve(sub, sub.rest, c0=np.zeros(3))
    with pytest.raises(RetargetError, match="marked_vertices"):
        MuscleIK(standin, [0, 400])
    with pytest.raises(RetargetError, match="target_displacements"):
        MuscleIK(standin, [0, 1]).push(np.zeros((3, 3)))
    # Rest targets: zero contractions, (rounding-)zero residual.
    result = solve(sub, sub.rest, method="dls")
    assert np.array_equal(result.c, np.zeros(standin.n_dof)) and result.residual < 1e-12
