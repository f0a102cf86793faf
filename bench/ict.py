"""Cross-identity retargeting ground truth from the ICT face model (../shared/data/ict_face).

The ICT model is additive: the same expression deltas apply to every identity, so
"identity A making expression e" retargeted onto identity B has a known answer, B + e.
This module builds the faces, the expressions, the three source conditions and the
vertex regions the accuracy benchmark reports on. Units are the model's centimetres.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.sparse.csgraph import dijkstra

from retarget.layouts import get_layout
from retarget.operators import edge_graph

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "ict_face" / "ict_face.npz"

# ICT-FaceKit's fixed jawline vertices standing in for the 68 layout's silhouette points
# 0-7 and 9-16 (see the data set's README); 8 (chin) is the landmark itself.
_RIGHT_JAWLINE = (1278, 1272, 12, 1834, 243, 781, 2199, 1447)
_LEFT_JAWLINE = (3661, 4390, 3022, 2484, 4036, 2253, 3490, 3496)
# 58 of the 68 points: every second jaw point (2..14) and all 51 inner points.
FEATURES_68 = (2, 4, 6, 8, 10, 12, 14) + tuple(range(17, 68))

# The six universal expressions as ARKit-shape combinations (FACS-style recipes).
UNIVERSAL = {
    "happiness": {"mouthSmile": 0.9, "cheekSquint": 0.6, "eyeSquint": 0.3},
    "sadness": {"browInnerUp": 0.8, "mouthFrown": 0.7, "mouthShrugLower": 0.4, "browDown": 0.2},
    "surprise": {"browInnerUp": 0.8, "browOuterUp": 0.8, "eyeWide": 0.7, "jawOpen": 0.5},
    "fear": {"browInnerUp": 0.7, "browOuterUp": 0.3, "eyeWide": 0.8, "mouthStretch": 0.6, "jawOpen": 0.2},
    "anger": {"browDown": 0.9, "eyeSquint": 0.5, "mouthPress": 0.6, "noseSneer": 0.3},
    "disgust": {"noseSneer": 0.9, "mouthUpperUp": 0.6, "browDown": 0.4, "cheekSquint": 0.4},
}


@dataclass
class ICTModel:
    neutral: np.ndarray      # (V, 3) float64 cm
    faces: np.ndarray        # (F, 3) int64
    expressions: np.ndarray  # (E, V, 3) float64 cm
    names: list[str]
    identity: np.ndarray     # (100, V, 3) float64 cm
    landmarks68: np.ndarray  # (68,) vertex indices
    face_count: int          # vertices [0, face_count) are the face area

    def identity_face(self, coefs: np.ndarray) -> np.ndarray:
        """(V, 3) neutral face of an identity (100 coefficients)."""
        return self.neutral + np.tensordot(coefs, self.identity, axes=1)

    def expression_offsets(self, weights: np.ndarray) -> np.ndarray:
        """(X, V, 3) expression displacements for (X, 53) weights."""
        return np.tensordot(weights, self.expressions, axes=1)

    def feature_vertices(self) -> np.ndarray:
        """(N,) vertex indices of the benchmark's feature points (FEATURES_68 order)."""
        out = []
        for i in FEATURES_68:
            if i < 8:
                out.append(_RIGHT_JAWLINE[i])
            elif 8 < i < 17:
                out.append(_LEFT_JAWLINE[i - 9])
            else:
                out.append(int(self.landmarks68[i]))
        return np.asarray(out)


def load_model(path: Path = DATA) -> ICTModel:
    d = np.load(path)
    return ICTModel(
        neutral=d["neutral"].astype(np.float64),
        faces=d["faces"].astype(np.int64),
        expressions=d["expressions"].astype(np.float64),
        names=[str(n) for n in d["expression_names"]],
        identity=d["identity"].astype(np.float64),
        landmarks68=d["landmarks_68"].astype(np.int64),
        face_count=int(d["face_vertex_count"]),
    )


def benchmark_layout():
    """The 68 layout restricted to the benchmark's 58 feature points."""
    return get_layout("ibug68").select(list(FEATURES_68), name="ict58")


def expression_weights(names: list[str], n_random: int, rng: np.random.Generator):
    """(X, 53) weights: the six universal expressions then n_random sparse combinations,
    and their labels."""
    index = {n: i for i, n in enumerate(names)}
    rows, labels = [], []

    def set_shape(row, base, value):
        for n in (base, base + "_L", base + "_R"):
            if n in index:
                row[index[n]] = value

    for label, recipe in UNIVERSAL.items():
        row = np.zeros(len(names))
        for base, value in recipe.items():
            set_shape(row, base, value)
        rows.append(row)
        labels.append(label)
    bases = sorted({n[:-2] if n.endswith(("_L", "_R")) else n for n in names} - {"mouthClose"})
    bases = [b for b in bases if not b.startswith("eyeLook")]
    for i in range(n_random):
        row = np.zeros(len(names))
        for base in rng.choice(bases, size=rng.integers(2, 5), replace=False):
            set_shape(row, base, rng.uniform(0.3, 1.0))
            if rng.random() < 0.3 and base + "_L" in index:  # now and then one-sided
                row[index[base + rng.choice(["_L", "_R"])]] = 0.0
        if row[index["jawOpen"]] > 0 and rng.random() < 0.5:
            row[index["mouthClose"]] = rng.uniform(0, row[index["jawOpen"]])
        rows.append(row)
        labels.append(f"random{i}")
    return np.asarray(rows), labels


def foreign_frame(points: np.ndarray, scale: float = 1.7, angle_deg: float = 25.0,
                  axis=(0.3, 1.0, 0.2), offset=(31.0, -12.0, 55.0)) -> np.ndarray:
    """(..., 3) points under a performer's own scale, rotation and translation."""
    a = np.asarray(axis, dtype=np.float64)
    a /= np.linalg.norm(a)
    t = np.radians(angle_deg)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    r = np.eye(3) + np.sin(t) * k + (1 - np.cos(t)) * k @ k
    return scale * points @ r.T + np.asarray(offset)


def image_points(points: np.ndarray, focal_px: float = 900.0, distance_cm: float = 55.0,
                 size=(640, 480)) -> np.ndarray:
    """(..., 2) pixel coordinates of (..., 3) points seen by a frontal pinhole camera
    (image y down), as a video tracker would report them."""
    z = distance_cm - points[..., 2]
    u = size[0] / 2 + focal_px * points[..., 0] / z
    v = size[1] / 2 - focal_px * (points[..., 1] - 1.0) / z
    return np.stack([u, v], axis=-1)


REPORT_REGIONS = ("brows", "eyes", "nose", "mouth", "jaw", "rest")
_REGION_OF = {"brows": "brows", "eyes": "eyes", "nose": "nose", "upper_lip": "mouth",
              "lower_lip": "mouth", "mouth_corners": "mouth", "jaw": "jaw"}


def vertex_regions(vertices: np.ndarray, faces: np.ndarray, feature_vertices: np.ndarray,
                   layout, face_count: int, reach_cm: float = 1.5):
    """Per face-area vertex: its report region and its layout region.

    A vertex takes the region of its nearest feature along the surface (graph geodesic, so
    the mouth slit separates the lips) if that feature is within reach_cm, else "rest".
    Returns (face_count,) report-region labels and (face_count,) layout-region labels
    ("" for rest).
    """
    g = dijkstra(edge_graph(vertices, faces), directed=False, indices=feature_vertices,
                 limit=reach_cm)[:, :face_count]
    nearest = g.argmin(0)
    reached = np.isfinite(g.min(0))
    layout_region = np.where(reached, np.asarray(layout.regions)[nearest], "")
    report = np.array([_REGION_OF.get(r, "rest") for r in layout_region])
    return report, layout_region
