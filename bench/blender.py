"""Blender vs our linear blend skinning on our glTF export: the largest vertex difference.

    python bench/blender.py [--resolution 1] [--seconds 10] [--fps 30] [--samples 12]

The built-in face at --resolution with its 68 iBUG landmarks and the demo performance
(`demo_weights`) as feature displacements for --seconds at --fps, exported twice:
with an ellipsoid rig (a glTF skin: joints, JOINTS/WEIGHTS) and with the default
biharmonic rig (negative weights, so morph targets). Blender 5 (bpy, in .venv-blender,
see tests/blender/requirements.txt) imports each file with its own glTF importer and
evaluates the mesh at --samples frames spread over the take, half of them between keys
(glTF LINEAR interpolation). Printed per rig: the largest difference between Blender's
vertices and v0 + W d(t) over all samples, in mesh units and as a fraction of the
mesh's bounding-box diagonal (the issue asks for under 1e-4), and the largest motion,
so the difference reads against something.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from retarget.clips import clip_at_rate  # noqa: E402

from retarget.gltf import export_gltf  # noqa: E402
from retarget.landmarks import from_vertex_indices  # noqa: E402
from retarget.layouts import get_layout  # noqa: E402
from retarget.mesh import mesh_from_arrays  # noqa: E402
from retarget.sample_face import demo_weights, posed_vertices, sample_face  # noqa: E402
from retarget.skin import skin_displacements  # noqa: E402
from retarget.weights import compute_weights  # noqa: E402

EVALUATE = ROOT / "tests" / "blender" / "evaluate_glb.py"
BLENDER_PYTHON = ROOT / ".venv-blender" / "bin" / "python"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--resolution", type=int, default=1)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument("--samples", type=int, default=12)
    args = parser.parse_args()
    if not BLENDER_PYTHON.is_file():
        sys.exit(f"no Blender interpreter at {BLENDER_PYTHON}: python3 -m venv .venv-blender && "
                 ".venv-blender/bin/pip install -r tests/blender/requirements.txt")

    face = sample_face(args.resolution)
    mesh = mesh_from_arrays(face.vertices, face.faces, uv=face.uv, name="face")
    points = from_vertex_indices(face.landmarks68, mesh.n_vertices, "ibug68")
    n = int(round(args.seconds * args.fps))
    landmarks = posed_vertices(face, demo_weights(n, args.fps))[:, face.landmarks68]
    clip = clip_at_rate("demo", landmarks - face.vertices[face.landmarks68], args.fps)
    size = float(np.linalg.norm(np.ptp(face.vertices, axis=0)))
    keys = np.linspace(0, n - 1, args.samples // 2 + 1)[:-1].round()
    frames = np.sort(np.r_[keys, keys + 0.5, n - 1])
    print(f"face: {mesh.n_vertices} vertices, {n} frames at {args.fps:g} fps, "
          f"{len(frames)} sampled frames, size {size:.2f} (mesh units)")

    for method in ("ellipsoid", "biharmonic"):
        weights = compute_weights(method, mesh.vertices, mesh.faces, points, get_layout("ibug68"))
        with tempfile.TemporaryDirectory() as folder:
            path, out = Path(folder) / "face.glb", Path(folder) / "out.npz"
            path.write_bytes(export_gltf(mesh, points, weights, [clip], units="keep"))  # mesh units
            run = subprocess.run([str(BLENDER_PYTHON), str(EVALUATE), str(path), str(out),
                                  str(args.fps), *map(str, frames)], capture_output=True, text=True)
            if run.returncode:
                sys.exit(run.stderr[-3000:])
            with np.load(out) as z:
                positions = z["positions"]
        worst = motion = 0.0
        for frame, got in zip(frames, positions):
            i, u = int(np.floor(frame)), frame % 1.0
            d = (1 - u) * clip.displacements[i] + u * clip.displacements[min(i + 1, n - 1)]
            expected = mesh.vertices + skin_displacements(weights, d)
            worst = max(worst, float(np.abs(got - expected).max()))
            motion = max(motion, float(np.abs(expected - mesh.vertices).max()))
        kind = "skin" if method == "ellipsoid" else "morph targets"
        print(f"{method:10s} ({kind}): largest Blender - LBS difference {worst:.3g} "
              f"({worst / size:.2g} of the mesh size); largest motion {motion:.3g}")


if __name__ == "__main__":
    main()
