"""The export's units: every length scaled once, before the file is written, and recorded.

glTF's unit is the metre, and Unity, Unreal, Blender and three.js take a .glb's numbers as
metres; a centimetre face exported as it is arrives 100 times too large. The exports
(`retarget.gltf.writer`, `retarget.gltf.arkit`) therefore write metres by default: the
mesh's unit (`retarget.units`, given or guessed from its size) gives a factor s (0.01 for
centimetres) and every length is multiplied by it before anything is written: positions,
joint translations (so inverse bind matrices and the jaw's hinge), feature displacements,
morph targets and head translations. Skin weights, morph weights, angles and times have
no unit and stay as they are.

Why the vertex data and not a scale on a root node: a node scale is honoured by a viewer
that composes the scene graph, but a skinned mesh ignores its node's transform (glTF
§3.7.3.1), an importer may apply or bake it differently (Unity's importer keeps it as the
object's scale, so the face reports a scale of 0.01 and every script that moves it in
metres is off by that), and the joints, morph targets and animation would still be in
centimetres in every tool that reads them. Scaled data are metres everywhere.

The scale is recorded in the scene's ``extras.retarget``: ``source_units`` (the mesh's
unit), ``scale_to_metres`` (metres per source unit) and ``scale`` (what was applied: file
number = source number x scale; 1.0 with units "keep"), so `retarget.gltf.read_gltf`
divides it out and an exported project imported again is in its original units.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from retarget.errors import RetargetError
from retarget.mesh import Mesh
from retarget.units import export_scale, mesh_units, unit_scale

__all__ = ["ExportUnits", "export_units", "file_scale", "scaled_clip", "scaled_mesh"]


@dataclasses.dataclass(frozen=True)
class ExportUnits:
    """source_units : the mesh's unit ("m", "cm", "mm", "in"); scale : what every length
    is multiplied by (file = source x scale)."""

    source_units: str
    scale: float

    def record(self) -> dict:
        """The keys the scene's ``extras.retarget`` records (module docstring)."""
        return {"source_units": self.source_units, "scale_to_metres": unit_scale(self.source_units),
                "scale": self.scale}


def export_units(mesh: Mesh, units: str = "m", source_units: str = "guess") -> ExportUnits:
    """The units of an export of `mesh`: `units` "m" or "keep", the mesh in `source_units`
    (one of `retarget.units.UNITS`, or "guess" from its size). `RetargetError` names a bad
    value."""
    unit = mesh_units(source_units, mesh.vertices)
    return ExportUnits(unit, export_scale(units, unit))


def scaled_mesh(mesh: Mesh, scale: float) -> Mesh:
    """`mesh` with its vertices times `scale` (normals, uv and material kept); itself at 1."""
    if scale == 1.0:
        return mesh
    return dataclasses.replace(mesh, vertices=np.asarray(mesh.vertices, dtype=np.float64) * scale)


def scaled_clip(clip, scale: float):
    """A clip (`Clip`, `ContractionClip`, `ArkitClip`) with its lengths times `scale`: a
    `Clip`'s displacements and any clip's head translations; itself at 1."""
    if scale == 1.0:
        return clip
    changes = {}
    if hasattr(clip, "displacements"):
        changes["displacements"] = clip.displacements * np.float32(scale)
    if getattr(clip, "head_translations", None) is not None:
        changes["head_translations"] = clip.head_translations * scale
    return dataclasses.replace(clip, **changes) if changes else clip


def file_scale(extras: dict) -> tuple[str | None, float]:
    """(source units or None, the scale applied) that a file's ``extras.retarget``
    records; (None, 1.0) for a file written before units were recorded. A recorded unit
    that is not one of `retarget.units.UNITS`, or a scale that is not a finite number > 0,
    is a `RetargetError` (the file was not written by this exporter)."""
    scale = extras.get("scale", 1.0)
    unit = extras.get("source_units")
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not np.isfinite(scale) or scale <= 0:
        raise RetargetError(f"the file's recorded scale must be a number > 0; got {scale!r}")
    if unit is not None:
        unit_scale(unit if isinstance(unit, str) else repr(unit))
    return unit, float(scale)
