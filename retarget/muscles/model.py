"""Virtual muscles and a jaw deforming a face mesh: Woodward et al. §4 (after Waters 1987).

Woodward §4.1 moves each vertex directly by abstract muscles, with no physics:

- a **linear muscle** has an origin v2 on the skull and an insertion v1 in the skin
  (muscle vector m = v1 - v2). A vertex p with q = p - v2, D = |q|, alpha the angle
  between m and q, inside the angular range omega and the radius Rf, is pulled toward the
  origin: p' = p + k a r (-q / D). The radial factor r is Waters' (1987):
  r = cos((1 - D/Rs) pi/2) for D <= Rs (nothing moves at the origin, full pull at Rs),
  r = cos((D - Rs)/(Rf - Rs) pi/2) for Rs < D <= Rf, 0 beyond. The angular factor is the
  paper's improvement over Waters' plain cos(alpha) (which jumps to 0 at omega); its
  formula was lost in the text, so we use the continuous form that keeps its intent:
  a = (cos alpha - cos omega) / (1 - cos omega), 1 along m, 0 at and beyond omega.
- an **ellipsoid (sphincter) muscle** draws vertices toward its centre with the same
  radial fall-off, measured in the ellipsoid's normalised distance (semi-axes lx, ly, lz),
  and no angular factor. One addition: per-axis pull gains (`SphincterMuscle.pull`, all 1
  in the paper), so the eye's sphincter closes the lids without dragging the eye corners.

k is the contraction times the muscle's `strength` (its largest displacement, mesh
units), so a muscle alone is linear in its contraction. Contractions are in [0, 1],
except the orbicularis oculi's, in [-1, 1]: negative opens the eye wide, the motion of
fear the paper's muscles lacked (§10). The **jaw** (§4 and §7.2's
angular joint) rotates the lower face about the hinge axis by the jaw angle, each vertex
by its weight times the angle. §4.2: the jaw moves vertices further than the muscles
can, out of the zones of the mouth muscles; such a vertex "is unaltered until it returns
within range". We evaluate every muscle's zone at the jaw-moved position, which is that
rule made continuous (a zone's factors fall to 0 at its edge, so nothing jumps); the
jaw interaction is what makes the model non-linear in the contractions.

Arrays are float64, positions and displacements in the mesh's own units (cm, m or mm:
zones and strengths are placed from the landmarks, `placement.place_muscles`), angles in
radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.errors import RetargetError

__all__ = ["Jaw", "LinearMuscle", "MuscleFace", "SphincterMuscle", "linearisation_error"]

_HALF_PI = 0.5 * np.pi
_JAW_STEP = 1e-6
"""Radians: central-difference step for the jaw column of the Jacobian (the one dof the
muscles' zones depend on non-linearly); error ~ step² against the analytic columns."""


def _vector(value, what: str, size: int = 3) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if a.shape != (size,) or not np.isfinite(a).all():
        raise RetargetError(f"{what} must be {size} finite numbers, got {value!r}")
    return a


def _positive(value, what: str) -> float:
    v = float(value)
    if not np.isfinite(v) or v <= 0:
        raise RetargetError(f"{what} must be a positive number, got {value!r}")
    return v


def _limits(value, what: str) -> tuple[float, float]:
    low, high = (float(x) for x in value)
    if not (np.isfinite(low) and np.isfinite(high) and low <= 0.0 < high):
        raise RetargetError(f"{what} must be [low, high] with low <= 0 < high, got {value!r}")
    return low, high


@dataclass(frozen=True)
class LinearMuscle:
    """Woodward §4.1's linear muscle.

    name : snake_case dof name (e.g. ``"zygomatic_major_left"``).
    origin : (3,) v2, the attachment to the skull, mesh units.
    insertion : (3,) v1, the insertion into the skin, mesh units.
    rs, rf : Rs < Rf, distances from the origin where the fall-off to the edge starts and
        where the influence ends, mesh units.
    omega : angular range about m = v1 - v2, radians in (0, pi/2).
    strength : displacement at full contraction where a = r = 1, mesh units.
    limits : (low, high) valid contraction range.
    """

    name: str
    origin: np.ndarray
    insertion: np.ndarray
    rs: float
    rf: float
    omega: float
    strength: float
    limits: tuple[float, float] = (0.0, 1.0)
    kind = "linear"

    def __post_init__(self) -> None:
        object.__setattr__(self, "origin", _vector(self.origin, f"{self.name}.origin"))
        object.__setattr__(self, "insertion", _vector(self.insertion, f"{self.name}.insertion"))
        for key in ("rs", "rf", "omega", "strength"):
            object.__setattr__(self, key, _positive(getattr(self, key), f"{self.name}.{key}"))
        object.__setattr__(self, "limits", _limits(self.limits, f"{self.name}.limits"))
        if self.rs >= self.rf:
            raise RetargetError(f"{self.name}: rs must be below rf, got rs={self.rs}, rf={self.rf}")
        if self.omega >= _HALF_PI:
            raise RetargetError(f"{self.name}.omega must be below pi/2 radians, got {self.omega}")
        if np.linalg.norm(self.insertion - self.origin) == 0:
            raise RetargetError(f"{self.name}: insertion and origin coincide")

    def to_json(self) -> dict:
        return {"name": self.name, "kind": self.kind, "origin": self.origin.tolist(),
                "insertion": self.insertion.tolist(), "rs": self.rs, "rf": self.rf,
                "omega": self.omega, "strength": self.strength, "limits": list(self.limits)}


@dataclass(frozen=True)
class SphincterMuscle:
    """Woodward §4.1's ellipsoid (sphincter) muscle.

    name : snake_case dof name (e.g. ``"orbicularis_oris"``).
    centre : (3,) the point vertices are drawn toward, mesh units.
    axes : (3, 3) rows: the ellipsoid's unit axes (major, minor, minor).
    radii : (3,) semi-axes lx, ly, lz along `axes`, mesh units.
    start : normalised ellipsoid distance in (0, 1) where the pull peaks (Rs / Rf of a
        linear muscle): nothing moves at the centre, nothing beyond the ellipsoid.
    strength : largest displacement at full contraction, mesh units.
    limits : (low, high) valid contraction range; a negative low lets the muscle push
        outward (the orbicularis oculi's opposite, the eye opening wide).
    pull : (3,) gains on the pull along each axis, in [0, 1]. The paper draws vertices
        straight at the centre (all 1); the eye's sphincter pulls mostly across the lid
        slit (an eyelid closes, its corners hardly move), which a centre alone cannot do.
    """

    name: str
    centre: np.ndarray
    axes: np.ndarray
    radii: np.ndarray
    start: float
    strength: float
    limits: tuple[float, float] = (0.0, 1.0)
    pull: np.ndarray = (1.0, 1.0, 1.0)
    kind = "sphincter"

    def __post_init__(self) -> None:
        object.__setattr__(self, "centre", _vector(self.centre, f"{self.name}.centre"))
        axes = np.asarray(self.axes, dtype=np.float64)
        if axes.shape != (3, 3) or not np.isfinite(axes).all():
            raise RetargetError(f"{self.name}.axes must be a 3x3 matrix, got {self.axes!r}")
        norms = np.linalg.norm(axes, axis=1, keepdims=True)
        if (norms == 0).any():
            raise RetargetError(f"{self.name}.axes has a zero row")
        object.__setattr__(self, "axes", axes / norms)
        radii = _vector(self.radii, f"{self.name}.radii")
        if (radii <= 0).any():
            raise RetargetError(f"{self.name}.radii must be positive, got {self.radii!r}")
        object.__setattr__(self, "radii", radii)
        start = float(self.start)
        if not 0.0 < start < 1.0:
            raise RetargetError(f"{self.name}.start must be in (0, 1), got {self.start!r}")
        object.__setattr__(self, "start", start)
        object.__setattr__(self, "strength", _positive(self.strength, f"{self.name}.strength"))
        object.__setattr__(self, "limits", _limits(self.limits, f"{self.name}.limits"))
        pull = _vector(self.pull, f"{self.name}.pull")
        if (pull < 0).any() or (pull > 1).any() or not pull.any():
            raise RetargetError(f"{self.name}.pull must be in [0, 1] and not all 0, got {self.pull!r}")
        object.__setattr__(self, "pull", pull)

    def to_json(self) -> dict:
        return {"name": self.name, "kind": self.kind, "centre": self.centre.tolist(),
                "axes": self.axes.tolist(), "radii": self.radii.tolist(), "start": self.start,
                "strength": self.strength, "limits": list(self.limits), "pull": self.pull.tolist()}


@dataclass(frozen=True, eq=False)
class Jaw:
    """The jaw: a rotation of the lower face about the hinge axis (Woodward §4, §7.2).

    hinge_right, hinge_left : (3,) points on the axis (the jaw hinges below the ears, the
        subject's right and left), mesh units. A positive angle opens the mouth: the axis
        runs from right to left hinge, and with the face's +y up and +z out of the face the
        right-hand rotation about it carries the chin down and back.
    weights : (V,) float64 in [0, 1], how much of the angle each vertex turns by: 1 on the
        chin and lower lip, 0 on the upper lip and above, smooth in between.
    limits : (low, high) valid jaw angle, radians.
    """

    hinge_right: np.ndarray
    hinge_left: np.ndarray
    weights: np.ndarray
    limits: tuple[float, float] = (0.0, 0.35)

    def __post_init__(self) -> None:
        object.__setattr__(self, "hinge_right", _vector(self.hinge_right, "jaw.hinge_right"))
        object.__setattr__(self, "hinge_left", _vector(self.hinge_left, "jaw.hinge_left"))
        w = np.asarray(self.weights, dtype=np.float64)
        if w.ndim != 1 or not np.isfinite(w).all() or (w < 0).any() or (w > 1).any():
            raise RetargetError("jaw.weights must be a (V,) array of numbers in [0, 1]")
        object.__setattr__(self, "weights", w)
        object.__setattr__(self, "limits", _limits(self.limits, "jaw.limits"))
        if np.linalg.norm(self.hinge_left - self.hinge_right) == 0:
            raise RetargetError("jaw: the two hinges coincide")

    @property
    def axis(self) -> np.ndarray:
        """(3,) unit rotation axis, right hinge to left hinge."""
        a = self.hinge_left - self.hinge_right
        return a / np.linalg.norm(a)

    def restricted(self, vertex_ids: np.ndarray) -> "Jaw":
        return Jaw(self.hinge_right, self.hinge_left, self.weights[vertex_ids], self.limits)

    def to_json(self) -> dict:
        nz = np.flatnonzero(self.weights)
        return {"hinge_right": self.hinge_right.tolist(), "hinge_left": self.hinge_left.tolist(),
                "limits": list(self.limits),
                "weights": {"n_vertices": len(self.weights), "vertex_indices": nz.tolist(),
                            "values": self.weights[nz].tolist()}}


class _Pairs:
    """(muscle, point) pairs with each pair's muscle parameters gathered, so the fields of
    every muscle at every point it may reach are a few elementwise numpy calls on (P,)
    arrays (no Python loop over muscles, no work on pairs out of reach). Parameters are
    stored component-major, (3, P) and (3, 3, P), so every call runs on contiguous rows.

    Both kinds share one formula. The normalised distance is t = sqrt(q' G q): a linear
    muscle's G is I / Rf² (t = D / Rf, its fall-off starts at Rs / Rf), a sphincter's the
    ellipsoid's form. The angular factor of a sphincter is 1 (direction 0, cos omega = -1,
    scale 1). The pull is along H q: H = I except for a sphincter with axis gains.
    """

    def __init__(self, muscles, muscle: np.ndarray, point: np.ndarray):
        self.muscle = muscle                            # (P,) int, dof index
        self.point = point                              # (P,) int, row of the points
        # pairs come grouped by point: the points that have any, and where each group starts
        self.points, self.starts = np.unique(point, return_index=True)
        lin = [m.kind == "linear" for m in muscles]
        origin = np.array([m.origin if k else m.centre for m, k in zip(muscles, lin)]).reshape(-1, 3)
        form = np.array([np.eye(3) / m.rf ** 2 if k else m.axes.T @ (m.axes / m.radii[:, None] ** 2)
                         for m, k in zip(muscles, lin)]).reshape(-1, 3, 3)
        pull = np.array([np.eye(3) if k else m.axes.T @ (m.pull[:, None] * m.axes)
                         for m, k in zip(muscles, lin)]).reshape(-1, 3, 3)
        scale = np.array([1.0 / (1.0 - np.cos(m.omega)) if k else 1.0 for m, k in zip(muscles, lin)])
        direction = np.array([(m.insertion - m.origin) / np.linalg.norm(m.insertion - m.origin)
                              if k else np.zeros(3) for m, k in zip(muscles, lin)]).reshape(-1, 3)
        cos_omega = np.array([np.cos(m.omega) if k else -1.0 for m, k in zip(muscles, lin)])
        start = np.array([m.rs / m.rf if k else m.start for m, k in zip(muscles, lin)])[muscle]
        self.origin = np.ascontiguousarray(origin[muscle].T)                     # (3, P)
        self.form = np.ascontiguousarray(form[muscle].transpose(1, 2, 0))        # (3, 3, P)
        self.pull = np.ascontiguousarray(pull[muscle].transpose(1, 2, 0))        # (3, 3, P)
        self.plain = bool(np.all(self.pull == np.eye(3)[:, :, None]))
        self.direction = np.ascontiguousarray((direction * scale[:, None])[muscle].T)   # (3, P) m / (1 - cos w)
        self.cos_omega = (cos_omega * scale)[muscle]                             # (P,) cos w / (1 - cos w)
        self.start = start
        # Waters' r as one cosine: cos((t - start) * k), k = pi/2 / start inside, pi/2 / (1 - start) out
        self.k_in = _HALF_PI / start
        self.k_out = _HALF_PI / (1.0 - start)
        self.minus_strength = -np.array([m.strength for m in muscles])[muscle]

    def fields(self, p: np.ndarray) -> np.ndarray:
        """(P, 3) or (S, P, 3): each pair's displacement at full contraction, p (P, 3) or
        (S, P, 3) its positions (S: several positions per pair at once)."""
        stacked = p.ndim == 3
        q = p.transpose(2, 0, 1) - self.origin[:, None] if stacked else p.T - self.origin   # (3, [S,] P)
        d = np.sqrt(np.maximum((q * q).sum(0), 1e-300))
        t = np.sqrt(np.einsum("ijp,isp,jsp->sp", self.form, q, q) if stacked
                    else np.einsum("ijp,ip,jp->p", self.form, q, q))
        # §4.1 angular factor, continuous at omega (see the module docstring)
        a = np.maximum((q * (self.direction[:, None] if stacked else self.direction)).sum(0) / d
                       - self.cos_omega, 0.0)
        r = np.cos(np.minimum((t - self.start) * np.where(t <= self.start, self.k_in, self.k_out), _HALF_PI))
        coef = self.minus_strength / d * a * r
        if not self.plain:
            q = np.einsum("ijp,jsp->isp", self.pull, q) if stacked else np.einsum("ijp,jp->ip", self.pull, q)
        out = coef * q
        return out.transpose(1, 2, 0) if stacked else out.T


def _reach(muscle) -> tuple[np.ndarray, float]:
    """(3,) centre and radius of a sphere holding the muscle's zone."""
    if muscle.kind == "linear":
        return muscle.origin, muscle.rf
    return muscle.centre, float(muscle.radii.max())


def _pairs_within(muscles, points: np.ndarray, slack: np.ndarray | float = 0.0) -> _Pairs:
    """The (muscle, point) pairs whose point lies within `slack` (K,) of the zone."""
    ms, ps = [], []
    for k, m in enumerate(muscles):
        centre, radius = _reach(m)
        near = np.flatnonzero(np.linalg.norm(points - centre, axis=1) - slack <= radius)
        ms.append(np.full(len(near), k))
        ps.append(near)
    muscle = np.concatenate(ms).astype(np.int64)
    point = np.concatenate(ps).astype(np.int64)
    order = np.lexsort((muscle, point))           # grouped by point, for np.add.reduceat
    return _Pairs(muscles, muscle[order], point[order])


class MuscleFace:
    """21 muscles and a jaw on one mesh: the forward map from D = M + 1 dofs to (V, 3)
    vertex displacements (Woodward §4), with its Jacobian for the muscle IK (§7.2).

    muscles : M `LinearMuscle` / `SphincterMuscle`, in dof order.
    jaw : `Jaw` whose weights are per vertex of `rest`.
    rest : (V, 3) float64 rest vertices this model deforms, mesh units.

    Each muscle's displacement field at the rest pose is computed once here (M, V, 3),
    so without jaw rotation a pose costs one (M,) x (M, V, 3) product; with it only the
    jaw's vertices (weight > 0) are evaluated again.
    """

    def __init__(self, muscles, jaw: Jaw, rest, *, _fields: np.ndarray | None = None):
        rest = np.asarray(rest, dtype=np.float64)
        if rest.ndim != 2 or rest.shape[1] != 3 or not np.isfinite(rest).all():
            raise RetargetError(f"rest must be a finite (V, 3) array, got shape {rest.shape}")
        muscles = tuple(muscles)
        if not all(isinstance(m, (LinearMuscle, SphincterMuscle)) for m in muscles):
            raise RetargetError("muscles must be LinearMuscle or SphincterMuscle objects")
        names = tuple(m.name for m in muscles) + ("jaw",)
        if len(set(names)) != len(names):
            raise RetargetError(f"muscle names must be unique and not 'jaw', got {names}")
        if len(jaw.weights) != len(rest):
            raise RetargetError(f"jaw.weights has {len(jaw.weights)} entries, rest has {len(rest)} vertices")
        self.muscles = muscles
        self.jaw = jaw
        self.rest = rest
        self.names: tuple[str, ...] = names
        self.limits = np.array([m.limits for m in muscles] + [jaw.limits], dtype=np.float64).reshape(-1, 2)
        if _fields is None:
            pairs = _pairs_within(muscles, rest)
            _fields = np.zeros((len(muscles), len(rest), 3))
            _fields[pairs.muscle, pairs.point] = pairs.fields(rest[pairs.point])
        self._fields0 = _fields                                          # (M, V, 3)
        self._fields0_flat = _fields.reshape(len(muscles), -1)           # (M, V * 3)
        # the jaw's vertices, with Rodrigues' terms that do not depend on the angle:
        # moved = base + cos(w theta) perp + sin(w theta) (axis x perp)
        self._jawed = np.flatnonzero(jaw.weights > 0)                    # (J,)
        self._jaw_rest = rest[self._jawed]
        self._jaw_weights = jaw.weights[self._jawed]
        axis = jaw.axis
        v = self._jaw_rest - jaw.hinge_right
        along = (v @ axis)[:, None] * axis
        self._perp = v - along
        self._turned = np.cross(axis, self._perp)
        self._base = jaw.hinge_right + along
        # §4.2: the muscles that the jaw may carry each of its vertices into or out of
        # (chord <= arc; 25 % margin for the IK stepping a little past the limits)
        travel = 1.25 * self._jaw_weights * np.abs(jaw.limits).max() * np.linalg.norm(self._perp, axis=1)
        self._jaw_pairs = _pairs_within(muscles, self._jaw_rest, travel)

    @property
    def n_dof(self) -> int:
        """D: the muscles, then the jaw."""
        return len(self.names)

    @property
    def n_muscles(self) -> int:
        return len(self.muscles)

    def _dofs(self, c) -> np.ndarray:
        c = np.asarray(c, dtype=np.float64)
        if c.shape != (self.n_dof,) or not np.isfinite(c).all():
            raise RetargetError(f"contractions must be {self.n_dof} finite numbers ({', '.join(self.names)}), "
                                f"got shape {c.shape}")
        return c

    def _jaw_moved(self, angle: float) -> tuple[np.ndarray, np.ndarray]:
        """(J, 3) the jaw's vertices turned by `angle`, and (J, 3) their d/d angle."""
        phi = self._jaw_weights * angle
        cos, sin = np.cos(phi)[:, None], np.sin(phi)[:, None]
        moved = self._base + cos * self._perp + sin * self._turned
        rate = self._jaw_weights[:, None] * (cos * self._turned - sin * self._perp)
        return moved, rate

    def _summed(self, c: np.ndarray, fields: np.ndarray) -> np.ndarray:
        """(J, 3) sum over muscles of c_m times the jaw pairs' (P, 3) fields, per vertex."""
        pairs = self._jaw_pairs
        out = np.zeros((len(self._jawed), 3))
        if len(pairs.muscle):
            out[pairs.points] = np.add.reduceat(c[pairs.muscle, None] * fields, pairs.starts)
        return out

    def displacements(self, c) -> np.ndarray:
        """(V, 3) float64 vertex displacements, mesh units, for contractions c (D,) (the
        muscles' in their limits, then the jaw angle in radians). Exact: non-linear in the
        jaw angle and in how the jaw carries vertices through the muscles' zones (§4.2:
        zones are evaluated where the jaw has put each vertex)."""
        c = self._dofs(c)
        out = (c[:-1] @ self._fields0_flat).reshape(-1, 3)
        if c[-1] != 0 and len(self._jawed):
            moved, _ = self._jaw_moved(c[-1])
            f = self._jaw_pairs.fields(moved[self._jaw_pairs.point])
            out[self._jawed] = moved - self._jaw_rest + self._summed(c, f)
        return out

    def jacobian(self, c) -> np.ndarray:
        """(V, 3, D) float64 d displacements / d c at c (D,). The muscle columns are exact
        (a muscle is linear in its own contraction, §7.2 eq. 14: its field where the jaw
        has put the vertex). The jaw column is the rotation's exact rate (§7.2 eq. 15,
        tangent to the axis, times the vertex's weight) plus how the muscles' fields change
        along it, a forward difference over `_JAW_STEP` radians (0 off the jaw)."""
        c = self._dofs(c)
        out = np.zeros((len(self.rest), 3, self.n_dof))
        out[:, :, :-1] = self._fields0.transpose(1, 2, 0)
        if len(self._jawed):
            moved, rate = self._jaw_moved(c[-1])
            pairs = self._jaw_pairs
            at, step = moved[pairs.point], _JAW_STEP * rate[pairs.point]
            # a forward difference: the fields at `at` are needed anyway, and at a step of
            # 1e-6 rad its truncation error (~1e-6 relative) is far below what the IK resolves
            f = pairs.fields(np.stack([at, at + step]))
            if c[-1] != 0:
                # every muscle that reaches a jaw vertex over the jaw's range has a pair
                # there, so this overwrites all of the rest-pose fields that change
                out[self._jawed[pairs.point], :, pairs.muscle] = f[0]
            out[self._jawed, :, -1] = rate + self._summed(c, (f[1] - f[0]) / _JAW_STEP)
        return out

    def restricted(self, vertex_ids) -> "MuscleFace":
        """The same model evaluated only at rest[vertex_ids] (K,): what the IK iterates on,
        so a step costs O(K D). Its vertex k is `vertex_ids[k]` of this one."""
        ids = np.asarray(vertex_ids)
        if ids.ndim != 1 or not np.issubdtype(ids.dtype, np.integer) or len(ids) == 0 \
                or ids.min() < -len(self.rest) or ids.max() >= len(self.rest):
            raise RetargetError(f"vertex_ids must be a non-empty (K,) array of vertex indices "
                                f"below {len(self.rest)}, got {vertex_ids!r}")
        return MuscleFace(self.muscles, self.jaw.restricted(ids), self.rest[ids],
                          _fields=self._fields0[:, ids])

    def linearised(self) -> np.ndarray:
        """(D, V, 3) float32: each dof's displacement field at its high limit alone (full
        contraction, the jaw fully open): morph targets for the GPU and for glTF export.
        The linear form of a pose c is sum_d c_d / high_d * field_d (`linearisation_error`
        measures how far that is from `displacements`). It is exact with the jaw closed (the
        muscles are linear); over poses drawn uniformly within the limits it is 14 % off on
        the sample face and 20 % on the ICT face, against 7 % for the jaw's rotation alone
        (bench/muscle_model.py): most of it is the jaw carrying the lower lip out of the
        mouth muscles' zones (§4.2), which the linear form cannot know."""
        out = np.empty((self.n_dof, len(self.rest), 3), dtype=np.float32)
        out[:-1] = self._fields0 * self.limits[:-1, 1, None, None]
        c = np.zeros(self.n_dof)
        c[-1] = self.limits[-1, 1]
        out[-1] = self.displacements(c)
        return out

    def to_json(self) -> dict:
        """Muscle geometry (origins, insertions, zones, strengths, limits) and the jaw (its
        hinges, limits and per-vertex weights, sparse): what the app edits and saves."""
        return {"version": 1, "muscles": [m.to_json() for m in self.muscles], "jaw": self.jaw.to_json()}

    @classmethod
    def from_json(cls, data: dict, rest) -> "MuscleFace":
        """The model `to_json` wrote, on (V, 3) `rest` (the mesh it was placed on)."""
        rest = np.asarray(rest, dtype=np.float64)
        try:
            muscles = []
            for m in data["muscles"]:
                kind = m.get("kind")
                if kind == "linear":
                    muscles.append(LinearMuscle(m["name"], m["origin"], m["insertion"], m["rs"], m["rf"],
                                                m["omega"], m["strength"], tuple(m["limits"])))
                elif kind == "sphincter":
                    muscles.append(SphincterMuscle(m["name"], m["centre"], m["axes"], m["radii"], m["start"],
                                                   m["strength"], tuple(m["limits"]), m.get("pull", (1, 1, 1))))
                else:
                    raise RetargetError(f"muscle {m.get('name')!r}: kind must be 'linear' or 'sphincter', got {kind!r}")
            j = data["jaw"]
            sparse = j["weights"]
            if int(sparse["n_vertices"]) != len(rest):
                raise RetargetError(f"jaw weights are for {sparse['n_vertices']} vertices, rest has {len(rest)}")
            ids = np.asarray(sparse["vertex_indices"], dtype=np.int64)
            if len(ids) and (ids.min() < 0 or ids.max() >= len(rest)):
                raise RetargetError("jaw weights: vertex index outside the mesh")
            values = np.asarray(sparse["values"], dtype=np.float64)
            if ids.ndim != 1 or values.shape != ids.shape:
                raise RetargetError(f"jaw weights: {values.size} values for {ids.size} vertex indices")
            weights = np.zeros(len(rest))
            weights[ids] = values
            jaw = Jaw(j["hinge_right"], j["hinge_left"], weights, tuple(j["limits"]))
        except (KeyError, TypeError, ValueError) as e:
            if isinstance(e, RetargetError):
                raise
            raise RetargetError(f"muscle JSON is malformed: {e!r}") from None
        return cls(muscles, jaw, rest)


def linearisation_error(model: MuscleFace, n_samples: int = 64, seed: int = 0) -> float:
    """Relative error of the linear form (`MuscleFace.linearised`) against the exact
    displacements over `n_samples` contraction vectors drawn uniformly within the limits:
    sqrt(sum |linear - exact|²) / sqrt(sum |exact|²) over all samples and vertices."""
    rng = np.random.default_rng(seed)
    fields = model.linearised().astype(np.float64)                  # (D, V, 3)
    high = model.limits[:, 1]
    err = ref = 0.0
    for _ in range(n_samples):
        c = rng.uniform(model.limits[:, 0], high)
        exact = model.displacements(c)
        linear = np.tensordot(c / high, fields, 1)
        err += float(((linear - exact) ** 2).sum())
        ref += float((exact ** 2).sum())
    return float(np.sqrt(err / ref)) if ref > 0 else 0.0
