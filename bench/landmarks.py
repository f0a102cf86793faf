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

    python bench/landmarks.py --spread 6 [--ict 3]

instead measures how much of the placement's error is variance: the 468 points are found
on --spread copies of each of --ict ICT identities, each copy moved by a random
similarity (scale 0.5-2, a turn of up to 10 degrees in the picture plane and 3 out of it,
a shift), carried back to the identity's own surface, and their RMS spread about their
mean (mm) printed per region of the mediapipe468 layout, beside how far the same point
lands on two different identities (compared on the first one's surface through ICT's
shared topology): the part that no averaging over pictures removes.
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


def spread(model, n_faces: int, copies: int, rng: np.random.Generator, tracker) -> None:
    """Print the 468 points' spread over moved copies of ICT identities (module docstring)."""
    from retarget.facemesh.placement import find_face_mesh as find

    regions = np.asarray(get_layout("mediapipe468").regions)
    rms, first = [], []
    for _ in tqdm(range(n_faces), desc="spread", leave=False):
        v = model.identity_face(rng.standard_normal(100))
        found = []
        for k in range(copies):
            turn = Rotation.from_euler("zyx", [rng.uniform(-10, 10), *rng.uniform(-3, 3, 2)], degrees=True)
            moved = (v - v.mean(0)) @ turn.as_matrix().T * rng.uniform(0.5, 2.0) + rng.uniform(-5, 5, 3)
            points = find(mesh_from_arrays(moved, model.faces), tracker).points
            found.append(points.positions(v) * 10.0)                    # on the identity itself, mm
        found = np.asarray(found)                                         # (copies, 468, 3)
        rms.append(np.sqrt(((found - found.mean(0)) ** 2).sum(2).mean(0)))
        first.append((v, points))
    rms = np.mean(rms, axis=0)
    (v0, p0), others = first[0], first[1:]
    between = np.mean([np.linalg.norm(p.positions(v0) - p0.positions(v0), axis=1) * 10.0 for _, p in others], axis=0)
    print(f"spread over {copies} moved copies of {n_faces} ICT identities, RMS mm per region; "
          f"and the same point on two identities, mean mm:")
    for r in dict.fromkeys(regions):
        print(f"  {r:<14}{rms[regions == r].mean():6.2f}{between[regions == r].mean():8.2f}")
    print(f"  {'all':<14}{rms.mean():6.2f}{between.mean():8.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ict", type=int, default=10)
    parser.add_argument("--sample", type=int, default=6)
    parser.add_argument("--turned", type=int, default=1)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--layout", default="ibug68")
    parser.add_argument("--spread", type=int, default=0,
                        help="instead: the points' spread over this many moved copies of --ict identities")
    args = parser.parse_args()
    print(machine())
    if args.spread:
        spread(load_model(), max(args.ict, 2), args.spread, np.random.default_rng(args.seed), FaceMeshTracker())
        return
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
