"""ARKit's 52 blendshape names and the shipped reference motion of each at every layout's
feature points.

ARKit (Apple, ``ARFaceAnchor.BlendShapeLocation``) describes a face by 52 coefficients in
[0, 1]; iPhone Live Link Face records them, MediaPipe's face landmarker outputs them,
VRM "perfect sync" avatars and Unreal / Unity / Blender tools consume them. "Left" and
"Right" in ARKit's names are the **subject's** left and right (``eyeBlinkLeft`` closes
the performer's own left eye), the convention of this project's layouts (+x toward the
subject's left).

The reference (``reference.npz`` beside this module, made by ``bench/arkit_reference.py``
from the ICT face model in ``../shared/data/ict_face``, ICT-FaceKit, MIT licence: the
notice is in the file and in ``NOTICE`` beside it) holds, for each of the 52 names, the
motion of the ICT generic neutral face at weight 1:

- ``ibug68_neutral`` (68, 3) float32 cm and ``ibug68_motion`` (52, 68, 3) float16 cm: at
  ICT's own 68 iBUG landmark vertices;
- ``mediapipe468_neutral`` (468, 3) float32 cm and ``mediapipe468_motion`` (52, 468, 3)
  float16 cm: at MediaPipe's 468 face-mesh points found on the ICT neutral with no clicks
  (`retarget.facemesh.placement.find_face_mesh`, once, in the script).

Axes are ICT's: +y up, +z out of the face, +x toward the subject's left. A layout whose
points are all iBUG points reads the first table at its ``ibug68`` indices; the
face-mesh layouts (``mediapipe468``, and ``mediapipe68``, whose iBUG points are read off
the face mesh) read the second at their ``mediapipe468`` indices.

From ICT's 53 shapes to ARKit's 52 (`ICT_SOURCES`): ICT names a one-sided shape
``<base>_L`` / ``<base>_R`` with ``_L`` acting on +x, the subject's left, so ``_L`` is
ARKit's ``Left``; ICT splits two shapes that ARKit has whole, ``browInnerUp`` and
``cheekPuff``, which are the sums of their halves; ICT has no tongue, so ``tongueOut``
moves nothing here (all-zero motion: it generates a zero morph target and the solver
gives it weight 0, as a face without a tongue shows nothing of it).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from retarget.errors import RetargetError
from retarget.layouts import Layout, get_layout

__all__ = ["ARKIT_NAMES", "ICT_SOURCES", "REFERENCE", "ArkitReference", "arkit_reference",
           "arkit_index", "points_from_weights"]

REFERENCE = Path(__file__).resolve().parent / "reference.npz"

ARKIT_NAMES: tuple[str, ...] = (
    # Apple's documented order (ARFaceAnchor.BlendShapeLocation): left eye, right eye,
    # mouth and jaw, eyebrows, cheeks, nose, tongue
    "eyeBlinkLeft", "eyeLookDownLeft", "eyeLookInLeft", "eyeLookOutLeft", "eyeLookUpLeft",
    "eyeSquintLeft", "eyeWideLeft",
    "eyeBlinkRight", "eyeLookDownRight", "eyeLookInRight", "eyeLookOutRight", "eyeLookUpRight",
    "eyeSquintRight", "eyeWideRight",
    "jawForward", "jawLeft", "jawRight", "jawOpen",
    "mouthClose", "mouthFunnel", "mouthPucker", "mouthLeft", "mouthRight",
    "mouthSmileLeft", "mouthSmileRight", "mouthFrownLeft", "mouthFrownRight",
    "mouthDimpleLeft", "mouthDimpleRight", "mouthStretchLeft", "mouthStretchRight",
    "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper",
    "mouthPressLeft", "mouthPressRight", "mouthLowerDownLeft", "mouthLowerDownRight",
    "mouthUpperUpLeft", "mouthUpperUpRight",
    "browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft", "browOuterUpRight",
    "cheekPuff", "cheekSquintLeft", "cheekSquintRight",
    "noseSneerLeft", "noseSneerRight",
    "tongueOut",
)
"""(52,) ARKit's blendshape names in Apple's order."""


def _ict_sources(name: str) -> tuple[str, ...]:
    """The ICT shapes whose sum is ARKit shape `name` (module docstring)."""
    if name == "tongueOut":
        return ()
    if name in ("browInnerUp", "cheekPuff"):
        return (name + "_L", name + "_R")
    for side, suffix in (("Left", "_L"), ("Right", "_R")):
        # jawLeft / mouthLeft are whole shapes in both sets (the jaw or mouth moving toward
        # the subject's left); only a trailing side after another word is ICT's suffix
        if name.endswith(side) and name not in ("jawLeft", "jawRight", "mouthLeft", "mouthRight"):
            return (name[: -len(side)] + suffix,)
    return (name,)


ICT_SOURCES: dict[str, tuple[str, ...]] = {name: _ict_sources(name) for name in ARKIT_NAMES}
"""ARKit name -> the ICT-FaceKit expression shapes summed for it (empty: none)."""

_INDEX = {name.lower(): i for i, name in enumerate(ARKIT_NAMES)}


def arkit_index(name: str) -> int:
    """Position of `name` in `ARKIT_NAMES`, matched without case (Live Link Face writes
    ``EyeBlinkLeft`` for ARKit's ``eyeBlinkLeft``); -1 when it is none of the 52."""
    return _INDEX.get(str(name).lower(), -1)


@dataclass(frozen=True, eq=False)
class ArkitReference:
    """The 52 shapes' motion at a layout's feature points on a reference face.

    layout : the layout's name.
    neutral : (N, 3) float64 reference neutral points (cm for the shipped table).
    motion : (52, N, 3) float64 displacement of each point at weight 1, `ARKIT_NAMES`
        order, same units.
    """

    layout: str
    neutral: np.ndarray
    motion: np.ndarray

    def __post_init__(self) -> None:
        n = np.asarray(self.neutral).shape
        m = np.asarray(self.motion).shape
        if len(n) != 2 or n[1] != 3 or m != (len(ARKIT_NAMES), *n):
            raise RetargetError(f"ArkitReference: neutral must be (N, 3) and motion "
                                f"({len(ARKIT_NAMES)}, N, 3); got {n} and {m}")

    def points(self, weights) -> np.ndarray:
        """(F, N, 3) float64 points ``neutral + sum_k w_k motion_k`` for (F, 52) weights
        (or (N, 3) for (52,))."""
        return points_from_weights(weights, self.neutral, self.motion)


def points_from_weights(weights, neutral: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """(..., N, 3) float64 ``neutral + sum_k w_k motion_k`` for (..., 52) weights, (N, 3)
    neutral and (52, N, 3) motion (the ICT model is additive, so this is the reference face
    making the expression)."""
    w = np.asarray(weights, dtype=np.float64)
    if w.shape[-1:] != (len(ARKIT_NAMES),) or not np.isfinite(w).all():
        raise RetargetError(f"ARKit weights must be finite with shape (..., {len(ARKIT_NAMES)}); "
                            f"got {w.shape}")
    return neutral + np.tensordot(w, motion, axes=(-1, 0))


def arkit_reference(layout: Layout | str) -> ArkitReference:
    """The shipped reference (module docstring) at `layout`'s points: a built-in layout's
    name or any `Layout` (a `Layout.select` subset included)."""
    layout = get_layout(layout) if isinstance(layout, str) else layout
    if not isinstance(layout, Layout):
        raise RetargetError(f"layout must be a Layout or a layout name, got {layout!r}")
    table = _table()
    if layout.has_ibug68 and not layout.name.startswith("mediapipe"):
        rows, key = list(layout.ibug68), "ibug68"
    elif layout.has_mediapipe468:  # face-mesh points (mediapipe68 reads the 68 iBUG points off the face mesh)
        rows, key = list(layout.mediapipe468), "mediapipe468"
    else:
        raise RetargetError(f"layout {layout.name!r} has points that are no iBUG point or face-mesh "
                            "vertex: the ARKit reference motion has none of them")
    neutral = table[f"{key}_neutral"][rows]
    motion = table[f"{key}_motion"][:, rows]
    return ArkitReference(layout.name, neutral, motion)


@lru_cache(maxsize=1)
def _table() -> dict[str, np.ndarray]:
    """The reference table's arrays as float64, read once."""
    try:
        with np.load(REFERENCE, allow_pickle=False) as z:
            names = tuple(str(n) for n in z["names"])
            table = {k: z[k].astype(np.float64) for k in
                     ("ibug68_neutral", "ibug68_motion", "mediapipe468_neutral", "mediapipe468_motion")}
    except (OSError, KeyError, ValueError) as exc:
        raise RetargetError(f"could not read the ARKit reference table {str(REFERENCE)!r}: {exc}; "
                            "make it with bench/arkit_reference.py") from exc
    if names != ARKIT_NAMES:
        raise RetargetError(f"the ARKit reference table {str(REFERENCE)!r} does not hold ARKit's 52 "
                            "names in order; make it again with bench/arkit_reference.py")
    for array in table.values():
        array.flags.writeable = False
    return table
