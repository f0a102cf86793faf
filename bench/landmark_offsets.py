"""Measure the table of per-point offsets that zero-click landmarks apply
(`retarget/facemesh/landmark_offsets.json`) on the ICT face model's identities.

    python bench/landmark_offsets.py [--faces 24] [--seed 2026] [--out PATH]

For each of --faces random ICT identities (coefficients ~ N(0, 1), as the model's own
sampler draws them), the 468 face-mesh points are found on the neutral mesh
(`find_face_mesh`) and each iBUG point's face-mesh vertex is compared with the ICT
landmark: the offset from one to the other, in the straight view's axes and in eye
widths, averaged over the faces, is the table; its RMS spread about that mean is stored
with it. `bench/landmarks.py` measures the result on other identities (another seed)
and on the project's own sample faces. Needs ../shared/data/ict_face; the table carries
the ICT-FaceKit MIT notice (it is derived from the model).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

from bench.ict import load_model  # noqa: E402
from retarget.facemesh.placement import EYE_CORNERS, OFFSETS, find_face_mesh, layout_landmarks  # noqa: E402
from retarget.facemesh.tracker import FaceMeshTracker  # noqa: E402
from retarget.layouts import get_layout  # noqa: E402
from retarget.mesh import mesh_from_arrays  # noqa: E402

ICT_NOTICE = (
    "Derived from the ICT Face Model (ICT-FaceKit, USC Institute for Creative Technologies) by "
    "bench/landmark_offsets.py. MIT License. Copyright (c) 2020 USC Institute for Creative "
    "Technologies. Permission is hereby granted, free of charge, to any person obtaining a copy "
    "of this software and associated documentation files (the \"Software\"), to deal in the "
    "Software without restriction, including without limitation the rights to use, copy, modify, "
    "merge, publish, distribute, sublicense, and/or sell copies of the Software, and to permit "
    "persons to whom the Software is furnished to do so, subject to the following conditions: "
    "The above copyright notice and this permission notice shall be included in all copies or "
    "substantial portions of the Software. THE SOFTWARE IS PROVIDED \"AS IS\", WITHOUT WARRANTY "
    "OF ANY KIND, EXPRESS OR IMPLIED, INCLUDING BUT NOT LIMITED TO THE WARRANTIES OF "
    "MERCHANTABILITY, FITNESS FOR A PARTICULAR PURPOSE AND NONINFRINGEMENT. IN NO EVENT SHALL THE "
    "AUTHORS OR COPYRIGHT HOLDERS BE LIABLE FOR ANY CLAIM, DAMAGES OR OTHER LIABILITY, WHETHER IN "
    "AN ACTION OF CONTRACT, TORT OR OTHERWISE, ARISING FROM, OUT OF OR IN CONNECTION WITH THE "
    "SOFTWARE OR THE USE OR OTHER DEALINGS IN THE SOFTWARE.")


def offsets_in_eye_widths(vertices: np.ndarray, faces: np.ndarray, truth68: np.ndarray,
                          tracker: FaceMeshTracker) -> np.ndarray:
    """(68, 3): truth68 (68, 3) minus each iBUG point's face-mesh vertex found on the mesh,
    along the straight view's axes, in eye widths."""
    mesh = mesh_from_arrays(vertices, faces)
    found = find_face_mesh(mesh, tracker)
    points, _ = layout_landmarks(found, get_layout("ibug68"), mesh, corrected=False)
    everywhere = found.points.positions(vertices)
    eye_width = np.linalg.norm(everywhere[EYE_CORNERS[1]] - everywhere[EYE_CORNERS[0]])
    return (truth68 - points.positions(vertices)) @ found.view.rotation.T / eye_width


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--faces", type=int, default=24)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--out", type=Path, default=OFFSETS)
    args = parser.parse_args()
    model = load_model()
    rng = np.random.default_rng(args.seed)
    tracker = FaceMeshTracker()
    measured = []
    for _ in tqdm(range(args.faces), desc="faces"):
        vertices = model.identity_face(rng.standard_normal(100))
        measured.append(offsets_in_eye_widths(vertices, model.faces, vertices[model.landmarks68], tracker))
    measured = np.asarray(measured)
    mean = measured.mean(0)
    spread = np.sqrt((np.linalg.norm(measured - mean, axis=2) ** 2).mean(0))
    args.out.write_text(json.dumps({
        "notice": ICT_NOTICE,
        "what": "offset from each iBUG-68 point's MediaPipe face-mesh vertex to the point, along the "
                "straight view's axes (image x, image y down, viewing direction), in eye widths "
                "(outer eye corner to outer eye corner); spread: RMS of the per-face offsets about it",
        "faces": args.faces, "seed": args.seed,
        "offsets": np.round(mean, 5).tolist(), "spread": np.round(spread, 5).tolist(),
    }, indent=1) + "\n")
    print(f"wrote {args.out}: mean |offset| {np.linalg.norm(mean, axis=1).mean():.4f} eye widths, "
          f"mean spread {spread.mean():.4f}")


if __name__ == "__main__":
    main()
