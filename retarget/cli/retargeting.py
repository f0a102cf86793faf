"""``retarget transfer``, ``rig``, ``export-gltf`` and ``demo``: a target mesh rigged and
driven by a source's feature points (Dutreve et al. 2008), from files (`retarget.files`)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from retarget.errors import RetargetError
from retarget.files import (DRIVES, computed_weights, export_gltf_files, layout_for, read_landmarks,
                            read_mesh, require_parent, transfer_files, write_file, write_json,
                            write_npy)
from retarget.gltf.keys import RATES
from retarget.gltf.writer import FORMS
from retarget.units import EXPORT_UNITS, UNITS
from retarget.cli.parser import PROG, layout_option, non_negative_float, positive_float, positive_int
from retarget.mesh import mesh_from_arrays, save_mesh
from retarget.pipeline import DEFAULT_KERNEL, DEFAULT_SMOOTHING
from retarget.rbf import KERNELS
from retarget.weights import DEFAULT_METHOD, METHODS

__all__ = ["add_demo", "add_export_gltf", "add_rig", "add_transfer"]

DEMO_FRAMES = 90
DEMO_DIR = "retarget-demo"
_METHODS, _KERNELS = ", ".join(METHODS), ", ".join(KERNELS)


# ---------------------------------------------------------------------------------------
# transfer


def add_transfer(commands, parents) -> None:
    p = commands.add_parser(
        "transfer", parents=parents, help="retarget source frames onto a target mesh",
        description="Retarget source feature-point frames onto a target mesh and write the "
        "deformed vertices, (F, V, 3) float32, as .npy.")
    p.add_argument("--target-mesh", required=True, metavar="MESH",
                   help="target mesh (obj, ply, stl, off, gltf, glb)")
    p.add_argument("--target-landmarks", required=True, metavar="T0.json",
                   help='its N landmarks: {"vertex_indices": [...]} or {"positions": '
                   '[[x, y, z], ...]}, optionally with "layout"')
    p.add_argument("--source-neutral", required=True, metavar="S0.npy",
                   help="(N, 2|3) neutral source points")
    p.add_argument("--source-frames", required=True, metavar="S.npy",
                   help="(F, N, 2|3) source points per frame, in S0's order; NaN = lost point")
    p.add_argument("--out", required=True, metavar="OUT.npy",
                   help="(F, V, 3) float32 deformed target vertices, written here")
    weights = p.add_mutually_exclusive_group()
    weights.add_argument("--deformer", choices=list(METHODS), default=None, metavar="NAME",
                         help=f"one of {_METHODS} (default: {DEFAULT_METHOD})")
    weights.add_argument("--rig", metavar="RIG.npz",
                         help="skin weights from 'retarget rig', instead of computing them")
    p.add_argument("--kernel", choices=list(KERNELS), default=DEFAULT_KERNEL, metavar="NAME",
                   help=f"RBF space-transform kernel: one of {_KERNELS} (default: {DEFAULT_KERNEL})")
    p.add_argument("--smoothing", type=non_negative_float, default=None, metavar="X",
                   help="space-transform smoothing, relative (default: "
                   + ", ".join(f"{v:g} for {d}D sources" for d, v in DEFAULT_SMOOTHING.items()) + ")")
    p.add_argument("--mask", nargs="+", action="extend", metavar="NAME",
                   help="partial retargeting: move only these regions, groups, point names "
                   "or feature indices (their union); names need a layout")
    layout_option(p)
    p.add_argument("--drive", choices=list(DRIVES), default="points",
                   help="points: feature points as skinning joints (default); muscles: their motion "
                   "solved into the 21 muscles' contractions and the jaw (Woodward et al.), no rig; "
                   "arkit: solved into ARKit's 52 blendshape weights and made by the shapes")
    p.add_argument("--muscles", metavar="MUSCLES.json",
                   help="with --drive muscles: muscles from 'retarget muscles' (default: placed from "
                   "the landmarks)")
    p.add_argument("--contractions-out", metavar="C.npy",
                   help="with --drive muscles: the (F, 22) contractions, written here (for "
                   "'retarget recognise')")
    _arkit_options(p, "the (F, 52) weights written here as Live Link Face CSV (timecodes at 30 fps)")
    p.set_defaults(run=_transfer)


def _transfer(args) -> int:
    _refuse_other_rigs(args)
    result = transfer_files(
        args.target_mesh,
        args.target_landmarks,
        args.source_neutral,
        args.source_frames,
        args.out,
        deformer=args.deformer or DEFAULT_METHOD,
        kernel=args.kernel,
        smoothing=args.smoothing,
        mask=args.mask,
        layout=args.layout,
        rig=args.rig,
        drive=args.drive,
        muscles=args.muscles,
        contractions_out=args.contractions_out,
        arkit=args.arkit,
        weights_out=args.weights_out,
        quiet=args.quiet,
    )
    print(result.summary())
    return 0


# ---------------------------------------------------------------------------------------
# rig


def add_rig(commands, parents) -> None:
    p = commands.add_parser(
        "rig", parents=parents, help="compute skin weights for a mesh and its landmarks",
        description="Compute the skin weights of a target mesh and write them as .npz "
        "(joint_indices and weights, (V, K)) for 'retarget transfer --rig'.")
    p.add_argument("mesh", metavar="MESH", help="target mesh")
    p.add_argument("--landmarks", required=True, metavar="T0.json", help="its landmarks JSON")
    p.add_argument("--out", required=True, metavar="RIG.npz", help="the rig, written here")
    p.add_argument("--method", choices=list(METHODS), default=DEFAULT_METHOD, metavar="NAME",
                   help=f"one of {_METHODS} (default: {DEFAULT_METHOD})")
    p.add_argument("--k", type=positive_int, metavar="K",
                   help="influences kept per vertex (default: the method's own, 4 for "
                   "ellipsoid and geodesic, all for the others)")
    layout_option(p)
    p.set_defaults(run=_rig)


def _rig(args) -> int:
    out = Path(args.out)
    require_parent(out)
    mesh = read_mesh(args.mesh)
    points = read_landmarks(args.landmarks, mesh)
    layout = layout_for(args.layout, points)
    options = {} if args.k is None else {"k": args.k}
    start = time.perf_counter()
    weights = computed_weights(args.method, mesh, points, layout, quiet=args.quiet, **options)
    seconds = time.perf_counter() - start
    write_file(out, weights.save)
    print(
        f"rig {args.method}: {weights.n_vertices} vertices, {weights.n_joints} joints, "
        f"{weights.n_influences} influences per vertex, {seconds:.2f} s -> {out}"
    )
    return 0


# ---------------------------------------------------------------------------------------
# export-gltf


def add_export_gltf(commands, parents) -> None:
    p = commands.add_parser(
        "export-gltf", parents=parents, help="export the rigged, animated face as glTF (.glb)",
        description="Write the target mesh (with its uv, normals and material), a joint per "
        "feature point and the rig (a glTF skin; morph targets for rigs with negative "
        "weights) as a glTF 2.0 binary; with a source, the retargeted take as an animation. "
        "With --drive muscles: a morph target per muscle and a jaw joint instead, animated by "
        "the solved contractions; with --drive arkit: ARKit's 52 blendshapes as named morph "
        "targets, animated by the solved weights. Lengths are written in metres (glTF's "
        "unit) from the mesh's unit, given or guessed from its size; --units keep writes the "
        "mesh's own numbers. The scale is recorded in the file.")
    p.add_argument("--mesh", required=True, metavar="MESH",
                   help="target mesh (obj, ply, stl, off, gltf, glb)")
    p.add_argument("--landmarks", required=True, metavar="T0.json", help="its landmarks JSON")
    p.add_argument("--out", required=True, metavar="OUT.glb", help="the glTF binary, written here")
    weights = p.add_mutually_exclusive_group()
    weights.add_argument("--deformer", choices=list(METHODS), default=None, metavar="NAME",
                         help=f"one of {_METHODS} (default: {DEFAULT_METHOD}); ellipsoid and "
                         "geodesic export as a skin, the others as morph targets")
    weights.add_argument("--rig", metavar="RIG.npz",
                         help="skin weights from 'retarget rig', instead of computing them")
    p.add_argument("--source-neutral", metavar="S0.npy",
                   help="(N, 2|3) neutral source points (with --source-frames: animate)")
    p.add_argument("--source-frames", metavar="S.npy",
                   help="(F, N, 2|3) source points per frame; the animation takes its name")
    p.add_argument("--fps", type=positive_float, default=30.0,
                   help="frames per second of the source frames (default: 30)")
    p.add_argument("--kernel", choices=list(KERNELS), default=None, metavar="NAME",
                   help=f"RBF space-transform kernel (default: {DEFAULT_KERNEL})")
    p.add_argument("--smoothing", type=non_negative_float, default=None, metavar="X",
                   help="space-transform smoothing, relative (default: as for transfer)")
    p.add_argument("--mask", nargs="+", action="extend", metavar="NAME",
                   help="partial retargeting: move only these regions, groups, point names "
                   "or feature indices")
    layout_option(p, "landmark layout (joint names)")
    p.add_argument("--drive", choices=list(DRIVES), default="points",
                   help="points: feature joints and the rig (default); muscles: a morph target per "
                   "muscle (and correctives for those the jaw crosses) and a jaw joint, animated by "
                   "the muscle IK's contractions (Woodward et al.), no rig; arkit: ARKit's 52 "
                   "blendshapes as named (sparse) morph targets, animated by the solved weights")
    p.add_argument("--muscles", metavar="MUSCLES.json",
                   help="with --drive muscles: muscles from 'retarget muscles' (default: placed from "
                   "the landmarks)")
    _arkit_options(p, "the take's (F, 52) weights written here as Live Link Face CSV at --fps")
    p.add_argument("--units", choices=list(EXPORT_UNITS), default="m",
                   help="m: every length in metres, glTF's unit (default); keep: the mesh's own numbers")
    p.add_argument("--mesh-units", choices=[*UNITS, "guess"], default="guess",
                   help="the unit the mesh is in (default: guess from its size: a face is about "
                   "0.2 m across, so ~0.2 is m, ~20 cm, ~200 mm; inches are never guessed)")
    p.add_argument("--form", choices=list(FORMS), default="exact",
                   help="exact: the rig as it is (a skin, or 3 morph targets a feature for rigs "
                   "with negative weights: large); skin: any rig as a skin of four influences a "
                   "vertex, fitted to the take, its error printed (small; what game engines play)")
    p.add_argument("--rate", type=float, choices=list(RATES), default=None, metavar="FPS",
                   help="animation keys at 24, 25, 30 or 60 fps (default: the take's own frames)")
    p.add_argument("--key-tolerance", type=non_negative_float, default=0.0, metavar="MM",
                   help="drop keys that the line between their neighbours reproduces within MM "
                   "millimetres, each channel apart (default 0: every key)")
    p.set_defaults(run=_export_gltf)


def _export_gltf(args) -> int:
    _refuse_other_rigs(args)
    result = export_gltf_files(
        args.mesh,
        args.landmarks,
        args.out,
        rig=args.rig,
        deformer=args.deformer or DEFAULT_METHOD,
        source_neutral=args.source_neutral,
        source_frames=args.source_frames,
        fps=args.fps,
        kernel=args.kernel,
        smoothing=args.smoothing,
        mask=args.mask,
        layout=args.layout,
        drive=args.drive,
        muscles=args.muscles,
        arkit=args.arkit,
        weights_out=args.weights_out,
        form=args.form,
        rate=args.rate,
        key_tolerance=args.key_tolerance,
        units=args.units,
        mesh_units=args.mesh_units,
        quiet=args.quiet,
    )
    print(result.summary())
    return 0


def _arkit_options(p, weights_help: str) -> None:
    """--arkit and --weights-out, for --drive arkit."""
    p.add_argument("--arkit", metavar="SHAPES.npz",
                   help="with --drive arkit: the shapes from 'retarget arkit' (default: made from the "
                   "landmarks, through --rig when given)")
    p.add_argument("--weights-out", metavar="W.csv", help=f"with --drive arkit: {weights_help}")


def _refuse_other_rigs(args) -> None:
    """--deformer and --rig name a rig, which --drive muscles does without; --drive arkit
    makes its shapes with their own rig or the --rig file's, never a --deformer's."""
    if args.drive == "muscles" and (args.deformer or args.rig):
        raise RetargetError("--drive muscles makes the motion with the muscles, not a rig: drop "
                            "--deformer and --rig")
    if args.drive == "arkit" and args.deformer:
        raise RetargetError("--drive arkit makes the motion with ARKit's shapes, made with their own "
                            "rig or --rig's: drop --deformer (or make a rig with 'retarget rig "
                            "--method NAME' and give it as --rig)")


# ---------------------------------------------------------------------------------------
# demo


def add_demo(commands, parents) -> None:
    p = commands.add_parser(
        "demo", parents=parents, help="run the built-in example (no files needed)",
        description="Retarget the built-in sample face from a performer of another identity, "
        "write the inputs and the result, and report the error against the ground truth.")
    p.add_argument("--out", default=DEMO_DIR, metavar="DIR",
                   help=f"directory for the files (default: ./{DEMO_DIR})")
    p.add_argument("--frames", type=positive_int, default=DEMO_FRAMES, metavar="F",
                   help=f"number of frames (default: {DEMO_FRAMES})")
    p.add_argument("--deformer", choices=list(METHODS), default=DEFAULT_METHOD, metavar="NAME",
                   help=f"one of {_METHODS} (default: {DEFAULT_METHOD})")
    p.set_defaults(run=_demo)


def _demo(args) -> int:
    from retarget.sample_face import demo_performance, demo_weights, posed_vertices, sample_face

    out_dir = Path(args.out)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RetargetError(f"could not create --out directory {str(out_dir)!r}: {exc}") from exc
    target = sample_face()
    expression = demo_weights(args.frames)
    s0, s = demo_performance(n_frames=args.frames)

    paths = {name: out_dir / name for name in (
        "target.obj", "target_landmarks.json", "source_neutral.npy",
        "source_frames.npy", "out.npy")}
    save_mesh(mesh_from_arrays(target.vertices, target.faces, uv=target.uv, name="target"),
              paths["target.obj"])
    write_json(paths["target_landmarks.json"],
                {"vertex_indices": np.asarray(target.landmarks68).tolist(), "layout": "ibug68"})
    write_npy(paths["source_neutral.npy"], s0)
    write_npy(paths["source_frames.npy"], s)

    result = transfer_files(
        paths["target.obj"], paths["target_landmarks.json"], paths["source_neutral.npy"],
        paths["source_frames.npy"], paths["out.npy"], deformer=args.deformer,
        quiet=args.quiet,
    )
    truth = posed_vertices(target, expression)
    error = np.linalg.norm(result.vertices - truth, axis=-1)          # (F, V) cm
    motion = np.linalg.norm(truth - target.vertices, axis=-1)         # (F, V) cm
    relative = error.sum() / motion.sum() if motion.sum() > 0 else float("nan")

    f, v, _ = result.vertices.shape
    rate = f / result.transfer_seconds if result.transfer_seconds > 0 else float("inf")
    print(
        f"retarget demo: the sample face ({v} vertices, in cm) animated by a performer of "
        f"another identity through {len(s0)} iBUG landmarks, {f} frames\n"
        f"  wrote {out_dir}/: target.obj, target_landmarks.json, "
        f"source_neutral.npy {s0.shape}, source_frames.npy {s.shape}\n"
        f"  retargeted with {result.method} in "
        f"{result.weights_seconds + result.transfer_seconds:.2f} s (weights "
        f"{result.weights_seconds:.2f} s, then {rate:.0f} frames/s) -> {result.out} "
        f"{result.vertices.shape} float32\n"
        f"  error against the ground truth (the target posed with the same expression "
        f"weights):\n"
        f"    mean {error.mean():.3f} cm, max {error.max():.3f} cm per vertex; relative "
        f"{100 * relative:.1f} % (sum of error lengths / sum of true displacement lengths)\n"
        f"  the same from the files: {PROG} transfer --target-mesh {paths['target.obj']} "
        f"--target-landmarks {paths['target_landmarks.json']} "
        f"--source-neutral {paths['source_neutral.npy']} "
        f"--source-frames {paths['source_frames.npy']} --out {paths['out.npy']}"
    )
    return 0
