"""A built-in face: a procedural head front with blendshapes, needing no data files.

`sample_face` builds a regular grid over a plane (s, t) (about centimetres across and up the
face), cuts it open along the mouth slit and the two eye openings (the grid vertices between
the corners are duplicated, so upper and lower lips, and upper and lower lids, are separate
sheets that meet only at the corners), and maps it onto a head: each (s, t) names a ray from a
point inside the head (s / 10 cm and t / 10 cm are its azimuth and elevation), cast onto a
smooth union of squarish ellipsoids and pushed out along the ray by Gaussian relief (nose,
brows, cheekbones, lips, chin; eye sockets round eyeball bulges). The result is a graph over
the ray directions, so no relief or expression can fold it.

Identity parameters slide tissue over the plane (eyes, nose tip, lips) and scale the head, so
the landmark vertices follow the anatomy. Expressions are differences of the same generator
with one control at 1: tissue slides (lids, brows, mouth corners, pucker), relief changes
(smile cheeks, pucker, cheek puff) and a jaw rotation with a smooth falloff whose lower-lip
sheet turns and upper-lip sheet stays, which opens the slit. They are computed per identity,
so a blink closes the lids of every face exactly, and the same weights mean the same motion
on every identity (ground truth for cross-identity retargeting).

The built-in performance (`demo_performance`): another identity, `DEMO_PERFORMER`, performing
a looping `demo_weights`, seen through its 68 landmarks, the source that drives the sample face
in the web app's demo and in ``retarget demo``.

Units and axes follow the ICT face model in `shared/data/ict_face`: centimetres, +y up, +z out
of the face (it looks toward +z), +x the subject's left (the `_L` shapes act on +x). Landmarks
follow the iBUG / Multi-PIE 68-point order.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from retarget.errors import RetargetError

EXPRESSION_NAMES = (
    "jawOpen", "mouthSmile_L", "mouthSmile_R", "mouthPucker", "browInnerUp", "browOuterUp_L",
    "browOuterUp_R", "eyeBlink_L", "eyeBlink_R", "mouthFrown_L", "mouthFrown_R", "cheekPuff",
)
# Identity parameters in standard units (|value| <= 3 stays plausible): per unit, face width
# +5 %, nose tip 0.3 cm lower and 8 % more prominent, jaw width +7 %, lips 12 % taller and 15 %
# fuller, eyes 0.5 cm further apart.
IDENTITY_PARAMETERS = ("face_width", "nose_length", "jaw_width", "lip_thickness", "eye_spacing")

# Material layout (s, t in cm-like units; the slits lie on grid lines at these values).
_R0 = 10.0                          # cm of (s, t) per radian of ray angle
_ORIGIN = np.array([0.0, 1.0, 0.0])  # where the rays start, inside the head
_T_MOUTH, _S_MOUTH = -3.7, 2.2       # mouth slit row and corner column
_T_EYE, _S_EYE_IN, _S_EYE_OUT = 2.4, 1.98, 4.78
_S_EYE = 0.5 * (_S_EYE_IN + _S_EYE_OUT)
_T_NOSE, _T_TIP, _T_BROW, _T_CHIN = 0.4, -0.7, 4.2, -6.9
_S_KNOTS = (0.0, _S_EYE_IN, _S_MOUTH, _S_EYE_OUT, 8.0, 17.5)
_S_STEPS = (0.25, 0.25, 0.25, 0.3, 0.4)
_T_KNOTS = (-10.5, -7.5, _T_MOUTH, _T_EYE, 7.0, 11.0)
_T_STEPS = (0.35, 0.25, 0.25, 0.25, 0.4)
_JAW_PIVOT, _JAW_ANGLE = np.array([0.0, 1.0, -0.5]), np.radians(15.0)
_LOOP_S = 10.0                       # seconds; the demo performance repeats with this period

DEMO_PERFORMER = (1.2, -0.8, 0.9, 0.6, -0.7)
"""The built-in performance's performer, shape parameters in `IDENTITY_PARAMETERS` order: far
enough from the sample face's zeros that the demo has a real change of proportions to carry."""


@dataclass(frozen=True, eq=False)
class SampleFace:
    """A procedural face mesh with linear expression shapes.

    vertices : (V, 3) float64, neutral positions in cm (+y up, +z out of the face, +x left).
    faces : (F, 3) int64 triangles, counter-clockwise seen from outside.
    uv : (V, 2) float64 texture coordinates in [0, 1] (the material grid).
    landmarks68 : (68,) int64 vertex indices in iBUG / Multi-PIE 68-point order.
    expression_names : (E,) ARKit-style names of the shapes.
    expressions : (E, V, 3) float64 displacements in cm at weight 1.
    """

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    landmarks68: np.ndarray
    expression_names: tuple[str, ...]
    expressions: np.ndarray


def _axis(knots, steps, resolution: int) -> np.ndarray:
    """Increasing grid coordinates through every knot, about steps / resolution apart."""
    out = [np.array([knots[0]])]
    for a, b, h in zip(knots[:-1], knots[1:], steps):
        n = max(1, round((b - a) * resolution / h))
        seg = a + (b - a) * np.arange(1, n + 1) / n
        seg[-1] = b                                  # knots exactly on the grid
        out.append(seg)
    return np.concatenate(out)


@dataclass(frozen=True, eq=False)
class _Layout:
    st: np.ndarray           # (V, 2) material coordinates
    faces: np.ndarray        # (F, 3)
    is_copy: np.ndarray      # (V,) bool: a lower-sheet copy of a slit vertex
    upper_mouth: np.ndarray  # (V,) bool: on or above the mouth row and not a copy
    upper_eye: np.ndarray    # (V,) bool: likewise for the eye row


def _layout(resolution: int) -> _Layout:
    """The cut grid: rows up t, columns across s, slits duplicated for the lower sheets."""
    half = _axis(_S_KNOTS, _S_STEPS, resolution)
    s_ax = np.concatenate([-half[:0:-1], half])
    t_ax = _axis(_T_KNOTS, _T_STEPS, resolution)
    ns, nt = len(s_ax), len(t_ax)
    s, t = np.meshgrid(s_ax, t_ax)
    st = np.stack([s.ravel(), t.ravel()], 1)
    idx = np.arange(ns * nt).reshape(nt, ns)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]  # quad: a b below, c d above
    left = (s_ax[:-1] + s_ax[1:] < 0)[None, :]  # mirror the diagonals for a symmetric mesh
    tri = np.where(left[..., None], np.stack([a, b, d, a, d, c], -1), np.stack([a, b, c, b, d, c], -1))
    tri = tri.reshape(nt - 1, ns - 1, 2, 3)
    s_abs = np.abs(s_ax)
    slits = [(np.flatnonzero(np.isclose(t_ax, _T_MOUTH))[0], s_abs < _S_MOUTH - 1e-9),
             (np.flatnonzero(np.isclose(t_ax, _T_EYE))[0],
              (s_abs > _S_EYE_IN + 1e-9) & (s_abs < _S_EYE_OUT - 1e-9))]
    lower_of = np.arange(ns * nt)
    n_v = ns * nt
    for row, cols in slits:
        orig = idx[row, cols]
        lower_of[orig] = n_v + np.arange(len(orig))
        n_v += len(orig)
        below = tri[row - 1]                         # quads whose top row is the slit row
        tri[row - 1] = np.where(np.isin(below, orig), lower_of[below], below)
    copies = np.concatenate([idx[r, c] for r, c in slits])
    st = np.concatenate([st, st[copies]])
    is_copy = np.arange(len(st)) >= ns * nt
    return _Layout(st, tri.reshape(-1, 3).astype(np.int64), is_copy,
                   (st[:, 1] >= _T_MOUTH) & ~is_copy, (st[:, 1] >= _T_EYE) & ~is_copy)


def _identity_parameters(identity) -> np.ndarray:
    p = np.zeros(len(IDENTITY_PARAMETERS))
    if identity is None:
        return p
    q = np.asarray(identity, dtype=np.float64)
    if q.ndim != 1 or len(q) > len(p) or not np.all(np.isfinite(q)):
        raise RetargetError(f"identity must be a finite vector of at most {len(p)} values "
                            f"({', '.join(IDENTITY_PARAMETERS)}), got shape {q.shape}")
    p[: len(q)] = q
    return p


def _blob(p, centre, radii):
    """Signed field (about cm) of an ellipsoid with squarish horizontal sections (|x|^3 + |z|^3)."""
    q = np.abs(p - centre) / radii
    g = np.cbrt(q[:, 0] * q[:, 0] * q[:, 0] + q[:, 2] * q[:, 2] * q[:, 2])
    return (np.sqrt(g * g + q[:, 1] * q[:, 1]) - 1.0) * np.cbrt(np.prod(radii))


def _smin(a, b, k):
    h = np.clip(k - np.abs(a - b), 0.0, None) / k
    return np.minimum(a, b) - 0.25 * k * h * h


def _head_sdf(p, idp):
    wx = 1.0 + 0.05 * idp[0]
    jaw = 1.0 + 0.07 * idp[2]
    d = _blob(p, (0.0, 3.0, 0.0), (7.5 * wx, 9.8, 10.2))                 # cranium
    d = _smin(d, _blob(p, (0.0, -2.6, 1.5), (6.2 * wx * jaw, 5.6, 9.3)), 2.0)  # face and jaw
    d = _smin(d, _blob(p, (0.0, -5.6, 8.7), (2.6 * jaw, 2.0, 1.9)), 1.5)   # chin
    return _smin(d, _blob(p, (0.0, -9.5, -1.5), (5.0 * wx, 6.0, 5.3)), 2.0)  # neck


def _surface(x, idp):
    """Points (V, 3) where the rays of plane coordinates x (V, 2) meet the head, and the rays (V, 3).

    Relief is added along the rays, so the face stays a graph over the ray directions: it
    cannot fold over, whatever the relief.
    """
    th, ph = x[:, 0] / _R0, x[:, 1] / _R0
    ray = np.stack([np.cos(ph) * np.sin(th), np.sin(ph), np.cos(ph) * np.cos(th)], 1)
    lo, hi = np.full(len(x), 2.0), np.full(len(x), 18.0)
    for _ in range(28):                              # bisection to 6e-8 cm: inside at 2, outside at 18
        mid = 0.5 * (lo + hi)
        out = _head_sdf(_ORIGIN + mid[:, None] * ray, idp) > 0
        hi, lo = np.where(out, mid, hi), np.where(out, lo, mid)
    return _ORIGIN + (0.5 * (lo + hi))[:, None] * ray, ray


def _bump(s, t, cs, ct, ws, wt):
    """Gaussian bump of height 1 at (cs, ct), widths ws and wt."""
    return np.exp(-(((s - cs) / ws) ** 2) - ((t - ct) / wt) ** 2)


def _material(st):
    """(V, 2) material coordinates of grid points st (V, 2): a disc round the nose is contracted,
    so the nose (steep sides seen from the ray origin) gets 2.5 times the rays."""
    s, t = st[:, 0], st[:, 1] - _T_NOSE
    k = 1.0 - 0.6 * np.exp(-((s / 1.3) ** 2) - (t / 1.9) ** 2)   # monotone: d(rho k)/d rho >= 0.4
    return np.stack([s * k, t * k + _T_NOSE], 1)


def _identity_warp(m, idp):
    """(V, 2) rest positions of material points m (V, 2): identity moves tissue, so landmarks follow.

    Each eye moves out 0.25 cm per unit eye_spacing, the nose tip 0.3 cm down per unit
    nose_length, the lips stretch 12 % per unit lip_thickness.
    """
    s, t = m[:, 0], m[:, 1]
    ds = 0.25 * idp[4] * np.tanh(s / 0.7) * _bump(np.abs(s), t, _S_EYE, _T_EYE, 2.4, 2.8)
    dt = -0.3 * idp[1] * _bump(s, t, 0.0, _T_TIP - 0.3, 1.8, 1.3)
    tau = (t - _T_MOUTH) / 0.8
    dt += 0.1 * idp[3] * tau * np.exp(-tau * tau) * _profile(s / (_S_MOUTH + 1.0), 1.0)
    return np.stack([s + ds, t + dt], 1)


def _profile(u, power):
    """(1 - u^2)^power on [-1, 1], 0 outside."""
    return np.clip(1.0 - u * u, 0.0, None) ** power


def _plane_motion(m, lay, c):
    """(V, 2) in-plane slide of material points m (V, 2): eye openings, lids, brows, mouth corners."""
    s, t = m[:, 0], m[:, 1]
    ds, dt = np.zeros_like(s), np.zeros_like(t)
    for side, tag in ((1.0, "L"), (-1.0, "R")):
        u = (side * s - _S_EYE) / (0.5 * (_S_EYE_OUT - _S_EYE_IN))
        shape = _profile(u + 0.15 * (1.0 - u * u), 0.8)       # upper lid peak nearer the nose
        up, lo, blink = 0.55 * shape, 0.38 * shape, c[f"eyeBlink_{tag}"]
        g = np.exp(-(((t - _T_EYE) / 0.75) ** 2))
        dt += g * np.where(lay.upper_eye, up - blink * (up + 0.8 * lo - 0.03 * shape),
                           -lo + blink * 0.2 * lo)
        corner = _bump(s, t, side * _S_MOUTH, _T_MOUTH, 1.1, 1.1)
        ds += side * corner * (0.5 * c[f"mouthSmile_{tag}"] - 0.1 * c[f"mouthFrown_{tag}"])
        dt += corner * (0.55 * c[f"mouthSmile_{tag}"] - 0.5 * c[f"mouthFrown_{tag}"])
        dt += 0.25 * c[f"mouthSmile_{tag}"] * _bump(s, t, side * 3.6, _T_EYE - 1.6, 1.6, 1.0)
        dt += 0.7 * c[f"browOuterUp_{tag}"] * _bump(s, t, side * 5.0, _T_BROW, 1.8, 1.7)
        dt += 0.7 * c["browInnerUp"] * _bump(s, t, side * 1.7, _T_BROW, 1.2, 1.7)
    dt -= 0.2 * (_bump(s, t, _S_MOUTH, _T_MOUTH, 1.2, 1.2) + _bump(s, t, -_S_MOUTH, _T_MOUTH, 1.2, 1.2))
    near_mouth = np.exp(-(((t - _T_MOUTH) / 1.4) ** 2))
    gap = 0.03 * _profile(s / _S_MOUTH, 0.5) * np.exp(-(((t - _T_MOUTH) / 0.5) ** 2))
    dt += np.where(lay.upper_mouth, gap, -gap)
    ds -= 0.3 * c["mouthPucker"] * s * near_mouth * np.exp(-((s / 3.5) ** 4))
    return np.stack([ds, dt], 1)


def _relief(m, x, lay, c, idp, eye_centre):
    """(V,) height (cm) along the rays: tissue relief (nose, brows, cheeks, lips, chin) at
    material points m (V, 2), bone relief (sockets, eyeballs, temples) at positions x (V, 2);
    eye_centre (2, 2) positions of the eyeballs."""
    s, t = m[:, 0], m[:, 1]
    lips, size, tip = 1.0 + 0.15 * idp[3], 1.0 + 0.08 * idp[1], _T_TIP
    tau = np.clip((2.6 - t) / (2.6 - tip), 0.0, 1.0)                 # 0 at the nasion, 1 at the tip
    h = size * (0.45 + 1.85 * tau) * np.exp(-((s / (0.5 + 0.5 * tau)) ** 2))  # dorsum
    h *= 0.5 * (1.0 + np.tanh((t - tip + 0.75) / 0.4))                        # underside
    h *= np.exp(-((np.maximum(t - 2.6, 0.0) / 0.7) ** 2))                        # nasion
    h += size * 0.35 * _bump(s, t, 0.0, tip, 0.6, 0.6)                          # lobule
    h += size * 0.6 * (_bump(s, t, 1.15, tip - 0.6, 0.5, 0.45) + _bump(s, t, -1.15, tip - 0.6, 0.5, 0.45))
    for side, tag in ((1.0, "L"), (-1.0, "R")):
        smile = c[f"mouthSmile_{tag}"]
        h += 0.4 * np.exp(-(((t - _brow_line(s)) / 0.45) ** 2)) * _profile((side * s - 3.3) / 2.6, 1.0)
        h += 0.45 * _bump(s, t, side * 4.3, _T_EYE - 1.7, 1.4, 1.0)              # cheekbone
        h += (0.3 + 0.3 * smile) * _bump(s, t, side * 3.0, _T_MOUTH + 1.6, 1.3, 1.3)  # cheek
        h += 0.9 * c["cheekPuff"] * _bump(s, t, side * 3.3, _T_MOUTH + 0.3, 1.6, 1.6)
        h -= 0.3 * smile * _bump(s, t, side * _S_MOUTH, _T_MOUTH, 0.8, 0.8)     # corner back
    lip_s = _profile(s / _S_MOUTH, 0.7) * lips * (1.0 + 0.9 * c["mouthPucker"])
    upper = 0.55 * np.exp(-(((t - _T_MOUTH - 0.32) / 0.33) ** 2))
    lower = 0.65 * np.exp(-(((t - _T_MOUTH + 0.45) / 0.4) ** 2))
    h += lip_s * np.where(lay.upper_mouth, upper, lower)
    h += (0.55 + 0.5 * c["mouthPucker"]) * _bump(s, t, 0.0, _T_MOUTH + 0.4, 2.6, 2.2)  # muzzle
    h -= 0.2 * _bump(s, t, 0.0, _T_MOUTH - 1.35, 1.3, 0.35)                    # labiomental fold
    h += 0.45 * _bump(s, t, 0.0, _T_CHIN + 1.0, 1.3, 0.9)
    xs, xt = x[:, 0], x[:, 1]
    for es, et in eye_centre:
        h += 0.4 * _bump(xs, xt, es * 0.9, _T_BROW - 0.3, 2.0, 0.8)              # brow bone
        h -= 0.8 * _bump(xs, xt, es, et + 0.55, 1.6, 0.9) + 0.25 * _bump(xs, xt, es, et - 0.9, 1.4, 0.6)
        h += 0.7 * _profile(np.hypot(xs - es, xt - et) / 1.4, 2.0)                # eyeball
        h -= 0.4 * _bump(xs, xt, np.sign(es) * 6.3, _T_EYE + 1.5, 1.2, 1.5)       # temple
    return h


def _jaw_weight(m, lay):
    """(V,) share of the jaw rotation: 1 on the chin and lower lip, 0 on the upper lip."""
    s, t = m[:, 0], m[:, 1]
    line = _T_MOUTH + 0.6 * np.maximum(np.abs(s) - _S_MOUTH, 0.0)
    a = 0.5 * (1.0 + np.tanh((line - t) / 0.9))
    k = _profile(s / _S_MOUTH, 1.0) * np.exp(-(((t - _T_MOUTH) / 0.9) ** 2))
    return np.where(lay.upper_mouth, a - a * k, a + (1.0 - a) * k)


def _geometry(lay, idp, c, neutral=None):
    """(V, 3) vertices for identity idp and expression controls c (name -> weight), and the
    (positions, surface points, rays) that a later call may pass as neutral to skip the rays
    that did not move."""
    m = _material(lay.st)
    eye_c = _identity_warp(_material(np.array([[_S_EYE, _T_EYE], [-_S_EYE, _T_EYE]])), idp)
    x = _identity_warp(m, idp) + _plane_motion(m, lay, c)
    if neutral is None:
        p, ray = _surface(x, idp)
    else:                                            # cast again only the rays that moved
        moved = np.any(np.abs(x - neutral[0]) > 1e-7, axis=1)
        x = np.where(moved[:, None], x, neutral[0])
        p, ray = neutral[1].copy(), neutral[2].copy()
        p[moved], ray[moved] = _surface(x[moved], idp)
    v = p + ray * _relief(m, x, lay, c, idp, eye_c)[:, None]
    angle = _JAW_ANGLE * c["jawOpen"] * _jaw_weight(m, lay)
    y, z = v[:, 1] - _JAW_PIVOT[1], v[:, 2] - _JAW_PIVOT[2]
    ca, sa = np.cos(angle), np.sin(angle)
    v[:, 1], v[:, 2] = _JAW_PIVOT[1] + ca * y - sa * z, _JAW_PIVOT[2] + sa * y + ca * z
    return v, (x, p, ray)


# Landmark spots on the material plane for the subject's right half and midline, in Multi-PIE
# order (jaw, brow and nose: the ray angles of the ICT face's landmarks); the left half is the
# mirror image. Eyelid and inner-lip points are then snapped onto their slit (upper or lower sheet).
_LANDMARK_ST = np.array([
    [-11.1, 3.15], [-10.76, 0.59], [-9.92, -1.75], [-9.03, -3.82], [-7.51, -5.79], [-5.3, -7.02],
    [-3.35, -7.06], [-1.49, -6.72], [0.0, -6.88],                                     # jaw 0-8
    [-6.34, 4.04], [-5.02, 4.52], [-3.68, 4.63], [-2.26, 4.5], [-1.09, 4.27],       # brow 17-21
    [0.0, 2.5], [0.0, 1.41], [0.0, 0.5], [0.0, -0.45],                                # nose 27-30
    [-1.15, -1.94], [-0.53, -1.85], [0.0, -1.88],                                     # base 31-33
    [-4.78, 2.4], [-3.92, 2.4], [-2.84, 2.4], [-1.98, 2.4], [-2.84, 2.4], [-3.92, 2.4],  # eye 36-41
    [-2.45, -3.7], [-1.51, -3.05], [-0.62, -2.9], [0.0, -2.95],                        # outer lip 48-51
    [0.0, -4.65], [-0.91, -4.6], [-1.64, -4.45],                                      # 57-59
    [-2.2, -3.7], [-0.9, -3.7], [0.0, -3.7], [0.0, -3.7], [-0.9, -3.7],               # 60-62, 66-67
])
_RIGHT = np.r_[0:9, 17:22, 27:34, 36:42, 48:52, 57:63, 66:68]
_MIRROR = np.r_[16:-1:-1, 26:16:-1, 27:31, 35:30:-1, 45:41:-1, 47, 46, 39:35:-1, 41, 40,
                54:47:-1, 59:54:-1, 64:59:-1, 67:64:-1]       # landmark k <-> _MIRROR[k]
_LIDS_LOWER, _LIDS_UPPER = np.r_[40, 41, 46, 47, 65:68], np.r_[37, 38, 43, 44, 61:64]


def _landmarks(lay) -> np.ndarray:
    """(68,) vertex indices picked on the material grid, so the same for every identity."""
    target = np.zeros((68, 2))
    target[_MIRROR[_RIGHT]] = _LANDMARK_ST * [-1.0, 1.0]
    target[_RIGHT] = _LANDMARK_ST
    st, out = lay.st, np.empty(68, dtype=np.int64)
    rest = _material(st)
    corners = np.isin(np.abs(st[:, 0]), [_S_EYE_IN, _S_EYE_OUT, _S_MOUTH])
    for k, (s, t) in enumerate(target):
        cand = ~lay.is_copy
        if k in _LIDS_LOWER or k in _LIDS_UPPER:
            cand = np.isclose(st[:, 1], t) & ~corners & (lay.is_copy == (k in _LIDS_LOWER))
        idx = np.flatnonzero(cand)
        out[k] = idx[np.argmin(np.hypot(rest[idx, 0] - s, rest[idx, 1] - t))]
    return out


def _brow_line(s):
    """Material t of the eyebrow centre line over column s."""
    return _T_BROW + 0.35 * _profile((np.abs(s) - 3.3) / 2.4, 1.0)


def sample_face(resolution: int = 1, identity: np.ndarray | None = None) -> SampleFace:
    """The built-in face.

    resolution : int in [1, 8]; the grid spacing is about 2.5 mm / resolution on the face, so the
        vertex count grows as resolution**2 (8430 at 1, 132907 at 4).
    identity : optional (k,) float, k <= 5, shape parameters in standard units (|value| <= 3 stays
        plausible), in the order of `IDENTITY_PARAMETERS`; missing trailing values are 0. Every
        identity has the same vertex count, triangles and landmark indices.
    """
    if isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer)) \
            or not 1 <= resolution <= 8:
        raise RetargetError(f"resolution must be an integer in [1, 8], got {resolution!r}")
    idp = _identity_parameters(identity)
    lay = _layout(int(resolution))
    zero = dict.fromkeys(EXPRESSION_NAMES, 0.0)
    neutral, cache = _geometry(lay, idp, zero)
    shapes = np.stack([_geometry(lay, idp, {**zero, name: 1.0}, cache)[0] - neutral
                       for name in EXPRESSION_NAMES])
    lo, hi = _S_KNOTS[-1], (_T_KNOTS[0], _T_KNOTS[-1])
    uv = np.stack([(lay.st[:, 0] + lo) / (2 * lo), (lay.st[:, 1] - hi[0]) / (hi[1] - hi[0])], 1)
    return SampleFace(neutral, lay.faces, uv, _landmarks(lay), EXPRESSION_NAMES, shapes)


def demo_weights(n_frames: int, fps: float = 30.0) -> np.ndarray:
    """(n_frames, E) float64 weights in [0, 1], in `EXPRESSION_NAMES` order, for a looping demo.

    A 10 s loop: talking (jaw at syllable rate, an "oo" pucker), surprise (jaw and brows), a
    smile, a frown, a cheek puff and a smirk with one brow raised; blinks every 1.5 to 2 s and a
    wink. Each shape passes 0.8 at least once per loop. Weights are smooth (raised-cosine pulses
    and loop-periodic sines), so frame n and frame n + 10 s * fps are equal.
    """
    if isinstance(n_frames, bool) or not isinstance(n_frames, (int, np.integer)) or n_frames < 0:
        raise RetargetError(f"n_frames must be a non-negative integer, got {n_frames!r}")
    if not np.isfinite(fps) or fps <= 0:
        raise RetargetError(f"fps must be a positive number, got {fps!r}")
    t = np.arange(n_frames) / float(fps)

    def pulse(centre, width, peak=1.0):
        d = (t - centre + 0.5 * _LOOP_S) % _LOOP_S - 0.5 * _LOOP_S
        return peak * np.where(np.abs(d) < width, 0.5 + 0.5 * np.cos(np.pi * d / width), 0.0)

    syllables = 0.5 - 0.3 * np.cos(2 * np.pi * 4.1 * t) - 0.2 * np.cos(2 * np.pi * 2.7 * t + 1.0)
    blink = sum(pulse(c, 0.13) for c in (0.8, 2.6, 4.4, 6.2, 7.7, 9.6)) + pulse(5.2, 0.6, 0.25)
    w = {
        "jawOpen": pulse(1.5, 1.6) * 0.45 * syllables + pulse(3.7, 0.6, 0.85),
        "mouthPucker": pulse(2.3, 0.35, 0.85),
        "browInnerUp": pulse(3.7, 0.6, 0.9) + pulse(6.7, 0.6, 0.6),
        "browOuterUp_L": pulse(3.7, 0.6, 0.85),
        "browOuterUp_R": pulse(3.7, 0.6, 0.85) + pulse(9.0, 0.6, 0.8),
        "mouthSmile_L": pulse(5.2, 0.8, 0.9) + pulse(9.0, 0.6, 0.85),
        "mouthSmile_R": pulse(5.2, 0.8, 0.9) + pulse(9.0, 0.6, 0.2),
        "mouthFrown_L": pulse(6.7, 0.6, 0.85),
        "mouthFrown_R": pulse(6.7, 0.6, 0.85),
        "cheekPuff": pulse(8.0, 0.5, 0.9),
        "eyeBlink_L": blink + pulse(9.2, 0.25),
        "eyeBlink_R": blink,
    }
    return np.clip(np.stack([w[name] for name in EXPRESSION_NAMES], 1), 0.0, 1.0)


def posed_vertices(face: SampleFace, weights: np.ndarray) -> np.ndarray:
    """Vertices posed by expression weights: (E,) -> (V, 3), or (F, E) -> (F, V, 3), float64 cm."""
    w = np.asarray(weights, dtype=np.float64)
    n_expr = len(face.expression_names)
    if w.ndim not in (1, 2) or w.shape[-1] != n_expr or not np.all(np.isfinite(w)):
        raise RetargetError(f"weights must be finite with shape ({n_expr},) or (F, {n_expr}), got {w.shape}")
    return face.vertices + np.tensordot(w, face.expressions, axes=(-1, 0))


def demo_performance(fps: float = 30.0, n_frames: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The built-in performance: `DEMO_PERFORMER`'s 68 landmarks (iBUG order) at rest,
    (68, 3) float64 cm, read-only, and performing `demo_weights` at `fps`, (F, 68, 3) float64
    cm; F = `n_frames`, by default one loop (10 s, after which the performance repeats).

    The performer is built once per process (about a second); the frames are cheap.
    """
    if not np.isfinite(fps) or fps <= 0:
        raise RetargetError(f"fps must be a positive number, got {fps!r}")
    neutral, expressions = _demo_performer68()
    weights = demo_weights(int(round(_LOOP_S * fps)) if n_frames is None else n_frames, fps)
    return neutral, neutral + np.tensordot(weights, expressions, axes=1)


def demo_points(layout, fps: float = 30.0, n_frames: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The built-in performance in a layout's points: (N, 3) at rest and (F, N, 3) frames,
    float64 cm, as `demo_performance`.

    layout : a `retarget.layouts.Layout`. A layout of iBUG points picks the performer's
    landmarks; the dense ``mediapipe468`` finds the face mesh's points on the performer
    with no clicks (`retarget.facemesh.placement`, once per process, about a second), as a
    user's own face would be tracked.
    """
    if layout.has_ibug68:
        neutral, frames = demo_performance(fps, n_frames)
        rows = list(layout.ibug68)
        return neutral[rows], frames[:, rows]
    if not layout.has_mediapipe468:
        raise RetargetError(f"the demo performer has no points for layout {layout.name!r} (points "
                            "that are no iBUG point or face-mesh vertex): play a take of it")
    if not np.isfinite(fps) or fps <= 0:
        raise RetargetError(f"fps must be a positive number, got {fps!r}")
    points, expressions = _demo_performer468()
    rows = list(layout.mediapipe468)
    weights = demo_weights(int(round(_LOOP_S * fps)) if n_frames is None else n_frames, fps)
    neutral = points[rows]
    return neutral, neutral + np.tensordot(weights, expressions[:, rows], axes=1)


@lru_cache(maxsize=1)
def _demo_performer468() -> tuple[np.ndarray, np.ndarray]:
    """`DEMO_PERFORMER`'s 468 face-mesh points: neutral (468, 3) and expressions (E, 468, 3)."""
    from retarget.facemesh.placement import find_face_mesh
    from retarget.mesh import mesh_from_arrays

    performer = sample_face(identity=np.asarray(DEMO_PERFORMER))
    points = find_face_mesh(mesh_from_arrays(performer.vertices, performer.faces)).points
    neutral, expressions = points.positions(performer.vertices), points.positions(performer.expressions)
    neutral.flags.writeable = expressions.flags.writeable = False
    return neutral, expressions


@lru_cache(maxsize=1)
def _demo_performer68() -> tuple[np.ndarray, np.ndarray]:
    """`DEMO_PERFORMER`'s landmarks: neutral (68, 3) and expressions (E, 68, 3), read-only."""
    performer = sample_face(identity=np.asarray(DEMO_PERFORMER))
    lm = np.asarray(performer.landmarks68)
    neutral, expressions = performer.vertices[lm], performer.expressions[:, lm]
    neutral.flags.writeable = expressions.flags.writeable = False
    return neutral, expressions
