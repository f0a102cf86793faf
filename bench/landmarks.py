"""Zero-click landmarks (`retarget.facemesh.placement`): how often a face is found, how
far the points land from known positions, and how long a mesh takes.

    python bench/landmarks.py [--ict 10] [--sample 6] [--turned 1] [--seed 7] [--layout ibug68]

Faces with known landmarks:

    ict       --ict random identities of the ICT face model (../shared/data/ict_face;
              another seed than the offset table's, `bench/landmark_offsets.py`), each
              as it comes (facing +z) and --turned more times in a random orientation
              (any rotation, so the search over view directions is exercised)
    sample    --sample identities of the project's own procedural face
              (`retarget.sample_face`, its 68 landmark vertices), facing +z

Prints, per set: faces found / faces tried, seconds a mesh (median), and per region of
the layout the mean and p95 distance (mm) from the known point, with the per-point
correction (`layout_landmarks(..., corrected=True)`) and without it.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402
from tqdm import tqdm  # noqa: E402

from bench.ict import DATA, load_model  # noqa: E402
from bench.stream import machine  # noqa: E402
from retarget.errors import RetargetError  # noqa: E402
from retarget.facemesh.placement import find_face_mesh, layout_landmarks  # noqa: E402
from retarget.facemesh.tracker import FaceMeshTracker  # noqa: E402
from retarget.layouts import get_layout  # noqa: E402
from retarget.mesh import mesh_from_arrays  # noqa: E402
from retarget.sample_face import IDENTITY_PARAMETERS, sample_face  # noqa: E402


def measure(name: str, cases, layout, tracker, cm_to_mm: float = 10.0) -> None:
    """Find the points on each (vertices, faces, truth (N, 3)) case; print the figures."""
    errors = {True: [], False: []}
    seconds, found = [], 0
    for vertices, faces, truth in tqdm(cases, desc=name, leave=False):
        mesh = mesh_from_arrays(vertices, faces)
        start = time.perf_counter()
        try:
            face = find_face_mesh(mesh, tracker)
        except RetargetError:
            continue
        for corrected in (True, False):
            points, _ = layout_landmarks(face, layout, mesh, corrected=corrected)
            errors[corrected].append(np.linalg.norm(points.positions(vertices) - truth, axis=1) * cm_to_mm)
        seconds.append(time.perf_counter() - start)
        found += 1
    print(f"{name}: faces found {found}/{len(cases)}, {statistics.median(seconds):.2f} s a mesh (median)")
    regions = np.asarray(layout.regions)
    for corrected in (True, False):
        e = np.asarray(errors[corrected])
        cells = [f"{r} {e[:, regions == r].mean():.1f}/{np.percentile(e[:, regions == r], 95):.1f}"
                 for r in dict.fromkeys(layout.regions)]
        print(f"  {'corrected' if corrected else 'raw      '} mean/p95 mm: " + ", ".join(cells)
              + f"; all {e.mean():.1f}/{np.percentile(e, 95):.1f}")


def turned(vertices: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(V, 3) vertices in a uniformly random orientation about their centre."""
    centre = vertices.mean(0)
    return (vertices - centre) @ Rotation.random(random_state=rng).as_matrix().T + centre


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ict", type=int, default=10)
    parser.add_argument("--sample", type=int, default=6)
    parser.add_argument("--turned", type=int, default=1)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--layout", default="ibug68")
    args = parser.parse_args()
    print(machine())
    layout = get_layout(args.layout)
    rows = np.asarray(layout.ibug68)
    rng = np.random.default_rng(args.seed)
    tracker = FaceMeshTracker()
    if DATA.exists() and args.ict:
        model = load_model()
        cases = []
        for _ in range(args.ict):
            v = model.identity_face(rng.standard_normal(100))
            for k in range(1 + args.turned):
                w = v if k == 0 else turned(v, rng)
                cases.append((w, model.faces, w[model.landmarks68[rows]]))
        measure(f"ict ({args.ict} identities x {1 + args.turned} orientations)", cases, layout, tracker)
    else:
        print(f"ict: skipped ({DATA} absent)")
    cases = []
    for k in range(args.sample):
        face = sample_face(1, identity=None if k == 0 else rng.uniform(-1, 1, len(IDENTITY_PARAMETERS)))
        cases.append((face.vertices, face.faces, face.vertices[face.landmarks68[rows]]))
    measure(f"sample ({args.sample} identities)", cases, layout, tracker)


if __name__ == "__main__":
    main()
