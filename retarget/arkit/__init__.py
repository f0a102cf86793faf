"""ARKit's 52 blendshapes, both ways (issue 16).

- `reference`: ARKit's names (Apple's order; Left is the subject's left) and the shipped
  reference motion of each shape at every layout's feature points (derived from the ICT
  face model, MIT; ``reference.npz`` and ``NOTICE`` beside it).
- `shapes`: the 52 shapes generated on any face through the space transform and its rig,
  one dense morph target per name (`arkit_shapes`).
- `solve`: the 52 weights in [0, 1] that best reproduce a frame's motion (`ArkitSolver`).
- `drive`: a stream driven by the 52 shapes, frame after frame, with per-shape gains
  (`ArkitDrive`); `settings`: the user's gains, painted fixes and rig (`ArkitSettings`).

ARKit curves as a source (Live Link Face CSV, tables of named weights) are read in
`retarget.sources.arkit_curves`, through `retarget.sources.files.read_take`.
"""

from retarget.arkit.reference import ARKIT_NAMES, ArkitReference, arkit_index, arkit_reference
from retarget.arkit.shapes import ArkitShapes, arkit_shapes
from retarget.arkit.solve import ArkitSolver
from retarget.arkit.drive import ArkitDrive
from retarget.arkit.settings import ArkitSettings

__all__ = ["ARKIT_NAMES", "ArkitDrive", "ArkitReference", "ArkitSettings", "ArkitShapes", "ArkitSolver", "arkit_index",
           "arkit_reference", "arkit_shapes"]
