"""Reading a glTF export back: pygltflib's own JSON decoding against retarget.gltf.decode.

    python bench/gltf_read.py [--resolution 1] [--rig rbf] [--seconds 2] [--repeats 7]

The built-in procedural face at --resolution (1: 8,430 vertices) with its 68 iBUG
landmarks, a --rig of weights (rbf: dense, so one morph target per joint and axis) and
a take of --seconds of its demo performance at 30 fps, exported with
`retarget.gltf.export_gltf`. Then, alternated so that other load on the machine hits
both alike, median wall and CPU seconds of:

    decode   the .glb into a `pygltflib.GLTF2`: pygltflib's `GLTF2.load_from_bytes`
             (dataclasses_json) and `retarget.gltf.decode.gltf_from_glb`
    read     `retarget.gltf.read_gltf` of the bytes (mesh, rig, clips), its document
             decoded each way

Progress on stderr; figures on stdout.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path
from unittest import mock

import numpy as np
import pygltflib

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.stream import machine  # noqa: E402
from retarget.clips import clip_at_rate  # noqa: E402
from retarget.gltf import decode, export_gltf, read_gltf  # noqa: E402
from retarget.landmarks import from_vertex_indices  # noqa: E402
from retarget.layouts import get_layout  # noqa: E402
from retarget.mesh import mesh_from_arrays  # noqa: E402
from retarget.sample_face import demo_weights, sample_face  # noqa: E402
from retarget.weights import compute_weights  # noqa: E402


def exported(resolution: int, rig: str, seconds: float) -> bytes:
    """The .glb of the sample face with a `rig` and `seconds` of its demo performance."""
    face = sample_face(resolution)
    mesh = mesh_from_arrays(face.vertices, face.faces, uv=face.uv, name="sample_face")
    points = from_vertex_indices(face.landmarks68, mesh.n_vertices, "ibug68")
    fps = 30.0
    expression = demo_weights(int(round(seconds * fps)), fps)
    motion = np.tensordot(expression, face.expressions[:, face.landmarks68], axes=(1, 0))
    clip = clip_at_rate("demo", motion.astype(np.float32), fps)
    weights = compute_weights(rig, mesh.vertices, mesh.faces, points, get_layout("ibug68"))
    return export_gltf(mesh, points, weights, [clip])


def pygltflib_glb(data: bytes):
    """pygltflib's own decoding, its warnings on odd chunks silenced as GltfDocument does."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return pygltflib.GLTF2.load_from_bytes(data)


def read_with_pygltflib(data: bytes):
    """`read_gltf` as it was before retarget.gltf.decode: pygltflib decoding the JSON."""
    with mock.patch.object(decode, "gltf_from_glb", pygltflib_glb):
        return read_gltf(data)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--resolution", type=int, default=1)
    parser.add_argument("--rig", default="rbf")
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()

    print("export...", file=sys.stderr, flush=True)
    data = exported(args.resolution, args.rig, args.seconds)
    doc = decode.gltf_from_glb(data)
    print(f"# {machine()}")
    print(f"{args.rig} export of the sample face at resolution {args.resolution}: "
          f"{len(data) / 2**20:.1f} MiB, {len(doc.accessors)} accessors, "
          f"{len(doc.meshes[0].primitives[0].targets or [])} morph targets; "
          f"median of {args.repeats}, alternated")
    timings = {}
    for _ in range(args.repeats):
        for name, fn in (("decode pygltflib", pygltflib_glb), ("decode ours", decode.gltf_from_glb),
                         ("read pygltflib", read_with_pygltflib), ("read ours", read_gltf)):
            start, start_cpu = time.perf_counter(), time.process_time()
            fn(data)
            timings.setdefault(name, []).append((time.perf_counter() - start,
                                                 time.process_time() - start_cpu))
    print(f"{'':<18} {'wall s':>8} {'cpu s':>8}")
    for name, rows in timings.items():
        wall, cpu = np.median(np.array(rows), axis=0)
        print(f"{name:<18} {wall:>8.3f} {cpu:>8.3f}")


if __name__ == "__main__":
    main()
