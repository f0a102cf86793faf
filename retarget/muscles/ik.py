"""Muscle inverse kinematics: the contractions and jaw angle that put a face's marked
vertices on their targets.

Woodward et al. (`../shared/papers/woodward-stereo-markers-muscle-ik.txt`) §7: each marked
vertex e is the end effector of a chain of one-DOF joints (the muscle contractions, linear
joints, and the jaw rotation, an angular one); the tracked marker is its goal g. The
contraction vector c (D,) is found by iterating first-order steps on the error d = g - e
(§7.1, eq. 9-11) until the vertices stop improving, every DOF kept in its valid range.

Two solvers, both on the same stacked Jacobian J = d displacements / d c, (3K, D):

- ``transpose``: the paper's Jacobian-transpose step (§7.2, eq. 12-13, after Baxter 2000),
  dc = alpha s with s = J^T d. The paper tunes the scale beta by hand; here each DOF's
  component of s is divided by its column's squared norm (a per-DOF beta, optional) and
  alpha is the optimal step along J s for the linearised problem, alpha = <d, J s> / |J s|^2
  (Buss 2004), halved while the exact residual does not decrease (the deformation is
  non-linear, §7.2). No matrix is inverted.
- ``dls``: damped least squares (Levenberg-Marquardt), (J^T J + lambda diag(J^T J)) dc =
  J^T d, lambda adapted by whether the exact residual fell; the DOFs that would leave their
  range are clamped at the bound and the rest solved again (an active-set step). It also
  stops as soon as a nearly undamped step lands where the linearisation forecast (the
  exact error within tol of the forecast one): under tracker noise that is often after
  one iteration of a warm-started frame.

Both project onto the limits (§7.2: "muscles have a physical contraction range"), work in
units scaled by each DOF's range (a jaw in radians and a contraction in [0, 1] then take
comparable steps), and stop when the RMS residual improves by less than ``tol`` of itself,
or falls under ``atol``, or after ``max_iterations``.

`solve` is one problem; `MuscleIK` restricts the model to the marked vertices once and
warm-starts each frame from the last (§7: a performance is a sequence of nearby poses).

Units: displacements, targets and residuals in the mesh's own units; contractions as the
model's limits say (contractions in [0, 1], the jaw angle in radians).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg.lapack import dposv as _dposv

from retarget.errors import RetargetError

METHODS = ("transpose", "dls")
_MAX_ITERATIONS = {"transpose": 200, "dls": 30}
_HALVINGS = 8          # step halvings before a transpose iteration counts as no progress
_LAMBDA0 = 1e-3        # initial Marquardt damping, relative to diag(J^T J)
_LAMBDA_MIN, _LAMBDA_MAX = 1e-9, 1e9
_CONFIRM_LAMBDA = 1e-2  # damping below which a step counts as a Gauss-Newton one
_FLOOR = 1e-9          # residual that counts as exact, relative to the wanted motion's RMS


@dataclass(frozen=True, eq=False)
class IKResult:
    """One solve.

    c : (D,) float64 contractions and jaw angle, within the model's limits.
    iterations : int, Jacobian steps taken (rejected trial steps of one iteration included
        in it, not counted apart).
    residual : float, RMS distance in mesh units between the marked vertices displaced by
        `c` and their targets, over the vertices with a finite target.
    """

    c: np.ndarray
    iterations: int
    residual: float


def solve(model, targets, c0=None, *, method: str = "transpose", max_iterations: int | None = None,
          tol: float = 1e-4, atol: float = 0.0, jacobian=None,
          precondition: bool = True) -> IKResult:
    """The contractions that put `model`'s vertices on `targets` (Woodward §7).

    model : a `MuscleFace` already restricted to the K marked vertices
        (`MuscleFace.restricted`), so one step costs O(K D).
    targets : (K, 3) float, wanted positions of those vertices (rest + wanted displacement),
        mesh units. Rows with a non-finite coordinate (lost points) are left out of the
        residual; if every row is, `c0` comes back unchanged with residual NaN.
    c0 : (D,) float start, clipped to the limits; default the rest pose (0 clipped).
    method : "transpose" (the paper's) or "dls" (damped least squares).
    max_iterations : default 200 for "transpose", 30 for "dls".
    tol : stop once an iteration lowers the RMS residual by less than tol times itself.
    atol : stop once the RMS residual is at most atol (mesh units); it is at least 1e-9 of
        the wanted displacements' RMS, where exact targets reach rounding noise.
    jacobian : optional (K, 3, D) float Jacobian used at every iteration instead of
        evaluating the model's (a chord method: e.g. the rest pose's, precomputed); the
        residual is still the exact one, so the answer stays exact where it converges.
    precondition : "transpose" only: divide each DOF's step by the squared norm of its
        Jacobian column (Jacobi preconditioning). The paper tunes its step scale beta by
        hand (§7.2); this tunes it per DOF, and on overlapping muscles it cuts the
        iterations several-fold (bench/muscles.py). False is the plain transpose step.
    """
    rest = np.asarray(model.rest, dtype=np.float64)
    targets = np.asarray(targets, dtype=np.float64)
    if targets.shape != rest.shape:
        raise RetargetError(f"targets must be {rest.shape} (the model's marked vertices, xyz), "
                            f"got {targets.shape}")
    problem = _Problem(model, method, max_iterations, tol, atol, jacobian, precondition)
    return problem.solve(targets - rest, problem.start(c0))


class MuscleIK:
    """Warm-started per-frame muscle IK (Woodward §7) for a fixed set of marked vertices.

    model : the whole face's `MuscleFace`.
    marked_vertices : (K,) int vertex indices of `model.rest` that carry markers.
    method : "dls" (default: fewest iterations, see bench/muscles.py) or "transpose".
    jacobian : "exact" evaluates the model's Jacobian at every iteration; "rest" evaluates
        it once at the rest pose here and reuses it (a chord method: cheaper iterations,
        linear convergence; the residual stays exact).
    **options : `solve`'s max_iterations, tol, atol, precondition.

    Attributes after `push`: c_ (D,) the last contractions, result_ the last `IKResult`.
    """

    def __init__(self, model, marked_vertices, method: str = "dls", *, jacobian: str = "exact",
                 **options):
        ids = np.asarray(marked_vertices)
        n = np.asarray(model.rest).shape[0]
        if ids.ndim != 1 or ids.size == 0 or not np.issubdtype(ids.dtype, np.integer):
            raise RetargetError(f"marked_vertices must be a non-empty 1-D array of vertex indices, "
                                f"got shape {ids.shape} dtype {ids.dtype}")
        if ids.min() < 0 or ids.max() >= n:
            raise RetargetError(f"marked_vertices must be in [0, {n}), got {ids.min()}..{ids.max()}")
        if jacobian not in ("exact", "rest"):
            raise RetargetError(f"jacobian must be 'exact' or 'rest', got {jacobian!r}")
        self.marked_vertices = ids.astype(np.int64)
        self.method = method
        self.model_ = model.restricted(self.marked_vertices)
        fixed = None
        if jacobian == "rest":
            fixed = np.asarray(self.model_.jacobian(_rest_pose(self.model_.limits)), np.float64)
        self._problem = _Problem(self.model_, method, options.pop("max_iterations", None),
                                 options.pop("tol", 1e-4), options.pop("atol", 0.0), fixed,
                                 options.pop("precondition", True))
        if options:
            raise RetargetError(f"unknown MuscleIK options: {sorted(options)}")
        self.reset()

    def reset(self) -> None:
        """Forget the last frame: the next push starts from the rest pose."""
        self.c_ = self._problem.start(None)
        self.result_ = None

    def push(self, target_displacements) -> np.ndarray:
        """The contractions for one frame, started from the previous frame's.

        target_displacements : (K, 3) float, wanted displacement of each marked vertex from
            its rest position, mesh units; rows with a non-finite value (lost points) are
            left out. A frame with no finite row holds the previous contractions.
        Returns (D,) float64 contractions and jaw angle (a copy).
        """
        d = np.asarray(target_displacements, dtype=np.float64)
        if d.shape != (self.marked_vertices.size, 3):
            raise RetargetError(f"target_displacements must be ({self.marked_vertices.size}, 3), "
                                f"got {d.shape}")
        self.result_ = self._problem.solve(d, self.c_)
        self.c_ = self.result_.c
        return self.c_.copy()


def _rest_pose(limits: np.ndarray) -> np.ndarray:
    """(D,) the rest pose (all DOFs 0) clipped to the limits."""
    return np.clip(np.zeros(len(limits)), limits[:, 0], limits[:, 1])


class _Problem:
    """The solver settings and the per-model constants of one IK set-up."""

    def __init__(self, model, method, max_iterations, tol, atol, jacobian, precondition):
        self.precondition = bool(precondition)
        if method not in METHODS:
            raise RetargetError(f"method must be one of {METHODS}, got {method!r}")
        self.model = model
        self.method = method
        self.max_iterations = _MAX_ITERATIONS[method] if max_iterations is None else int(max_iterations)
        if self.max_iterations < 0:
            raise RetargetError(f"max_iterations must be >= 0, got {max_iterations!r}")
        if not (tol >= 0 and atol >= 0):
            raise RetargetError(f"tol and atol must be >= 0, got {tol!r}, {atol!r}")
        self.tol, self.atol = float(tol), float(atol)
        limits = np.asarray(model.limits, dtype=np.float64)
        self.low, self.high = limits[:, 0].copy(), limits[:, 1].copy()
        self.d = len(limits)
        # Each DOF's range: steps are taken in range-scaled units so that a jaw angle in
        # radians and a contraction in [0, 1] are moved alike; a DOF with no range is frozen.
        self.span = self.high - self.low
        self.safe_span = np.where(self.span > 0, self.span, 1.0)
        k = np.asarray(model.rest).shape[0]
        self.fixed = None
        if jacobian is not None:
            fixed = np.asarray(jacobian, dtype=np.float64)
            if fixed.shape != (k, 3, self.d):
                raise RetargetError(f"jacobian must be ({k}, 3, {self.d}), got {fixed.shape}")
            # Stored in range-scaled units, (K, 3, D), scaled once here rather than a frame.
            self.fixed = fixed * self.span

    def start(self, c0) -> np.ndarray:
        if c0 is None:
            return _rest_pose(np.stack([self.low, self.high], 1))
        c0 = np.asarray(c0, dtype=np.float64)
        if c0.shape != (self.d,) or not np.isfinite(c0).all():
            raise RetargetError(f"c0 must be a finite ({self.d},) vector, got shape {c0.shape}")
        return np.clip(c0, self.low, self.high)

    def solve(self, wanted: np.ndarray, c0: np.ndarray) -> IKResult:
        """wanted : (K, 3) wanted displacements (NaN rows lost); c0 : (D,) within limits."""
        valid = np.isfinite(wanted).all(axis=1)
        if not valid.any():
            return IKResult(c0.copy(), 0, float("nan"))
        rows = None if valid.all() else valid
        if rows is not None:
            wanted = wanted[rows]
        target = wanted.reshape(-1)
        n = target.size // 3
        # Exactly representable targets would otherwise iterate on rounding noise.
        floor = max(self.atol, _FLOOR * float(np.sqrt(target @ target / n)))

        def error(c):
            """(3K',) wanted minus current displacement of the valid rows."""
            disp = self.model.displacements(c)
            return target - (disp if rows is None else disp[rows]).reshape(-1)

        fixed = self.fixed
        if fixed is not None:
            fixed = (fixed if rows is None else fixed[rows]).reshape(-1, self.d)

        def jacobian(c):
            """(3K', D) Jacobian in range-scaled units (columns times the DOF's range)."""
            if fixed is not None:
                return fixed
            j = self.model.jacobian(c)
            return (j if rows is None else j[rows]).reshape(-1, self.d) * self.span

        step = self._transpose if self.method == "transpose" else self._dls
        c, iterations, f = step(c0.copy(), error, jacobian, floor)
        return IKResult(c, iterations, float(np.sqrt(f / n)))

    def _done(self, f_old: float, f_new: float, n: int, floor: float) -> bool:
        """Whether the RMS residual stopped improving (relative tol) or is under `floor`."""
        r_old, r_new = np.sqrt(f_old), np.sqrt(f_new)
        return r_old - r_new <= self.tol * r_old or np.sqrt(f_new / n) <= floor

    def _blocked(self, c: np.ndarray, s: np.ndarray) -> np.ndarray:
        """(D,) bool: DOFs at a bound that a step along s would push past it, plus frozen ones."""
        return ((c <= self.low) & (s < 0)) | ((c >= self.high) & (s > 0)) | (self.span <= 0)

    def _transpose(self, c, error, jacobian, floor):
        """Woodward §7.2 eq. 12-13: dc = alpha J^T d, projected onto the limits."""
        e = error(c)
        f = e @ e
        n = e.size // 3
        it = 0
        while it < self.max_iterations and f > n * floor**2:
            it += 1
            j = jacobian(c)
            # Range-scaled gradient direction; the DOFs pinned at a bound are left out so the
            # step length is chosen for the DOFs that can actually move (a projected gradient).
            s = j.T @ e
            if self.precondition:
                # The paper's beta tuned per DOF, automatically: a muscle that barely moves the
                # marked vertices (small column) would otherwise crawl (Jacobi preconditioning).
                s /= np.maximum(np.einsum("ij,ij->j", j, j), 1e-300)
            s[self._blocked(c, s)] = 0.0
            js = j @ s
            den = js @ js
            if den <= 0.0:
                break                                  # projected gradient zero: a stationary point
            alpha = (e @ js) / den                     # optimal along J s for the linearised problem
            s *= self.span                             # back to the DOFs' own units
            for _ in range(_HALVINGS):
                c_new = np.clip(c + alpha * s, self.low, self.high)
                e_new = error(c_new)
                f_new = e_new @ e_new
                if f_new < f:
                    break
                alpha *= 0.5                           # non-linearity or the clip overshot
            else:
                break                                  # no descent along J^T d: converged
            done = self._done(f, f_new, n, floor)
            c, e, f = c_new, e_new, f_new
            if done:
                break
        return c, it, f

    def _dls(self, c, error, jacobian, floor):
        """Damped least squares (Levenberg-Marquardt) with an active-set clamp at the limits."""
        e = error(c)
        f = e @ e
        n = e.size // 3
        lam = _LAMBDA0
        it = 0
        j = None
        while it < self.max_iterations and f > n * floor**2:
            it += 1
            if j is None or self.fixed is None:
                j = jacobian(c)
                a = j.T @ j
                # Marquardt's scaling by diag(J^T J), floored so that a DOF no marked vertex
                # feels (a zero column) is damped rather than singular.
                damp = np.maximum(np.diag(a), 1e-12 * max(np.trace(a), 1e-300))
            g = j.T @ e                                # in range-scaled units
            while True:
                u = self._bounded_step(a, damp * lam, g, c)
                c_new = np.clip(c + u * self.span, self.low, self.high)
                e_new = error(c_new)
                f_new = e_new @ e_new
                if f_new < f:
                    # The linear model's own forecast of the new error: where the exact error
                    # matches it, a further step could recover only their difference plus what
                    # a DOF held at a bound would gain by leaving it (for an undamped step the
                    # forecast gradient J^T e_forecast = g - A u vanishes on the free DOFs), so
                    # when both are within tol the last step has converged.
                    miss = e_new - (e - j @ u)
                    pull = g - a @ u
                    inward = (((c_new <= self.low) & (pull > 0)) | ((c_new >= self.high) & (pull < 0))) \
                        & (self.span > 0)
                    gain = miss @ miss + np.sum(pull[inward] ** 2 / damp[inward])
                    confirmed = lam <= _CONFIRM_LAMBDA and gain <= 2.0 * self.tol * f_new
                    lam = max(lam / 10.0, _LAMBDA_MIN)   # trust the linear model more
                    break
                lam *= 4.0                             # the linear model over-promised: damp more
                if lam > _LAMBDA_MAX:
                    return c, it, f                    # no descent at any damping: converged
            done = confirmed or self._done(f, f_new, n, floor)
            c, e, f = c_new, e_new, f_new
            if done:
                break
        return c, it, f

    def _bounded_step(self, a, damp, g, c):
        """(D,) range-scaled step u solving (A + diag(damp)) u = g with c + u*span in the limits.

        Active set: DOFs at a bound that the gradient pushes outward start fixed (u = 0);
        each pass solves for the free ones, clamps those that leave their range at the bound
        and fixes them, until none leaves (at most D passes; D = 22 makes each a tiny solve).
        """
        m = a.copy()
        m.flat[::self.d + 1] += damp
        span = self.safe_span
        lo, hi = (self.low - c) / span, (self.high - c) / span
        fixed = self._blocked(c, g)
        u = np.zeros(self.d)
        for _ in range(self.d):
            free = np.flatnonzero(~fixed)
            if free.size == 0:
                break
            if free.size == self.d:                    # the usual case: no copies
                u = _spd_solve(m, g)
            else:
                held = np.flatnonzero(fixed)
                u[free] = _spd_solve(m[free[:, None], free], g[free] - m[free[:, None], held] @ u[held])
            out = ~fixed & ((u < lo) | (u > hi))
            if not out.any():
                break
            u[out] = np.clip(u[out], lo[out], hi[out])
            fixed |= out
        return u


def _spd_solve(m: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with m x = b for a symmetric positive definite m (n, n): LAPACK's Cholesky solve
    called directly (numpy's general solve costs more in overhead than in flops at n = 22);
    the general solve where the damped matrix is numerically not positive definite."""
    _, x, info = _dposv(m, b, lower=0, overwrite_a=0, overwrite_b=0)
    return x if info == 0 else np.linalg.solve(m, b)
