"""Woodward et al.'s virtual muscles (§4): 21 muscles and a jaw placed on any face from
its landmarks, the forward map from contractions to vertex displacements, its Jacobian
for the muscle IK (§7, `retarget.muscles.ik`), and a linear form for the GPU.

- `table.MUSCLE_TABLE`: the paper's Table 1, anatomical names, how each is placed.
- `model`: `LinearMuscle`, `SphincterMuscle`, `Jaw`, `MuscleFace`, `linearisation_error`.
- `placement.place_muscles(vertices, faces, points, layout)` -> `MuscleFace`.
"""

from retarget.muscles.model import Jaw, LinearMuscle, MuscleFace, SphincterMuscle, linearisation_error
from retarget.muscles.placement import ibug68_points, jaw_weights, place_muscles
from retarget.muscles.table import MUSCLE_TABLE, MuscleRow, dof_names

__all__ = [
    "Jaw", "LinearMuscle", "MUSCLE_TABLE", "MuscleFace", "MuscleRow", "SphincterMuscle", "dof_names",
    "ibug68_points", "jaw_weights", "linearisation_error", "place_muscles",
]
