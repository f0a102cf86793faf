"""Per-frame ARKit weights: the 52 coefficients in [0, 1] that best reproduce a face's
motion from its ARKit shapes.

The fit is a bounded, regularised least squares (as blendshape solvers for performance
capture pose it: Lewis et al., "Practice and Theory of Blendshape Facial Models",
Eurographics 2014 STAR, §5; Seol et al., "Spacetime Expression Cloning for Blendshapes",
ToG 2012, for the non-negative, bounded weights):

    min_w  ½ |B w - d|²  + ½ λ Σ_k G_kk w_k²                         (ridge)
                          + τ Σ_k sqrt(G_kk ḡ) w_k                       (sparsity)
                          + ½ σ Σ_(l,r) mirror pairs s_lr (w_l - w_r)²   (no left/right split)
    s.t.   0 <= w_k <= 1,   w_i w_j = 0 for antagonists (i, j)

B (3N, 52) holds the shapes' displacements of N points (feature points, or vertices), d
(3N,) the frame's, G = BᵀB, ḡ its mean diagonal and s_lr = sqrt(G_ll G_rr), so every
term is measured in the shapes' own sizes and the weights need no units. The ridge is
relative (a shape alone is biased by 1 / (1 + λ)) and keeps shapes the points cannot
tell apart (the eye-look shapes at 68 points) from running off; the mirror term makes a
symmetric expression use both sides' shapes equally rather than one side's twice over.
The sparsity term is an L1 penalty (the weights are non-negative, so it is linear): a
soft threshold, τ in weight for a shape of typical size and more for a small one (noise
of a given size on the points makes a spurious weight inversely proportional to the
shape's size, hence sqrt(G_kk ḡ) rather than G_kk, which would also make a big shape
dearer than small ones imitating it), so a tracker's jitter does not flicker dozens of
tiny weights on and off (which would also cost the solver a step each). Antagonists
(smile and frown, blink and wide, jaw left and right, ...) move the same skin opposite
ways, so both on would cancel each other to fit noise: they are kept exclusive, by
fixing the weaker of a co-active pair at 0 and solving again (a greedy step for the
complementarity constraint; no bias at all while they are not both on, unlike a co-
activation penalty, which is indefinite and would need a ridge on every shape to stay
convex).

Solve: the quadratic ``½ wᵀ H w - cᵀ w`` with H = G + ridge + mirror term fixed once
(`ArkitSolver.__init__`) and c = Bᵀd - τ sqrt(diag(G) ḡ) per frame, by a primal active-
set method for box constraints (Nocedal & Wright, Numerical Optimization, §16.5): free
weights take the exact minimiser with the others held at their bounds, a minimiser
outside [0, 1] is clipped into it with every clipped weight fixed when that lowers the
objective (projected Newton, Bertsekas 1982), else approached until the first weight
meets its bound, which is fixed, and bound weights whose gradient points inward are
freed: at a frame's first check all of them (from the previous frame's weights only a
few change), then the most promising one at a time (Lawson & Hanson, "Solving Least
Squares Problems", ch. 23, so the steps cannot cycle). A smooth take needs one or two
linear solves a frame, and the inverses of the free blocks are cached per free set, so a
frame costs a few 52 x 52 products.
"""

from __future__ import annotations

import numpy as np

from retarget.arkit.reference import ARKIT_NAMES
from retarget.errors import RetargetError

__all__ = ["ANTAGONISTS", "MIRROR_PAIRS", "ArkitSolver"]


ANTAGONISTS: tuple[tuple[str, str], ...] = tuple(
    pair for side in ("Left", "Right") for pair in (
        (f"mouthSmile{side}", f"mouthFrown{side}"),
        (f"eyeWide{side}", f"eyeBlink{side}"),
        (f"eyeWide{side}", f"eyeSquint{side}"),
        (f"eyeLookUp{side}", f"eyeLookDown{side}"),
        (f"eyeLookIn{side}", f"eyeLookOut{side}"),
        (f"browDown{side}", f"browOuterUp{side}"),
        (f"browDown{side}", "browInnerUp"),
        (f"mouthLowerDown{side}", "mouthShrugLower"),
        (f"mouthStretch{side}", "mouthPucker"),
    )) + (("jawLeft", "jawRight"), ("mouthLeft", "mouthRight"))
"""Shapes that move the same skin opposite ways (ARKit's definitions): on together, they
cancel; the solver keeps them exclusive."""

MIRROR_PAIRS: tuple[tuple[str, str], ...] = tuple(
    (name, name[:-4] + "Right") for name in ARKIT_NAMES
    if name.endswith("Left") and name not in ("jawLeft", "mouthLeft"))
"""(Left, Right) halves of one expression (jawLeft / jawRight and mouthLeft / mouthRight
are opposite motions, in `ANTAGONISTS`)."""

_CACHE_SIZE = 128  # free sets whose inverse is kept: a take visits a few dozen


class ArkitSolver:
    """Fits the 52 ARKit weights to one frame of displacements (module docstring).

    Parameters
    ----------
    shapes_at_points : (52, N, 3) float, each shape's displacements at N points (feature
        points: `ArkitShapes.at_points`; or vertices: `ArkitShapes.deltas`), any units.
    ridge : λ, relative ridge (default 1e-4).
    symmetry : σ, the left/right difference charge of `MIRROR_PAIRS` (default 1e-3).
    sparsity : τ, the soft threshold on every weight (default 0.01).
    exclusive : keep `ANTAGONISTS` exclusive (default True).

    `solve` is per frame and keeps the last weights as the next frame's start; `reset`
    forgets them (a new take).
    """

    def __init__(self, shapes_at_points, *, ridge: float = 1e-4, symmetry: float = 1e-3,
                 sparsity: float = 0.01, exclusive: bool = True):
        b = np.asarray(shapes_at_points, dtype=np.float64)
        k = len(ARKIT_NAMES)
        if b.ndim != 3 or b.shape[0] != k or b.shape[2] != 3 or b.shape[1] == 0:
            raise RetargetError(f"shapes_at_points must have shape ({k}, N, 3); got {b.shape}")
        if not np.isfinite(b).all():
            raise RetargetError("shapes_at_points must be finite")
        for name, value in (("ridge", ridge), ("symmetry", symmetry), ("sparsity", sparsity)):
            if not np.isfinite(value) or value < 0:
                raise RetargetError(f"{name} must be a finite number >= 0; got {value!r}")
        self.ridge, self.symmetry, self.sparsity, self.exclusive = ridge, symmetry, sparsity, exclusive
        index = {n: i for i, n in enumerate(ARKIT_NAMES)}
        self._antagonists = np.array([(index[a], index[b]) for a, b in ANTAGONISTS]).T  # (2, P)
        self.n_points = b.shape[1]
        self.shapes_ = b.reshape(k, -1)                        # Bᵀ, (52, 3N)
        gram = self.shapes_ @ self.shapes_.T
        self.hessian_ = self._hessian(gram)
        self.threshold_ = self._threshold(gram)
        self._inverses: dict[bytes, np.ndarray] = {}
        self.reset()

    def _hessian(self, gram: np.ndarray) -> np.ndarray:
        """(52, 52) positive definite H = G + ridge + mirror term (module docstring); a
        shape with no motion (tongueOut) gets a tiny floor so H stays invertible."""
        diag = np.diag(gram).copy()
        floor = 1e-9 * max(diag.mean(), np.finfo(float).tiny)
        h = gram + np.diag(self.ridge * np.maximum(diag, floor) + floor)
        index = {n: i for i, n in enumerate(ARKIT_NAMES)}
        for a, b in MIRROR_PAIRS:
            i, j = index[a], index[b]
            s = self.symmetry * np.sqrt(diag[i] * diag[j])
            h[[i, j], [i, j]] += s
            h[[i, j], [j, i]] -= s
        return h

    def _threshold(self, gram: np.ndarray) -> np.ndarray:
        """(52,) the sparsity term's coefficients τ sqrt(G_kk ḡ) (module docstring)."""
        diag = np.diag(gram)
        return self.sparsity * np.sqrt(diag * diag.mean())

    def reset(self) -> None:
        """Forget the previous frame: the next solve starts from all weights 0."""
        self.weights_ = np.zeros(len(ARKIT_NAMES))

    def solve(self, displacements) -> np.ndarray:
        """(52,) float64 weights in [0, 1] for (N, 3) displacements of the N points (the
        shapes' units), warm-started from the previous frame.

        A point with a non-finite coordinate (lost) is left out of this frame's fit (its
        rows of B dropped, slower: the normal matrix is rebuilt); a frame with no finite
        point keeps the previous weights.
        """
        d = np.asarray(displacements, dtype=np.float64)
        if d.shape != (self.n_points, 3):
            raise RetargetError(f"displacements must have shape ({self.n_points}, 3); got {d.shape}")
        d = d.ravel()
        finite = np.isfinite(d)
        if finite.all():
            self.weights_ = self._fit(self.hessian_, self.shapes_ @ d - self.threshold_, self._inverses)
        elif finite.reshape(-1, 3).all(axis=1).any():
            kept = np.repeat(finite.reshape(-1, 3).all(axis=1), 3)
            b = self.shapes_[:, kept]
            gram = b @ b.T
            c = b @ d[kept] - self._threshold(gram)
            self.weights_ = self._fit(self._hessian(gram), c, None)
        return self.weights_.copy()

    def _fit(self, h: np.ndarray, c: np.ndarray, inverses: dict | None) -> np.ndarray:
        """The box QP from the previous weights, then antagonists made exclusive: while a
        pair is on together, its weaker one is held at 0 and the QP solved again."""
        off = np.zeros(len(c), dtype=bool)
        if not self.exclusive:
            return _box_qp(h, c, self.weights_, off, inverses)
        w = _box_qp(h, c, self.weights_, off, inverses, self._antagonists)
        a, b = self._antagonists
        for _ in range(a.size):
            both = (w[a] > 0) & (w[b] > 0)
            if not both.any():
                break
            off[np.where(w[a] < w[b], a, b)[both]] = True
            w = _box_qp(h, c, np.where(off, 0.0, w), off, inverses, self._antagonists)
        return w

    def solve_frames(self, displacements) -> np.ndarray:
        """(F, 52) float64 weights for (F, N, 3) displacements, frame after frame (each
        warm-starting the next)."""
        d = np.asarray(displacements, dtype=np.float64)
        if d.ndim != 3:
            raise RetargetError(f"displacements must have shape (F, {self.n_points}, 3); got {d.shape}")
        return np.stack([self.solve(frame) for frame in d]) if len(d) else np.zeros((0, len(ARKIT_NAMES)))


def _box_qp(h: np.ndarray, c: np.ndarray, start: np.ndarray, off: np.ndarray,
            inverses: dict | None, exclusive: np.ndarray | None = None,
            max_steps: int = 200) -> np.ndarray:
    """argmin ½ wᵀ h w - cᵀ w over 0 <= w <= 1 (and w = 0 where `off`) for positive
    definite (K, K) h and (K,) c, by the primal active-set method from `start` (module
    docstring). `inverses` caches the free blocks' inverses by free set (None: no cache).
    `exclusive` (2, P) index pairs: a weight at 0 is not freed while its partner is on."""
    diagonal = np.diag(h)
    tol = 1e-12 * max(float(diagonal.max()), 1e-300)
    w = np.clip(start, 0.0, 1.0)
    # the previous frame's support starts free; bound weights are freed one at a time below
    low, high = (w <= 0.0) | off, (w >= 1.0) & ~off
    wholesale = True
    for _ in range(max_steps):
        free = ~(low | high)
        held = high.astype(np.float64)              # the bound weights' values: 0 or 1
        target = held.copy()
        if free.any():
            target[free] = _inverse(h, free, inverses) @ (c[free] - (h @ held)[free])
        inside = (target[free] >= 0.0) & (target[free] <= 1.0)
        if inside.all():
            w = target
            grad = h @ w - c
            # bound weights whose gradient points into the box would lower the objective
            inward = (low & ~off & (grad < -tol)) | (high & (grad > tol))
            if exclusive is not None:
                a, b = exclusive
                partner_on = np.zeros(len(w), dtype=bool)
                partner_on[a[w[b] > 0]] = True
                partner_on[b[w[a] > 0]] = True
                inward &= ~(low & partner_on)
            gain = np.where(inward, grad * grad / diagonal, 0.0)
            if not gain.any():
                return w
            if wholesale:
                # from a warm start a few weights change at once (a frame's noise): free all
                # that would lower the objective, as projected methods do
                low &= gain == 0
                high &= gain == 0
                wholesale = False
            else:
                # then the one whose release lowers the objective most (Lawson & Hanson's rule:
                # one at a time, so the steps cannot cycle)
                best = int(np.argmax(gain))
                low[best] = high[best] = False
            continue
        # the free minimiser leaves the box: clipped, if that lowers the objective, with
        # every weight it clipped fixed at once (projected Newton, Bertsekas 1982) ...
        clipped = np.clip(target, 0.0, 1.0)
        if _objective(h, c, clipped) < _objective(h, c, w):
            low |= free & (target < 0.0)
            high |= free & (target > 1.0)
            w = clipped
            continue
        # ... else toward it until the first weight meets its bound, which is fixed
        step = target - w
        f = np.flatnonzero(free)
        s = step[f]
        with np.errstate(divide="ignore", invalid="ignore"):
            room = np.where(s < 0, -w[f] / s, np.where(s > 0, (1.0 - w[f]) / s, np.inf))
        blocking = int(np.argmin(room))
        alpha = min(1.0, max(float(room[blocking]), 0.0))
        w = np.clip(w + alpha * step, 0.0, 1.0)
        hit = f[blocking]
        if s[blocking] < 0:
            w[hit], low[hit] = 0.0, True
        else:
            w[hit], high[hit] = 1.0, True
    return w


def _objective(h: np.ndarray, c: np.ndarray, w: np.ndarray) -> float:
    """½ wᵀ h w - cᵀ w."""
    return float(w @ (0.5 * (h @ w) - c))


def _inverse(h: np.ndarray, free: np.ndarray, cache: dict | None) -> np.ndarray:
    """The inverse of h's free block, cached by free set."""
    key = free.tobytes()
    if cache is not None and key in cache:
        return cache[key]
    inv = np.linalg.inv(h[np.ix_(free, free)])
    if cache is not None:
        if len(cache) >= _CACHE_SIZE:
            cache.pop(next(iter(cache)))
        cache[key] = inv
    return inv
