"""The user's settings of a face's 52 ARKit shapes: a gain per shape, a painted "fix" per
shape, and the rig the shapes are made on.

- **gain** (52,) in [0, `MAX_GAIN`], default 1: scales the shape's solved weight in a
  stream driven by ARKit (`retarget.arkit.drive.ArkitDrive`), e.g. 1.3 for a performer who
  barely smiles, 0 to silence a shape.
- **fix**: a per-vertex mask in [0, 1] that scales that one shape's morph target, painted
  where the generated shape moves skin it should not (a blink that pulls the cheek): the
  shape played is ``mask[v] * deltas[k, v]``. Stored sparse, only the vertices painted
  below 1 (`ShapeFix`), so an unpainted shape costs nothing and a painted region of a
  133k-vertex face a few kilobytes. The fixes change what the shapes look like (the
  played and downloaded morph targets), not what they mean: the solver still fits the
  shapes' generated motion at the feature points.
- **rig**: what the shapes are made on (`retarget.arkit.shapes.arkit_shapes`):
  ``"default"``, the dense rig of the reference's 468 face-mesh points, or ``"project"``,
  the project's own rig on its feature points (what the points stream plays).

JSON form (`ArkitSettings.to_json` / `from_json`)::

    {"rig": "default" | "project",
     "gains": {"<ARKit name>": gain, ...},                 (names left out: 1)
     "masks": {"<ARKit name>": {"vertices": [v, ...],       (ascending, distinct, < V)
                                "values": [m, ...]}, ...}}  (in [0, 1], one per vertex)

Every refusal is a `RetargetError` naming the shape, the field and the value.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from retarget.arkit.reference import ARKIT_NAMES
from retarget.errors import RetargetError

__all__ = ["ArkitSettings", "MAX_GAIN", "RIGS", "ShapeFix"]

MAX_GAIN = 2.0
"""The largest gain a shape may have."""

RIGS = ("default", "project")
"""What the shapes may be made on (module docstring)."""

_INDEX = {name: k for k, name in enumerate(ARKIT_NAMES)}


@dataclass(frozen=True, eq=False)
class ShapeFix:
    """One shape's painted mask, sparse: vertices (M,) int64 ascending and distinct, values
    (M,) float32 in [0, 1]; every other vertex keeps the shape whole (mask 1)."""

    vertices: np.ndarray
    values: np.ndarray

    def dense(self, n_vertices: int) -> np.ndarray:
        """(V,) float32 mask."""
        mask = np.ones(n_vertices, np.float32)
        mask[self.vertices] = self.values
        return mask


@dataclass(frozen=True, eq=False)
class ArkitSettings:
    """gains (52,) float64 in [0, MAX_GAIN]; fixes: ARKit index -> `ShapeFix`; rig: one of
    `RIGS`."""

    gains: np.ndarray = field(default_factory=lambda: np.ones(len(ARKIT_NAMES)))
    fixes: dict[int, ShapeFix] = field(default_factory=dict)
    rig: str = "default"

    @classmethod
    def from_json(cls, data, n_vertices: int | None = None) -> "ArkitSettings":
        """Validated settings from the JSON form (module docstring); `n_vertices` bounds the
        masks' vertex indices (None: not checked, e.g. before a mesh)."""
        if not isinstance(data, dict):
            raise RetargetError(f"ARKit settings must be an object; got {type(data).__name__}")
        unknown = set(data) - {"rig", "gains", "masks"}
        if unknown:
            raise RetargetError(f"ARKit settings have unknown fields {sorted(unknown)}; "
                                "expected rig, gains, masks")
        rig = data.get("rig", "default")
        if rig not in RIGS:
            raise RetargetError(f"rig must be one of {', '.join(map(repr, RIGS))}; got {rig!r}")
        gains = np.ones(len(ARKIT_NAMES))
        for name, gain in _named(data.get("gains") or {}, "gains").items():
            # compared before any conversion: NaN fails, and so does an int too large for a float
            if isinstance(gain, bool) or not isinstance(gain, (int, float)) or not 0.0 <= gain <= MAX_GAIN:
                raise RetargetError(f"gain of {name} must be a number in [0, {MAX_GAIN:g}]; got {gain!r}")
            gains[_INDEX[name]] = float(gain)
        fixes = {}
        for name, mask in _named(data.get("masks") or {}, "masks").items():
            fix = _fix(name, mask, n_vertices)
            if len(fix.vertices):
                fixes[_INDEX[name]] = fix
        return cls(gains, fixes, rig)

    def to_json(self) -> dict:
        """The JSON form: every gain (Apple's order), the painted masks, the rig."""
        return {"rig": self.rig,
                "gains": {name: float(g) for name, g in zip(ARKIT_NAMES, self.gains)},
                "masks": {ARKIT_NAMES[k]: {"vertices": fix.vertices.tolist(),
                                           "values": [round(float(x), 5) for x in fix.values]}
                          for k, fix in sorted(self.fixes.items())}}

    def fitting(self, n_vertices: int) -> "ArkitSettings":
        """These settings for a mesh of `n_vertices`: masks painted on another mesh (a
        vertex past its end) are dropped, the gains and rig kept."""
        fixes = {k: f for k, f in self.fixes.items() if not len(f.vertices) or f.vertices[-1] < n_vertices}
        return ArkitSettings(self.gains, fixes, self.rig)

    def fixed_deltas(self, deltas: np.ndarray) -> np.ndarray:
        """(52, V, 3) float32 morph targets with the masks applied (a copy when any is)."""
        if not self.fixes:
            return deltas
        out = np.array(deltas, dtype=np.float32)
        for k, fix in self.fixes.items():
            out[k, fix.vertices] *= fix.values[:, None]
        return out


def _named(table, what: str) -> dict:
    if not isinstance(table, dict):
        raise RetargetError(f"{what} must be an object of ARKit names; got {type(table).__name__}")
    for name in table:
        if name not in _INDEX:
            raise RetargetError(f"{what}: {name!r} is not one of ARKit's 52 shape names "
                                f"(e.g. eyeBlinkLeft, jawOpen, mouthSmileRight)")
    return table


def _fix(name: str, mask, n_vertices: int | None) -> ShapeFix:
    if not isinstance(mask, dict) or set(mask) != {"vertices", "values"}:
        raise RetargetError(f"mask of {name} must be an object with vertices and values")
    vertices, values = mask["vertices"], mask["values"]
    if not isinstance(vertices, list) or not isinstance(values, list):
        raise RetargetError(f"mask of {name}: vertices and values must be lists")
    if len(vertices) != len(values):
        raise RetargetError(f"mask of {name} has {len(vertices)} vertices and {len(values)} values; "
                            "it needs one value per vertex")
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in vertices):
        raise RetargetError(f"mask of {name}: vertices must be integer vertex indices")
    # checked before numpy sees them: NaN fails the comparison, a huge int is out of range
    bad = next((x for x in values if isinstance(x, bool) or not isinstance(x, (int, float)) or not 0 <= x <= 1),
               None)
    if bad is not None:
        raise RetargetError(f"mask of {name}: values must be numbers in [0, 1]; got {bad!r}")
    limit = min(n_vertices, 2**31) if n_vertices is not None else 2**31
    bad = next((v for v in vertices if not 0 <= v < limit), None)
    if bad is not None:
        raise RetargetError(f"mask of {name}: vertex {bad} is not one of the mesh's {n_vertices} vertices")
    v = np.asarray(vertices, dtype=np.int64)
    x = np.asarray(values, dtype=np.float64)
    if len(v) > 1 and not (np.diff(v) > 0).all():
        raise RetargetError(f"mask of {name}: vertices must be ascending and distinct")
    keep = x < 1  # a vertex at 1 keeps the shape whole: not stored
    return ShapeFix(v[keep], x[keep].astype(np.float32))
