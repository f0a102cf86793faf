"""ARKit shapes and weights on the ICT face model: cross-identity accuracy, solve time, the
weights -> points -> retarget -> solve round trip, and ARKit weights as output (stream and
glTF export sizes).

    python bench/arkit.py [--seed 0] [--pairs 2] [--frames 300] [--noise-mm 0]
                          [--layout ibug68|ibug51|dutreve22|mediapipe468] [--rig default|NAME] [--found]
                          [--export-only] [--large-resolution 4] [--seconds 30]

The feature points on an ICT identity: for the iBUG layouts ICT's own landmark vertices;
for ``mediapipe468`` the 468 points found on the generic neutral (as in the shipped
table) carried to every identity by the shared topology, or with ``--found`` found on
each identity anew (MediaPipe's placement differences between two faces included).

1. **Shapes.** Identity A's reference motion (A's own ARKit shapes at its feature points
   and at its 468 face-mesh points; ICT is additive, so A + shape) is carried to identity
   B by `arkit_shapes` with B's rig (``default``: the shapes' own, 468 reference points
   carried onto B and an RBF rig; or a deformer's rig on the layout's points); the truth
   is B's own shape, B + the same ICT delta. Relative error per shape = sum over the face
   area (ICT vertices [0, 9409)) of the vertex error lengths / sum of the true
   displacement lengths; the mean over the 51 shapes ICT has (tongueOut has no motion),
   and the worst shapes. Target <= 25 % mean.
2. **Solve.** A smooth take of ARKit weights (a few shapes on at a time, as faces move)
   played through the shipped reference at the layout's points, retargeted onto B
   (`Retargeter`, as any take), and B's 52 weights solved per frame from the retargeted
   feature displacements (`ArkitSolver` on B's `at_points`, from the shipped reference):
   time per frame (median and 95th percentile, warm-started; wall and the thread's CPU
   time, which a loaded machine does not inflate), mean absolute weight error
   against the input weights (the round trip), and the fit's residual (relative to the
   motion); ``--noise-mm`` adds a tracker's jitter to the retargeted points first.
3. **Residual over the face.** The same take on B's whole face: the face the solved weights
   make (``sum_k w_k delta_k``, what ``export-gltf --drive arkit`` plays) against the full
   retargeted motion (the feature displacements through B's rig on the layout's points,
   ``retarget.weights.DEFAULT_METHOD``: what ``--drive points`` plays), relative (sum over the
   face area of the vertex error lengths / sum of the retargeted motion's lengths); and both
   against the truth, B making the take's expressions with its own ICT shapes.
4. **Output sizes.** A stream frame of 52 weights (float32 after the stream's 32-byte frame
   header, `server/wire.py`) against one of the layout's points; the ARKit glTF export of a
   take (``--seconds`` at 30 fps) on the sample face and on the sample face at
   ``--large-resolution`` (4: 132,907 vertices), its targets sparse
   (`retarget.gltf.arkit.TOLERANCE`) against dense, and what the tolerance costs: the largest
   target error and the largest posed-vertex error over the take, relative to the face size.
Sections 1-3 need ../shared/data/ict_face (without it, section 3 runs on the sample face
driven by another identity's ARKit take, with the shapes' own rig); ``--export-only`` runs 4.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.arkit_reference import arkit_deltas  # noqa: E402
from bench.ict import DATA, load_model  # noqa: E402
from retarget.arkit.clip import ArkitClip  # noqa: E402
from retarget.arkit.reference import ARKIT_NAMES, ArkitReference, arkit_reference  # noqa: E402
from retarget.arkit.shapes import arkit_shapes  # noqa: E402
from retarget.arkit.solve import ANTAGONISTS, ArkitSolver  # noqa: E402
from retarget.facemesh.placement import find_face_mesh  # noqa: E402
from retarget.gltf.arkit import TOLERANCE, arkit_tolerance, export_arkit_gltf  # noqa: E402
from retarget.gltf.animation import mesh_instances  # noqa: E402
from retarget.gltf.document import GltfDocument  # noqa: E402
from retarget.gltf.sparse import index_type, kept_rows, sparse_is_smaller  # noqa: E402
from retarget.landmarks import SurfacePoints, from_vertex_indices  # noqa: E402
from retarget.layouts import get_layout  # noqa: E402
from retarget.mesh import mesh_from_arrays  # noqa: E402
from retarget.pipeline import Retargeter  # noqa: E402
from retarget.sample_face import sample_face  # noqa: E402
from retarget.skin import skin_displacements  # noqa: E402
from retarget.weights import DEFAULT_METHOD, METHODS, compute_weights  # noqa: E402

STREAM_HEADER_BYTES = 32  # the stream's frame header (server/wire.py)


def smooth_take(n_frames: int, rng: np.random.Generator, fps: float = 60.0) -> np.ndarray:
    """(F, 52) weights in [0, 1]: raised-cosine pulses of 0.3-1.2 s, about three shapes on at
    a time, symmetric pairs mostly together, antagonists never together; tongueOut 0."""
    t = np.arange(n_frames) / fps
    w = np.zeros((n_frames, len(ARKIT_NAMES)))
    index = {n: i for i, n in enumerate(ARKIT_NAMES)}
    opposite = {pair for a, b in ANTAGONISTS for pair in ((index[a], index[b]), (index[b], index[a]))}
    start = 0.0
    while start < t[-1]:
        k = int(rng.integers(len(ARKIT_NAMES) - 1))
        width, peak = rng.uniform(0.3, 1.2), rng.uniform(0.3, 1.0)
        centre = start + width
        bump = 0.5 + 0.5 * np.cos(np.pi * (t - centre) / width)
        pulse = peak * np.where(np.abs(t - centre) < width, bump, 0)
        span = pulse > 0
        if not any(w[span, j].any() for (i, j) in opposite if i == k):
            w[:, k] = np.maximum(w[:, k], pulse)
            name = ARKIT_NAMES[k]
            if name.endswith(("Left", "Right")) and rng.random() < 0.7 and name not in (
                    "jawLeft", "jawRight", "mouthLeft", "mouthRight"):
                twin = index[name[:-4] + "Right"] if name.endswith("Left") else index[name[:-5] + "Left"]
                w[:, twin] = np.maximum(w[:, twin], pulse)
        start += rng.uniform(0.1, 0.4)
    return np.clip(w, 0.0, 1.0)


def face_residuals(vertices, faces, points, layout, displacements, solved, shapes, truth=None,
                   area: int | None = None, chunk: int = 32) -> dict:
    """Relative residuals over the face area (vertices [0, area)) of a take on one face:
    ``arkit`` the face the solved weights make, (F, 52) `solved` through `shapes.deltas`,
    against ``points`` the full retargeted motion, (F, N, 3) `displacements` through the
    face's `DEFAULT_METHOD` rig on its feature points; and, given ``truth`` (F, 52) weights of
    (52, V, 3) true shapes as (weights, deltas), both against it. Each is sum of vertex error
    lengths / sum of the reference's motion lengths."""
    rig = compute_weights(DEFAULT_METHOD, vertices, faces, points, layout)
    area = len(vertices) if area is None else area
    sums = {"arkit-points": 0.0, "points": 0.0, "arkit-truth": 0.0, "points-truth": 0.0, "truth": 0.0}
    for i in range(0, len(solved), chunk):
        played = skin_displacements(rig, displacements[i:i + chunk])[:, :area]
        made = np.tensordot(solved[i:i + chunk], shapes.deltas[:, :area], axes=1)
        sums["arkit-points"] += np.linalg.norm(made - played, axis=2).sum()
        sums["points"] += np.linalg.norm(played, axis=2).sum()
        if truth is not None:
            true = np.tensordot(truth[0][i:i + chunk], truth[1][:, :area], axes=1)
            sums["arkit-truth"] += np.linalg.norm(made - true, axis=2).sum()
            sums["points-truth"] += np.linalg.norm(played - true, axis=2).sum()
            sums["truth"] += np.linalg.norm(true, axis=2).sum()
    out = {"arkit vs points": sums["arkit-points"] / sums["points"]}
    if truth is not None:
        out["arkit vs truth"] = sums["arkit-truth"] / sums["truth"]
        out["points vs truth"] = sums["points-truth"] / sums["truth"]
    return out


def sample_face_residual(args) -> None:
    """Section 3 without ICT: the sample face driven by an ARKit take through the shipped
    reference (another identity), solved with the shapes' own rig."""
    rng = np.random.default_rng(args.seed)
    f = sample_face()
    points = from_vertex_indices(f.landmarks68, len(f.vertices), "ibug68")
    shapes = arkit_shapes(f.vertices, f.faces, points, "ibug68")
    weights = smooth_take(args.frames, rng)
    ref = arkit_reference("ibug68")
    d = Retargeter().fit(ref.neutral, points.positions(f.vertices)).displacements(ref.points(weights))
    solved = ArkitSolver(shapes.at_points).solve_frames(d)
    r = face_residuals(f.vertices, f.faces, points, get_layout("ibug68"), d, solved, shapes)
    print(f"residual over the face (sample face, {args.frames} frames): the ARKit face is "
          f"{100 * r['arkit vs points']:.1f} % off the full retargeted motion ({DEFAULT_METHOD} rig)")


def export_sizes(resolution: int, seconds: float, rng: np.random.Generator, fps: float = 30.0) -> None:
    """Section 4 for the sample face at `resolution`: the export of a take, sparse and dense."""
    f = sample_face(resolution)
    points = from_vertex_indices(f.landmarks68, len(f.vertices), "ibug68")
    t0 = time.perf_counter()
    shapes = arkit_shapes(f.vertices, f.faces, points, "ibug68")
    shapes_s = time.perf_counter() - t0
    weights = smooth_take(int(round(seconds * fps)), rng, fps)
    mesh = mesh_from_arrays(f.vertices, f.faces, uv=f.uv)
    t0 = time.perf_counter()
    data = export_arkit_gltf(mesh, shapes, [ArkitClip.at_rate("take", weights, fps)],
                             units="keep")  # the errors below in mesh units
    export_s = time.perf_counter() - t0
    gltf = GltfDocument(data, "arkit.glb", None)
    doc = gltf.doc
    accessors = [doc.accessors[t["POSITION"]] for t in doc.meshes[0].primitives[0].targets]
    views = {a.bufferView for a in accessors if a.bufferView is not None}
    views |= {v for a in accessors if a.sparse is not None
              for v in (a.sparse.indices.bufferView, a.sparse.values.bufferView)}
    target_bytes = sum(doc.bufferViews[v].byteLength for v in views)
    v = mesh.n_vertices
    dense = len(data) - target_bytes + 52 * v * 12
    rows = sum(a.sparse.count if a.sparse is not None else (a.count if a.bufferView is not None else 0)
               for a in accessors)
    (instance,) = mesh_instances(gltf)
    error = instance["targets"] - shapes.deltas                       # (52, V, 3) what was dropped
    size = float(np.linalg.norm(np.ptp(f.vertices, axis=0)))
    frames = weights[::10]                                            # every 10th frame of the take
    posed = max(float(np.linalg.norm(np.tensordot(w, error, axes=1), axis=1).max()) for w in frames)
    print(f"sample face x{resolution} ({v:,} vertices; shapes {shapes_s:.1f} s): {seconds:g} s take at "
          f"{fps:g} fps -> sparse {len(data) / 2**20:.1f} MiB, dense {dense / 2**20:.1f} MiB "
          f"({100 * len(data) / dense:.0f} %; the 52 dense targets alone {52 * v * 12 / 2**20:.1f} MiB), "
          f"export {export_s:.1f} s; {100 * rows / (52 * v):.1f} % of target rows kept; tolerance "
          f"{TOLERANCE:g} of the size ({arkit_tolerance(f.vertices):.4f} cm): largest target error "
          f"{np.linalg.norm(error, axis=2).max() / size:.1e}, largest posed-vertex error over the take "
          f"{posed / size:.1e} of the face size ({10 * posed:.3f} mm)")
    # what other tolerances would give (the targets' bytes as `target_accessor` chooses them)
    index_bytes = index_type(v).itemsize
    sweep = []
    for share in (0.0, 1e-4, 3e-4, 1e-3):
        kept = [len(kept_rows(delta, share * size)) for delta in shapes.deltas]
        n_bytes = sum(k * (12 + index_bytes) if sparse_is_smaller(k, v) else 12 * v for k in kept)
        sweep.append(f"{share:g}: {n_bytes / 2**20:.1f} MiB")
    print("  the 52 targets by tolerance (share of the face size): " + ", ".join(sweep))


def output_sizes(args) -> None:
    """Section 4 (module docstring)."""
    n = get_layout(args.layout).n_points
    print(f"stream frame: 52 weights = 52 x 4 + {STREAM_HEADER_BYTES} = {52 * 4 + STREAM_HEADER_BYTES} "
          f"bytes ({(52 * 4 + STREAM_HEADER_BYTES) * 30 / 1000:.1f} kB/s at 30 fps), against "
          f"{n * 12 + STREAM_HEADER_BYTES} bytes for {args.layout}'s {n} points")
    rng = np.random.default_rng(args.seed)
    for resolution in (1, args.large_resolution):
        export_sizes(resolution, args.seconds, rng)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--pairs", type=int, default=2, help="identity pairs (A, B)")
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--noise-mm", type=float, default=0.0,
                        help="Gaussian noise added to every retargeted point coordinate (tracker jitter)")
    parser.add_argument("--layout", default="ibug68",
                        choices=("ibug68", "ibug51", "dutreve22", "mediapipe468"))
    parser.add_argument("--rig", default="default", choices=["default", *METHODS],
                        help="B's rig: the shapes' default (468 reference points carried onto B, an RBF "
                        "rig) or a deformer's rig on the layout's points")
    parser.add_argument("--found", action="store_true", help="mediapipe468: find the points on A and "
                        "on B each (MediaPipe's placement noise included) instead of the generic face's "
                        "placement carried by the shared topology to both")
    parser.add_argument("--export-only", action="store_true", help="section 4 only (no ICT needed)")
    parser.add_argument("--large-resolution", type=int, default=4,
                        help="the sample face's resolution for the large export (4: 132,907 vertices)")
    parser.add_argument("--seconds", type=float, default=30.0, help="the exported take's length")
    args = parser.parse_args()
    if not args.export_only:
        if DATA.exists():
            ict_figures(args)
        else:
            print(f"no ICT data at {DATA}: sections 1-2 skipped, section 3 on the sample face")
            sample_face_residual(args)
    output_sizes(args)


def ict_figures(args) -> None:
    """Sections 1-3 (module docstring)."""
    model = load_model()
    layout = get_layout(args.layout)
    deltas = arkit_deltas(model)                                   # (52, V, 3) cm
    moving = np.any(deltas != 0, axis=(1, 2))
    face = model.face_count
    dense = layout.name == "mediapipe468"
    generic = find_face_mesh(mesh_from_arrays(model.neutral, model.faces)).points
    rng = np.random.default_rng(args.seed)
    errors, solve_ms, round_trip, residual, over_face = [], [], [], [], []
    for pair in range(args.pairs):
        a = model.identity_face(rng.standard_normal(100))
        b = model.identity_face(rng.standard_normal(100))
        if not dense:  # ICT's own landmark vertices, the same anatomy on every identity
            landmarks = model.landmarks68[list(layout.ibug68)]
            points_a = points = from_vertex_indices(landmarks, len(b), layout.name)
        elif args.found:
            points_a, points = (find_face_mesh(mesh_from_arrays(x, model.faces)).points for x in (a, b))
        else:
            points_a = points = generic
        points = SurfacePoints(points.vertex_indices, points.barycentric, layout.name)
        rig = None if args.rig == "default" else compute_weights(args.rig, b, model.faces, points, layout)
        reference = ArkitReference(layout.name, points_a.positions(a), points_a.positions(deltas))
        dense_a = ArkitReference("mediapipe468", generic.positions(a), generic.positions(deltas))
        shapes = arkit_shapes(b, model.faces, points, layout, rig, reference=reference,
                              dense_reference=dense_a)
        err = np.linalg.norm(shapes.deltas[:, :face] - deltas[:, :face], axis=2).sum(1)
        true = np.linalg.norm(deltas[:, :face], axis=2).sum(1)
        errors.append(err / np.maximum(true, 1e-12))

        # the round trip: a take through the shipped reference, retargeted onto B, solved
        # against B's shapes from the shipped reference
        shipped = arkit_shapes(b, model.faces, points, layout, rig)
        weights = smooth_take(args.frames, rng)
        ref = arkit_reference(layout)
        retargeter = Retargeter().fit(ref.neutral, points.positions(b))
        displacements = retargeter.displacements(ref.points(weights))
        displacements = displacements + rng.normal(0.0, args.noise_mm / 10.0, displacements.shape)
        solver = ArkitSolver(shipped.at_points)
        solved = np.empty_like(weights)
        for f, d in enumerate(displacements):
            t0, c0 = time.perf_counter(), time.thread_time()
            solved[f] = solver.solve(d)
            solve_ms.append((1e3 * (time.perf_counter() - t0), 1e3 * (time.thread_time() - c0)))
        round_trip.append(np.abs(solved - weights)[:, moving].mean())
        fit = np.tensordot(solved, shipped.at_points, axes=1)
        residual.append(np.linalg.norm(fit - displacements) / np.linalg.norm(displacements))
        over_face.append(face_residuals(b, model.faces, points, layout, displacements, solved, shipped,
                                        (weights, deltas), face))
        print(f"pair {pair}: shapes mean {100 * errors[-1][moving].mean():.1f} %, round trip |dw| "
              f"{round_trip[-1]:.4f}, residual {100 * residual[-1]:.2f} %, over the face "
              + ", ".join(f"{k} {100 * v:.1f} %" for k, v in over_face[-1].items()), flush=True)
    per_shape = np.where(moving, np.mean(errors, axis=0), np.nan)
    order = np.argsort(-np.nan_to_num(per_shape, nan=-1))
    print(f"\nlayout {layout.name} ({layout.n_points} points), {args.pairs} identity pairs, "
          f"seed {args.seed}, "
          f"rig {args.rig}" + (", points found on each identity" if args.found else "")
          + (f", {args.noise_mm} mm noise" if args.noise_mm else ""))
    print(f"shapes A -> B: mean relative error {100 * np.nanmean(per_shape):.1f} % over the "
          f"{int(moving.sum())} shapes ICT has (target <= 25 %), median "
          f"{100 * np.nanmedian(per_shape):.1f} %")
    print("worst: " + ", ".join(f"{ARKIT_NAMES[k]} {100 * per_shape[k]:.0f} %" for k in order[:8]))
    best = order[moving.sum() - 5:moving.sum()]
    print("best: " + ", ".join(f"{ARKIT_NAMES[k]} {100 * per_shape[k]:.0f} %" for k in best))
    # wall time counts the other processes of a shared machine; the thread's CPU time not
    wall, cpu = np.asarray(solve_ms).T
    print(f"solve a frame (target < 0.5 ms), {len(wall)} frames: wall median {np.median(wall):.3f} ms, "
          f"p95 {np.percentile(wall, 95):.3f} ms, max {wall.max():.2f} ms; CPU median "
          f"{np.median(cpu):.3f} ms, p95 {np.percentile(cpu, 95):.3f} ms, max {cpu.max():.2f} ms")
    print(f"round trip (weights -> points -> retarget -> solve): mean |weight error| "
          f"{np.mean(round_trip):.4f}; "
          f"fit residual {100 * np.mean(residual):.2f} % of the motion")
    print(f"residual over the face (ICT face area, {args.pairs} pairs): the ARKit face is "
          f"{100 * np.mean([r['arkit vs points'] for r in over_face]):.1f} % off the full retargeted "
          f"motion ({DEFAULT_METHOD} rig on the {layout.n_points} points); against B's own shapes: ARKit "
          f"{100 * np.mean([r['arkit vs truth'] for r in over_face]):.1f} %, points "
          f"{100 * np.mean([r['points vs truth'] for r in over_face]):.1f} %")


if __name__ == "__main__":
    main()
