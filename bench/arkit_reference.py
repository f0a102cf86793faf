"""Make the ARKit reference table (`retarget/arkit/reference.npz`) from the ICT face model.

    python bench/arkit_reference.py [--out PATH]

For each of ARKit's 52 shapes (`retarget.arkit.reference.ARKIT_NAMES`; the ICT shapes each
is made of: `ICT_SOURCES`), the motion at weight 1 of the ICT generic neutral face at
(1) ICT's 68 iBUG landmark vertices and (2) MediaPipe's 468 face-mesh points found on the
neutral with no clicks (`find_face_mesh`, as the app finds a user's points), and the
neutral points themselves. The motion is stored as float16 (at most 0.01 mm off at the
largest motion, 4.2 cm), the neutrals as float32, cm; about 0.2 MB. Needs
../shared/data/ict_face; the table carries the ICT-FaceKit MIT notice (it is derived from
the model), written into the file and into ``retarget/arkit/NOTICE``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from bench.ict import load_model  # noqa: E402
from bench.landmark_offsets import ICT_NOTICE  # noqa: E402
from retarget.arkit.reference import ARKIT_NAMES, ICT_SOURCES, REFERENCE  # noqa: E402
from retarget.facemesh.placement import find_face_mesh  # noqa: E402
from retarget.mesh import mesh_from_arrays  # noqa: E402

NOTICE = REFERENCE.parent / "NOTICE"


def arkit_deltas(model) -> np.ndarray:
    """(52, V, 3) float64 cm: each ARKit shape's vertex deltas on the ICT model (the sum of
    its ICT shapes; zero for tongueOut)."""
    index = {n: i for i, n in enumerate(model.names)}
    out = np.zeros((len(ARKIT_NAMES), *model.neutral.shape))
    for k, name in enumerate(ARKIT_NAMES):
        for source in ICT_SOURCES[name]:
            out[k] += model.expressions[index[source]]
    return out


def check_sides(model, deltas: np.ndarray) -> None:
    """Refuse a table whose Left shapes do not act on the subject's left (+x): ARKit's
    convention, which the ICT `_L` suffix is taken to follow."""
    for k, name in enumerate(ARKIT_NAMES):
        if name.endswith("Left") and not name.startswith(("jaw", "mouthLeft")):
            size = np.linalg.norm(deltas[k], axis=1)
            x = (size * model.neutral[:, 0]).sum() / size.sum()
            if x <= 0:
                raise SystemExit(f"{name} moves the subject's right side (motion centre x = {x:.2f} cm)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REFERENCE)
    args = parser.parse_args()
    model = load_model()
    deltas = arkit_deltas(model)
    check_sides(model, deltas)
    landmarks = model.landmarks68
    found = find_face_mesh(mesh_from_arrays(model.neutral, model.faces))
    dense = found.points
    tables = {
        "ibug68_neutral": model.neutral[landmarks].astype(np.float32),
        "ibug68_motion": deltas[:, landmarks].astype(np.float16),
        "mediapipe468_neutral": dense.positions(model.neutral).astype(np.float32),
        "mediapipe468_motion": dense.positions(deltas).astype(np.float16),
    }
    np.savez_compressed(
        args.out, names=np.array(ARKIT_NAMES), notice=np.array(ICT_NOTICE.replace(
            "bench/landmark_offsets.py", "bench/arkit_reference.py")),
        ict_sources=np.array(["+".join(ICT_SOURCES[n]) for n in ARKIT_NAMES]),
        units=np.array("cm; +y up, +z out of the face, +x toward the subject's left"),
        facemesh_confidence=found.confidence.astype(np.float32), **tables)
    NOTICE.write_text(
        "retarget/arkit/reference.npz is derived from the ICT Face Model (ICT-FaceKit,\n"
        "https://github.com/ICT-VGL/ICT-FaceKit) by bench/arkit_reference.py.\n\n"
        + _MIT)
    worst = float(np.abs(tables["ibug68_motion"].astype(np.float64) - deltas[:, landmarks]).max())
    print(f"wrote {args.out} ({args.out.stat().st_size / 1024:.0f} KB): 52 shapes at 68 iBUG and 468 "
          f"face-mesh points; float16 rounding at most {10 * worst:.4f} mm; face mesh presence "
          f"{found.presence:.2f}, {int((found.confidence < 0.6).sum())} points under 0.6 confidence")


_MIT = """MIT License

Copyright (c) 2020 USC Institute for Creative Technologies

Permission is hereby granted, free of charge, to any person obtaining a copy
of this software and associated documentation files (the "Software"), to deal
in the Software without restriction, including without limitation the rights
to use, copy, modify, merge, publish, distribute, sublicense, and/or sell
copies of the Software, and to permit persons to whom the Software is
furnished to do so, subject to the following conditions:

The above copyright notice and this permission notice shall be included in all
copies or substantial portions of the Software.

THE SOFTWARE IS PROVIDED "AS IS", WITHOUT WARRANTY OF ANY KIND, EXPRESS OR
IMPLIED, INCLUDING BUT NOT LIMITED TO THE WARRANTIES OF MERCHANTABILITY,
FITNESS FOR A PARTICULAR PURPOSE AND NONINFRINGEMENT. IN NO EVENT SHALL THE
AUTHORS OR COPYRIGHT HOLDERS BE LIABLE FOR ANY CLAIM, DAMAGES OR OTHER
LIABILITY, WHETHER IN AN ACTION OF CONTRACT, TORT OR OTHERWISE, ARISING FROM,
OUT OF OR IN CONNECTION WITH THE SOFTWARE OR THE USE OR OTHER DEALINGS IN THE
SOFTWARE.
"""


if __name__ == "__main__":
    main()
