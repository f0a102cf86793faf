"""Placing Woodward's 21 muscles and the jaw on any face from its landmarks.

The paper placed muscles by hand (§4: "Muscles were positioned using an interactive
application"); here `place_muscles` derives every origin, insertion and zone from the 68
iBUG points following `table.MUSCLE_TABLE`, sized in E, the distance between the eye
centres, so a face in cm, m or mm gets the same muscles in its own units. Directions are
those of a face frame fitted to the points (x toward the subject's left, y up, z out of
the face), so the mesh may be in any orientation.

The jaw's hinges are the jaw contour's top points (0-2 and 14-16, in front of the ears)
pushed back and in toward the condyles. Its per-vertex weights: a smooth step across the
lip contact line (lower face 1, upper face 0), faded out down the neck and behind the
hinges; on the lips themselves the step is replaced by the share of surface distance to
the upper and lower lip points, so that, on lips that are separate sheets (the sample
face's, or any mesh after `retarget open-mouth`, `retarget/lips.py`), the upper lip gets
0 and the lower lip 1 right up to the contact line and the lips part when the jaw opens.
This is the rig's lip separation (`weights/biharmonic.lip_supports`) for the jaw.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from retarget.errors import RetargetError
from retarget.layouts import IBUG68_TO_MEDIAPIPE468, Layout, get_layout
from retarget.muscles.model import Jaw, LinearMuscle, MuscleFace, SphincterMuscle
from retarget.muscles.table import MUSCLE_TABLE
from retarget.operators import edge_graph
from retarget.similarity import similarity_transform
from retarget.welding import welded

__all__ = ["ibug68_points", "jaw_weights", "place_muscles"]

_MIRROR68 = np.asarray(get_layout("ibug68").mirror)
_JAW_LIMITS = (0.0, 0.45)
"""Radians: closed to about 26 degrees open (ICT's jawOpen, fitted, is 0.36 rad)."""
_EYE_LIMITS = (-1.0, 1.0)
"""The orbicularis oculi may go negative: the eye opening wide, which fear needs and the
paper's muscles could not do (§10)."""
_MIN_MATCHED = 6


def _smoothstep(t):
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def ibug68_points(points: np.ndarray, layout: Layout | str = "ibug68") -> tuple[np.ndarray, np.ndarray]:
    """(68, 3) iBUG-ordered points and (68,) bool which of them the layout has.

    points : (N, 3) float, the layout's points on the mesh, mesh units.
    A layout point stands for iBUG point i when its ``ibug68`` index is i or its
    ``mediapipe468`` vertex is MediaPipe's vertex for i (so ``mediapipe468`` works too).
    Points the layout lacks (``ibug51`` has no jaw contour, ``dutreve21`` 21 of 68) are the
    built-in face's (`Layout.reference_points`) carried by the similarity that best fits
    the present ones: muscles need only rough anchors there.
    """
    layout = layout if isinstance(layout, Layout) else get_layout(layout)
    p = np.asarray(points, dtype=np.float64)
    if p.shape != (layout.n_points, 3) or not np.isfinite(p).all():
        raise RetargetError(f"points must be a finite ({layout.n_points}, 3) array for layout "
                            f"{layout.name!r}, got shape {p.shape}")
    out = np.full((68, 3), np.nan)
    ibug = np.asarray(layout.ibug68)
    mp = {v: j for j, v in enumerate(layout.mediapipe468)}
    for i in range(68):
        hit = np.flatnonzero(ibug == i)
        j = hit[0] if len(hit) else mp.get(IBUG68_TO_MEDIAPIPE468[i], -1)
        if j >= 0:
            out[i] = p[j]
    have = np.isfinite(out[:, 0])
    if have.sum() < _MIN_MATCHED:
        raise RetargetError(f"layout {layout.name!r} has {have.sum()} of the 68 iBUG points; "
                            f"muscles need at least {_MIN_MATCHED}")
    if not have.all():
        ref = np.asarray(get_layout("ibug68").reference_points())
        s, rot, t = similarity_transform(ref[have], out[have])
        out[~have] = s * ref[~have] @ rot.T + t
    return out, have


def _frame(p: np.ndarray) -> np.ndarray:
    """(3, 3) rows x (toward the subject's left), y (up), z (out of the face)."""
    x = p[42:48].mean(0) - p[36:42].mean(0)
    x /= np.linalg.norm(x)
    up = 0.5 * (p[42:48].mean(0) + p[36:42].mean(0)) - p[48:68].mean(0)
    y = up - (up @ x) * x
    y /= np.linalg.norm(y)
    return np.stack([x, y, np.cross(x, y)])


def _linear(name, origin, insertion, rs, rf, omega_deg, strength) -> LinearMuscle:
    length = float(np.linalg.norm(insertion - origin))
    return LinearMuscle(name, origin, insertion, rs * length, rf * length, np.radians(omega_deg), strength)


def _muscles(p: np.ndarray, frame: np.ndarray, e: float) -> list:
    """The 21 muscles of `MUSCLE_TABLE` in its order. p: (68, 3) points, e: eye distance."""
    X, Y, Z = frame
    mouth_half = 0.5 * float(np.linalg.norm(p[54] - p[48]))
    lip_half = 0.5 * float(np.linalg.norm(p[57] - p[51]))
    out = []
    for row in MUSCLE_TABLE:
        if row.side == "midline":            # orbicularis oris
            out.append(SphincterMuscle(
                # centred in front of the lips: pursing pushes them out as well as together
                row.base, p[48:68].mean(0) + mouth_half * Z, frame,
                (1.7 * mouth_half, 1.8 * lip_half, 2.2 * mouth_half), 0.55, 0.15 * e))
            continue
        for side, sx in (("left", 1.0), ("right", -1.0)):
            # recipes name the left side's points; `i` gives the one on this side
            def i(k, side=side):
                return k if side == "left" else int(_MIRROR68[k])

            def pt(k):
                return p[i(k)]

            name = f"{row.base}_{side}"
            inward = -sx * X
            b = row.base
            if b == "zygomatic_major":
                lid = 0.5 * (pt(46) + pt(47))
                bone = 0.5 * (pt(15) + pt(45))          # the zygomatic bone, below the eye's outer corner
                origin = bone + ((lid - bone) @ Y - 0.1 * e) * Y
                out.append(_linear(name, origin, pt(54), 1.0, 1.25, 20, 0.27 * e))
            elif b.startswith("frontalis"):
                brow = {"frontalis_inner": pt(22), "frontalis_major": pt(23),
                        "frontalis_secondary": pt(24), "frontalis_outer": 0.5 * (pt(25) + pt(26))}[b]
                origin = brow + 0.9 * e * Y - 0.08 * e * Z      # up the forehead, along its curve
                out.append(_linear(name, origin, brow, 0.95, 1.4, 18, 0.13 * e))
            elif b == "corrugator_supercilii":
                origin = p[27] - 0.08 * e * inward + 0.15 * e * Y + 0.05 * e * Z
                out.append(_linear(name, origin, pt(24), 0.5, 1.35, 40, 0.18 * e))
            elif b == "levator_labii_superioris_alaeque_nasi":
                origin = 0.5 * (pt(42) + p[28]) + 0.1 * e * Y + 0.05 * e * Z
                out.append(_linear(name, origin, pt(35), 1.0, 1.45, 20, 0.11 * e))
            elif b == "levator_labii_superioris":
                origin = 0.5 * (pt(46) + pt(47)) - 0.15 * e * Y + 0.05 * e * Z
                out.append(_linear(name, origin, 0.5 * (pt(52) + pt(53)), 1.0, 1.3, 20, 0.13 * e))
            elif b == "depressor_anguli_oris":
                # on the mandible below the corner (not the jaw contour's far-back point 11,
                # which would pull the corner back more than down)
                jawline = 0.5 * (pt(10) + pt(11))
                origin = pt(54) + ((jawline - pt(54)) @ Y) * Y - 0.1 * e * inward
                out.append(_linear(name, origin, pt(54), 1.0, 1.3, 25, 0.16 * e))
            elif b == "orbicularis_oculi":
                # a quarter of the slit above the lower lid: in a blink the upper lid travels
                # about three times as far as the lower (ICT's eyeBlink: 8.0 and 2.7 mm)
                upper, lower = 0.5 * (pt(43) + pt(44)), 0.5 * (pt(46) + pt(47))
                out.append(SphincterMuscle(name, 0.75 * lower + 0.25 * upper, frame,
                                           (0.55 * e, 0.42 * e, 0.5 * e), 0.4, 0.08 * e, _EYE_LIMITS,
                                           (0.25, 1.0, 0.5)))
            else:  # pragma: no cover - the table and these recipes are edited together
                raise AssertionError(f"no placement recipe for {b}")
    return out


def _hinges(p: np.ndarray, frame: np.ndarray, e: float) -> tuple[np.ndarray, np.ndarray]:
    """(3,) right and left jaw hinges: the top of the jaw contour (0-2 / 14-16, in front
    of the ears) pushed back toward the condyle, in from the skin and down to the tragus
    (the sample face's own jawOpen turns about such an axis)."""
    X, Y, Z = frame
    right = p[0:3].mean(0) - 0.2 * e * Y - 0.15 * e * Z + 0.1 * e * X
    left = p[14:17].mean(0) - 0.2 * e * Y - 0.15 * e * Z - 0.1 * e * X
    return right, left


def jaw_weights(vertices: np.ndarray, faces: np.ndarray, p: np.ndarray, frame: np.ndarray,
                hinges: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """(V,) float64 in [0, 1]: the share of the jaw angle each vertex turns by.

    vertices (V, 3), faces (F, 3) int, p (68, 3) iBUG points, frame (3, 3) face axes,
    hinges the jaw's two hinge points; all in mesh units.
    """
    v = np.asarray(vertices, dtype=np.float64)
    centre = 0.5 * (p[60:68].mean(0) + p[48:60].mean(0))
    local = (v - centre) @ frame.T
    lp = (p - centre) @ frame.T
    # the lip contact line: inner corners and the midpoints of facing inner lip points
    line = np.array([lp[60], 0.5 * (lp[61] + lp[67]), 0.5 * (lp[62] + lp[66]),
                     0.5 * (lp[63] + lp[65]), lp[64]])
    line = line[np.argsort(line[:, 0])]
    height = local[:, 1] - np.interp(local[:, 0], line[:, 0], line[:, 1])
    chin_depth = max(float(np.interp(0.0, line[:, 0], line[:, 1]) - lp[8, 1]), 1e-9)
    # a step from 0 at 0.2 chin depths above the line (the nose base stays) to 1 at 0.45 below
    w = _smoothstep((0.2 * chin_depth - height) / (0.65 * chin_depth))
    # the neck below the chin and everything behind the hinges stay
    w *= 1.0 - _smoothstep((lp[8, 1] - local[:, 1] - 0.3 * chin_depth) / (0.9 * chin_depth))
    e = float(np.linalg.norm(lp[42:48].mean(0) - lp[36:42].mean(0)))
    hinge_z = 0.5 * float((((hinges[0] - centre) + (hinges[1] - centre)) @ frame[2]))
    w *= _smoothstep((local[:, 2] - hinge_z) / (0.3 * e))
    # on the lips: the share of surface distance, 0 on the upper lip, 1 on the lower
    half_width = 0.5 * float(np.linalg.norm(lp[54] - lp[48]))
    half_height = 0.5 * float(np.linalg.norm(lp[57] - lp[51]))
    near = np.flatnonzero(((local[:, 0] / (1.8 * half_width)) ** 2 + (local[:, 1] / (3 * half_height)) ** 2
                           + (local[:, 2] / (1.5 * half_width)) ** 2) < 1.0)
    if len(near) and len(faces):
        tree = cKDTree(v)
        upper = np.unique(tree.query(p[[49, 50, 51, 52, 53, 61, 62, 63]])[1])
        lower = np.unique(tree.query(p[[55, 56, 57, 58, 59, 65, 66, 67]])[1])
        lower = np.setdiff1d(lower, upper)
        if len(lower) and len(upper):
            # along the surface with its coincident vertices welded (a UV seam is no wall)
            weld = welded(v, faces)
            graph = edge_graph(weld.vertices, weld.faces)
            limit = 4.0 * half_width
            du = dijkstra(graph, indices=np.unique(weld.index[upper]), min_only=True, limit=limit)[weld.index[near]]
            dl = dijkstra(graph, indices=np.unique(weld.index[lower]), min_only=True, limit=limit)[weld.index[near]]
            finite = np.isfinite(du) & np.isfinite(dl)
            share = np.where(finite, du / np.maximum(du + dl, 1e-300), np.where(np.isfinite(du), 1.0, 0.0))
            share = np.where(np.isfinite(du) | np.isfinite(dl), _smoothstep(share), w[near])
            ln = local[near]
            # the lips' region: down to the chin's fold, up to the upper lip but not the nose
            r = np.sqrt((ln[:, 0] / (1.15 * half_width)) ** 2 + (ln[:, 2] / half_width) ** 2
                        + (ln[:, 1] / np.where(ln[:, 1] > 0, 1.3, 2.0) / half_height) ** 2)
            beta = 1.0 - _smoothstep((r - 1.0) / 0.5)
            w[near] = (1.0 - beta) * w[near] + beta * share
    w = np.clip(w, 0.0, 1.0)
    w[w < 1e-4] = 0.0
    return w


def place_muscles(vertices, faces, points, layout: Layout | str = "ibug68") -> MuscleFace:
    """Woodward's 21 muscles and the jaw placed on a face (`table.MUSCLE_TABLE`).

    vertices : (V, 3) float, the mesh, any units and orientation.
    faces : (F, 3) int triangles (used to separate the lips for the jaw).
    points : (N, 3) float, the layout's feature points on the mesh (or a `SurfacePoints`).
    layout : a `Layout` or a layout name; any layout holding at least six of the 68 iBUG
        points directly or through its MediaPipe vertices (``ibug68``, ``mediapipe468``, ...).
    Returns a `MuscleFace` on `vertices`.
    """
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3 or not np.isfinite(v).all() or len(v) == 0:
        raise RetargetError(f"vertices must be a finite (V, 3) array, got shape {v.shape}")
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3 or (len(f) and (f.min() < 0 or f.max() >= len(v))):
        raise RetargetError(f"faces must be a (F, 3) array of vertex indices below {len(v)}")
    if hasattr(points, "positions"):
        points = points.positions(v)
    p, _ = ibug68_points(points, layout)
    frame = _frame(p)
    e = float(np.linalg.norm(p[42:48].mean(0) - p[36:42].mean(0)))
    if e <= 0:
        raise RetargetError("points: the two eyes coincide")
    hinges = _hinges(p, frame, e)
    jaw = Jaw(*hinges, jaw_weights(v, f.astype(np.int64), p, frame, hinges), _JAW_LIMITS)
    return MuscleFace(_muscles(p, frame, e), jaw, v)
