"""Length units of a mesh: what a face file's numbers are in, and a guess from its size.

A mesh file holds bare numbers; glTF (and so Blender, Unity, Unreal and three.js loading a
.glb) takes them as metres. A face modelled or scanned in centimetres (the sample face, the
ICT data) arrives 100 times too large unless the export scales it. `UNITS` are the units a
face may be in, each with its length in metres; `guess_units` guesses one from the mesh's
size, `unit_scale` gives metres per unit, `export_scale` what an export multiplies every
length by.

The guess (`guess_units`): a human face, brow to chin, or a head with its neck is about
`FACE_SIZE` = 0.2 m (0.1-0.4 m in practice), so the largest extent of the mesh's bounding box
(any axis: a scan may be z-up) is compared with 0.2 m in each of m, cm and mm, and the unit
that puts it nearest on a log scale wins: extents from 0.063 to 0.63 are metres, 6.3 to 63
centimetres, 63 to 632 millimetres (the boundaries are 0.2 x 10^(k +- 1/2)); smaller than
0.063 is metres, larger than 632 millimetres. Ambiguity: inches are never guessed, because an
inch face (6-12 in) lies inside the centimetre range, so a face in inches is guessed as
centimetres (2.54 times too small) and must be chosen by hand; so must a tiny face in
metres (a 5 cm model), a mesh in decimetres, or a whole body in millimetres. The guess is a
default shown to the user, never a silent fact.
"""

from __future__ import annotations

import math

import numpy as np

from retarget.errors import RetargetError

__all__ = ["EXPORT_UNITS", "FACE_SIZE", "GUESSED_UNITS", "UNITS", "export_scale", "face_size",
           "guess_units", "mesh_units", "unit_scale"]

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}
"""The units a mesh may be in, each with its length in metres."""

GUESSED_UNITS = ("m", "cm", "mm")
"""The units `guess_units` chooses among (inches are never guessed: module docstring)."""

EXPORT_UNITS = ("m", "keep")
"""An export's units: "m" (metres, glTF's convention) or "keep" (the mesh's own numbers)."""

FACE_SIZE = 0.2
"""Metres: the typical largest bounding-box extent of a face mesh the guess assumes."""


def face_size(vertices) -> float:
    """The largest extent of the axis-aligned bounding box of (V, 3) `vertices`, in their
    units; 0.0 for no vertices."""
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise RetargetError(f"vertices must have shape (V, 3); got {v.shape}")
    return float(np.ptp(v, axis=0).max()) if len(v) else 0.0


def guess_units(vertices) -> str:
    """The unit of `GUESSED_UNITS` in which the (V, 3) `vertices` make a face about
    `FACE_SIZE` metres across (module docstring: the rule and its ambiguity); "m" for a
    mesh of no extent."""
    size = face_size(vertices)
    if not math.isfinite(size) or size <= 0:
        return "m"
    return min(GUESSED_UNITS, key=lambda u: abs(math.log10(size * UNITS[u] / FACE_SIZE)))


def unit_scale(unit: str) -> float:
    """Metres per `unit` (one of `UNITS`); `RetargetError` naming the value otherwise."""
    if unit not in UNITS:
        raise RetargetError(f"mesh units must be one of {', '.join(UNITS)}; got {unit!r}")
    return UNITS[unit]


def mesh_units(unit: str, vertices) -> str:
    """The mesh's unit: `unit` itself (one of `UNITS`), or for "guess" `guess_units` of the
    (V, 3) `vertices`."""
    if unit == "guess":
        return guess_units(vertices)
    unit_scale(unit)
    return unit


def export_scale(units: str, source_units: str) -> float:
    """What an export multiplies every length by: metres per `source_units` for units "m",
    1.0 for "keep" (`EXPORT_UNITS`)."""
    if units not in EXPORT_UNITS:
        raise RetargetError(f"export units must be one of {', '.join(EXPORT_UNITS)}; got {units!r}")
    return unit_scale(source_units) if units == "m" else 1.0
