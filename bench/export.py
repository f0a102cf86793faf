"""glTF export: time and file size for a large face with a long take.

    python bench/export.py [--resolution 4] [--seconds 30] [--fps 30] [--repeats 3]
                           [--rigs ellipsoid rbf] [--forms exact skin]
                           [--rate 24] [--key-tolerance MM]

The built-in procedural face at --resolution (4: 132,907 vertices, the smallest grid at
or above 100k; see bench/upload.py) with uv, its 68 iBUG landmarks, and a take of
--seconds at --fps: the face's own demo performance (`demo_weights`) at the landmarks,
as feature displacements (no retargeting is timed). For each rig (ellipsoid: a glTF skin;
rbf: dense with negative weights, so morph targets), after computing the weights (timed
apart), in each --forms (exact: the rig as it is; skin: any rig as a four-influence
skin, `retarget.weights.skin_fit`), its keys at --rate and reduced to --key-tolerance
(`retarget.gltf.keys`):

    export   retarget.gltf.export_gltf, to bytes in memory: wall and CPU seconds
    read     retarget.gltf.read_gltf of those bytes: wall and CPU seconds
    size     the .glb in MiB, split into mesh (positions, uv, triangles), rig (JOINTS /
             WEIGHTS and inverse bind matrices, or morph targets) and animation (key
             times, joint translations, morph weights)
    fit      for the skin form: the fit's RMS error relative to the vertex motion, in mm,
             and the RMS error of the worst vertex in mm (the face is taken in centimetres)

Times are medians over --repeats. Progress on stderr; figures on stdout.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.stream import machine  # noqa: E402
from retarget.clips import clip_at_rate  # noqa: E402
from retarget.gltf import export_gltf, read_gltf  # noqa: E402
from retarget.gltf.document import GltfDocument  # noqa: E402
from retarget.landmarks import from_vertex_indices  # noqa: E402
from retarget.layouts import get_layout  # noqa: E402
from retarget.mesh import mesh_from_arrays  # noqa: E402
from retarget.sample_face import demo_weights, sample_face  # noqa: E402
from retarget.weights import compute_weights  # noqa: E402


def median_seconds(fn, repeats: int):
    """(median wall seconds, median CPU seconds of this process, the last result) of fn()
    over `repeats` calls: on a shared machine the CPU time is the steadier figure."""
    wall, cpu, result = [], [], None
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        result = fn()
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return float(np.median(wall)), float(np.median(cpu)), result


def byte_split(data: bytes) -> dict[str, int]:
    """Bytes of the BIN chunk by what they hold: mesh, rig, animation."""
    doc = GltfDocument(data, "the export", None).doc
    owner = {}
    primitive = doc.meshes[0].primitives[0]
    for name, accessor in vars(primitive.attributes).items():
        if accessor is not None:
            owner[accessor] = "rig" if name.startswith(("JOINTS_", "WEIGHTS_")) else "mesh"
    owner[primitive.indices] = "mesh"
    for target in primitive.targets or []:
        owner[target["POSITION"]] = "rig"
    for skin in doc.skins or []:
        owner[skin.inverseBindMatrices] = "rig"
    for animation in doc.animations or []:
        for sampler in animation.samplers:
            owner[sampler.input] = owner[sampler.output] = "animation"
    views: dict[int, str] = {}
    for index, part in owner.items():
        accessor = doc.accessors[index]
        used = [accessor.bufferView]
        if accessor.sparse is not None:
            used += [accessor.sparse.indices.bufferView, accessor.sparse.values.bufferView]
        views.update({v: part for v in used if v is not None})
    split = {"mesh": 0, "rig": 0, "animation": 0}
    for view, part in views.items():
        split[part] += doc.bufferViews[view].byteLength
    return split


def fit_summary(data: bytes) -> str:
    """The skin fit's error as the file records it (``extras.retarget.fit``), or "-"."""
    fit = GltfDocument(data, "the export", None).doc.scenes[0].extras["retarget"].get("fit")
    if not fit or "rms_relative" not in fit:
        return "-"
    return (f"{100 * fit['rms_relative']:.1f} % rms ({fit['rms_mm']:.3f} mm), worst vertex "
            f"{fit['worst_vertex_mm']:.2f} mm rms")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--resolution", type=int, default=4)
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--rigs", nargs="+", default=["ellipsoid", "rbf"])
    parser.add_argument("--forms", nargs="+", default=["exact"], choices=["exact", "skin"])
    parser.add_argument("--rate", type=float, default=None, help="animation rate (24, 25, 30, 60)")
    parser.add_argument("--key-tolerance", type=float, default=0.0, help="key reduction, mm")
    args = parser.parse_args()

    face = sample_face(args.resolution)
    mesh = mesh_from_arrays(face.vertices, face.faces, uv=face.uv, name="sample_face")
    points = from_vertex_indices(face.landmarks68, mesh.n_vertices, "ibug68")
    n_frames = int(round(args.seconds * args.fps))
    expression = demo_weights(n_frames, args.fps)
    motion = np.tensordot(expression, face.expressions[:, face.landmarks68], axes=(1, 0))
    clip = clip_at_rate("demo", motion.astype(np.float32), args.fps)
    print(f"# {machine()}")
    print(f"face: {mesh.n_vertices} vertices, {mesh.n_faces} triangles, uv; "
          f"{points.n_points} joints; take: {n_frames} frames at {args.fps:g} fps "
          f"({args.seconds:g} s); median of {args.repeats}; keys at "
          f"{'the take' if args.rate is None else f'{args.rate:g} fps'}, tolerance {args.key_tolerance:g} mm")
    print(f"{'rig':<10} {'form':<5} {'kind':<6} {'weights s':>9} {'export s':>9} {'cpu s':>6} "
          f"{'read s':>7} {'cpu s':>6} {'MiB':>7} {'mesh':>6} {'rig':>6} {'anim':>6}  fit")
    for method in args.rigs:
        print(f"{method} weights...", file=sys.stderr, flush=True)
        start = time.perf_counter()
        weights = compute_weights(method, mesh.vertices, mesh.faces, points, get_layout("ibug68"))
        weights_seconds = time.perf_counter() - start
        for form in args.forms:
            print(f"{method} {form} export...", file=sys.stderr, flush=True)
            options = {"form": form, "rate": args.rate, "key_tolerance": args.key_tolerance,
                       "mesh_units": "cm"}
            export_seconds, export_cpu, data = median_seconds(
                lambda: export_gltf(mesh, points, weights, [clip], **options), args.repeats)
            print(f"{method} {form} read...", file=sys.stderr, flush=True)
            read_seconds, read_cpu, back = median_seconds(lambda: read_gltf(data), args.repeats)
            split = byte_split(data)
            mib = 2.0**20
            print(f"{method:<10} {form:<5} {back.deformation:<6} {weights_seconds:>9.2f} "
                  f"{export_seconds:>9.2f} {export_cpu:>6.2f} {read_seconds:>7.2f} {read_cpu:>6.2f} "
                  f"{len(data) / mib:>7.1f} {split['mesh'] / mib:>6.1f} {split['rig'] / mib:>6.1f} "
                  f"{split['animation'] / mib:>6.1f}  {fit_summary(data)}", flush=True)


if __name__ == "__main__":
    main()
