"""The muscles in the form a GPU and a glTF file play them (issue 15): one morph target per
muscle plus a jaw joint.

The exact model (`MuscleFace.displacements`) is linear in the 21 contractions as long as
the jaw is closed; the jaw is a rotation, and it carries the lower lip through the mouth
muscles' zones (Woodward §4.2), which no fixed field can follow. The played form keeps
what is exact and cheap:

- **muscles**: morph targets, muscle m's displacement field at its high limit (the jaw
  closed); a pose's morph weight is c_m / high_m (negative for an orbicularis oculi
  opening the eye wide: glTF, three.js and Blender take negative weights);
- **jaw**: a joint at the hinge axis rotated by the jaw angle, weighted per vertex by the
  jaw's weights against a static root: linear blend skinning, what a glTF skin does, so
  the app's shader and every glTF viewer play the same thing;
- **correctives**: one more morph target for each muscle whose zone the jaw carries
  vertices through (the zygomatics, orbicularis oris, levators and depressors: 9 of 21
  on the sample face), named ``<muscle>*jaw`` and weighted by (c_m / high_m) (jaw /
  jaw_high). K_m is muscle m's exact field with the jaw fully open, taken back through
  the inverse of the jaw's skinning to the rest frame (morphs are applied before the
  skin), minus its rest field T_m: with the jaw fully open, muscle m adds exactly its own
  motion to the jaw's. Any product of keyed weights plays in glTF (the animation keys
  every target's weight per frame) and in a shader. Over poses drawn uniformly within the
  limits they take the sample face from 12.4 % to 5.4 % off the exact muscles
  (`played_error`); what is left is the zones' non-linear response between closed and
  open, and linear blend skinning against the model's per-vertex share of the angle.

glTF applies morph targets first and the skin after (glTF 2.0 §3.7.3), and so does
`played_displacements`. `played_error` measures the form against the exact muscles.
Units: the mesh's own; angles in radians.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from retarget.errors import RetargetError
from retarget.muscles.model import MuscleFace

__all__ = ["MuscleMorphs", "muscle_morphs", "played_displacements", "played_error"]

_CORRECTIVE_FLOOR = 1e-4
"""A corrective is kept when it moves a vertex by more than this share of its muscle's
largest displacement (float32 holds ~1e-7): below, it is rounding, not the jaw."""


@dataclass(frozen=True, eq=False)
class MuscleMorphs:
    """A `MuscleFace` as morph targets and a jaw joint.

    names : (M,) the muscles' dof names (the model's names without ``"jaw"``).
    targets : (M, V, 3) float32 each muscle's displacement at weight 1, mesh units.
    high : (M,) float64 the contraction that weight 1 stands for (the muscle's high limit).
    jaw_pivot : (3,) float64 a point on the hinge axis (the right hinge).
    jaw_axis : (3,) float64 unit axis, right hinge to left; a positive angle opens.
    jaw_weights : (V,) float32 in [0, 1], each vertex's weight on the jaw joint (the rest
        on the static root).
    jaw_limits : (2,) float64 the jaw angle's range, radians; jaw_limits[1] is the angle a
        corrective's jaw factor 1 stands for.
    corrective_of : (C,) int64 indices into `names`: the muscles that have a corrective, in
        `correctives` order (empty: the plain form, `muscle_morphs(..., correctives=False)`).
    correctives : (C, V, 3) float32 each corrective target's displacement at weight 1,
        mesh units, applied with the muscle targets before the jaw's skinning.
    """

    names: tuple[str, ...]
    targets: np.ndarray
    high: np.ndarray
    jaw_pivot: np.ndarray
    jaw_axis: np.ndarray
    jaw_weights: np.ndarray
    jaw_limits: np.ndarray
    corrective_of: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    correctives: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 3), np.float32))

    @property
    def corrective_names(self) -> tuple[str, ...]:
        """(C,) the corrective targets' names, ``<muscle>*jaw``."""
        return tuple(f"{self.names[m]}*jaw" for m in self.corrective_of)

    def weights(self, contractions) -> tuple[np.ndarray, np.ndarray]:
        """(..., D) contractions (the muscles, then the jaw) -> (..., M) morph weights and
        (...,) jaw angles."""
        c = np.asarray(contractions, dtype=np.float64)
        if c.shape[-1] != len(self.names) + 1:
            raise RetargetError(f"contractions must have {len(self.names) + 1} values; got {c.shape}")
        return c[..., :-1] / self.high, c[..., -1]

    def corrective_weights(self, contractions) -> np.ndarray:
        """(..., D) contractions -> (..., C) the correctives' weights, (c_m / high_m) times
        (jaw / jaw_limits[1])."""
        muscles, angle = self.weights(contractions)
        return muscles[..., self.corrective_of] * (angle / self.jaw_limits[1])[..., None]


def muscle_morphs(model: MuscleFace, correctives: bool = True) -> MuscleMorphs:
    """The played form of `model`, with the correctives (see the module docstring) unless
    `correctives` is False."""
    fields = model.linearised()[:-1]
    high = np.asarray(model.limits[:-1, 1], dtype=np.float64)
    if (high <= 0).any():
        raise RetargetError("every muscle needs a positive high limit to be a morph target")
    jaw = model.jaw
    plain = MuscleMorphs(tuple(model.names[:-1]), fields, high, jaw.hinge_right.copy(), jaw.axis,
                         jaw.weights.astype(np.float32), np.asarray(jaw.limits, dtype=np.float64))
    if not correctives:
        return plain
    of, targets = _correctives(model, plain)
    return replace(plain, corrective_of=of, correctives=targets)


def _correctives(model: MuscleFace, morphs: MuscleMorphs) -> tuple[np.ndarray, np.ndarray]:
    """(C,) int64 muscles with a corrective and (C, V, 3) float32 their targets K_m =
    A^-1 (exact_m) - T_m at the open jaw, A the jaw's skinning there, per vertex
    (1 - w) I + w R; exact_m = displacements(m at high, jaw open) - displacements(jaw open)."""
    m = len(morphs.names)
    opened = np.zeros((m + 1, m + 1))
    opened[:, -1] = morphs.jaw_limits[1]
    opened[np.arange(m), np.arange(m)] = morphs.high
    jaw_alone = model.displacements(opened[-1])
    jawed = np.flatnonzero(morphs.jaw_weights > 0)                      # (J,)
    w = morphs.jaw_weights[jawed, None, None].astype(np.float64)
    turn = _rotation(morphs.jaw_axis, float(morphs.jaw_limits[1]))
    skin = (1.0 - w) * np.eye(3) + w * turn                            # (J, 3, 3)
    out = np.zeros((m, len(model.rest), 3))
    for k in range(m):
        exact = model.displacements(opened[k]) - jaw_alone              # (V, 3)
        # off the jaw A = I, so the corrective is exact - T there (0 but for rounding)
        back = exact.copy()
        back[jawed] = np.linalg.solve(skin, exact[jawed, :, None])[..., 0]
        out[k] = back - morphs.targets[k]
    # a muscle the jaw never carries a vertex into or out of has no corrective: its K is
    # float32 rounding of its own field
    size = np.abs(morphs.targets).max(axis=(1, 2))
    kept = np.flatnonzero(np.abs(out).max(axis=(1, 2)) > _CORRECTIVE_FLOOR * size)
    return kept.astype(np.int64), out[kept].astype(np.float32)


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """(3, 3) rotation by `angle` radians about the unit `axis` (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def played_displacements(morphs: MuscleMorphs, rest, contractions) -> np.ndarray:
    """(V, 3) float64 displacements of the played form for one pose (D,) on (V, 3) `rest`:
    morph targets (muscles and correctives), then the jaw joint's linear blend skinning."""
    weights, angle = morphs.weights(contractions)
    r = np.asarray(rest, dtype=np.float64)
    morphed = r + np.tensordot(weights, morphs.targets, 1)
    if len(morphs.corrective_of):
        morphed += np.tensordot(morphs.corrective_weights(contractions), morphs.correctives, 1)
    if angle != 0:
        turned = (morphed - morphs.jaw_pivot) @ _rotation(morphs.jaw_axis, float(angle)).T + morphs.jaw_pivot
        morphed += morphs.jaw_weights[:, None] * (turned - morphed)
    return morphed - r


def played_error(model: MuscleFace, n_samples: int = 64, seed: int = 0,
                 correctives: bool = True) -> float:
    """Relative error of the played form (with or without its correctives) against the
    exact muscles over `n_samples` poses drawn uniformly within the limits:
    sqrt(sum |played - exact|²) / sqrt(sum |exact|²)."""
    rng = np.random.default_rng(seed)
    morphs = muscle_morphs(model, correctives)
    err = ref = 0.0
    for _ in range(n_samples):
        c = rng.uniform(model.limits[:, 0], model.limits[:, 1])
        exact = model.displacements(c)
        err += float(((played_displacements(morphs, model.rest, c) - exact) ** 2).sum())
        ref += float((exact ** 2).sum())
    return float(np.sqrt(err / ref)) if ref > 0 else 0.0
