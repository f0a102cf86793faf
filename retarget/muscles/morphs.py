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
  the app's shader and every glTF viewer play the same thing.

glTF applies morph targets first and the skin after (glTF 2.0 §3.7.3), and so does
`played_displacements`. `played_error` measures the form against the exact muscles.
Units: the mesh's own; angles in radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.errors import RetargetError
from retarget.muscles.model import MuscleFace

__all__ = ["MuscleMorphs", "muscle_morphs", "played_displacements", "played_error"]


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
    jaw_limits : (2,) float64 the jaw angle's range, radians.
    """

    names: tuple[str, ...]
    targets: np.ndarray
    high: np.ndarray
    jaw_pivot: np.ndarray
    jaw_axis: np.ndarray
    jaw_weights: np.ndarray
    jaw_limits: np.ndarray

    def weights(self, contractions) -> tuple[np.ndarray, np.ndarray]:
        """(..., D) contractions (the muscles, then the jaw) -> (..., M) morph weights and
        (...,) jaw angles."""
        c = np.asarray(contractions, dtype=np.float64)
        if c.shape[-1] != len(self.names) + 1:
            raise RetargetError(f"contractions must have {len(self.names) + 1} values; got {c.shape}")
        return c[..., :-1] / self.high, c[..., -1]


def muscle_morphs(model: MuscleFace) -> MuscleMorphs:
    """The played form of `model`."""
    fields = model.linearised()[:-1]
    high = np.asarray(model.limits[:-1, 1], dtype=np.float64)
    if (high <= 0).any():
        raise RetargetError("every muscle needs a positive high limit to be a morph target")
    jaw = model.jaw
    return MuscleMorphs(tuple(model.names[:-1]), fields, high, jaw.hinge_right.copy(), jaw.axis,
                        jaw.weights.astype(np.float32), np.asarray(jaw.limits, dtype=np.float64))


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """(3, 3) rotation by `angle` radians about the unit `axis` (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def played_displacements(morphs: MuscleMorphs, rest, contractions) -> np.ndarray:
    """(V, 3) float64 displacements of the played form for one pose (D,) on (V, 3) `rest`:
    morph targets, then the jaw joint's linear blend skinning."""
    weights, angle = morphs.weights(contractions)
    r = np.asarray(rest, dtype=np.float64)
    morphed = r + np.tensordot(weights, morphs.targets, 1)
    if angle != 0:
        turned = (morphed - morphs.jaw_pivot) @ _rotation(morphs.jaw_axis, float(angle)).T + morphs.jaw_pivot
        morphed += morphs.jaw_weights[:, None] * (turned - morphed)
    return morphed - r


def played_error(model: MuscleFace, n_samples: int = 64, seed: int = 0) -> float:
    """Relative error of the played form against the exact muscles over `n_samples` poses
    drawn uniformly within the limits: sqrt(sum |played - exact|²) / sqrt(sum |exact|²)."""
    rng = np.random.default_rng(seed)
    morphs = muscle_morphs(model)
    err = ref = 0.0
    for _ in range(n_samples):
        c = rng.uniform(model.limits[:, 0], model.limits[:, 1])
        exact = model.displacements(c)
        err += float(((played_displacements(morphs, model.rest, c) - exact) ** 2).sum())
        ref += float((exact ** 2).sum())
    return float(np.sqrt(err / ref)) if ref > 0 else 0.0
