"""``retarget muscles`` (Woodward §4: the 21 muscles and the jaw placed on a face from its
landmarks) and ``retarget recognise`` (§10: the expression of each frame, from the muscle
contractions)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from retarget.cli.parser import PROG, layout_option, positive_float
from retarget.errors import RetargetError
from retarget.files import (contractions_files, layout_for, muscles_for, read_landmarks, read_mesh,
                            read_npy, require_parent, write_json)
from retarget.muscles import MUSCLE_TABLE, dof_names, linearisation_error
from retarget.muscles.expressions import default_recogniser
from retarget.pipeline import DEFAULT_KERNEL
from retarget.rbf import KERNELS

__all__ = ["add_muscles", "add_recognise"]


def add_muscles(commands) -> None:
    p = commands.add_parser(
        "muscles", help="place the 21 virtual muscles and the jaw on a face",
        description="Place Woodward et al.'s 21 virtual muscles (linear and sphincter) and the "
        "jaw on a face mesh from its landmarks, and write their geometry as JSON for "
        f"'{PROG} transfer --drive muscles --muscles' (edit it to move a muscle).")
    p.add_argument("mesh", metavar="MESH", help="the face mesh")
    p.add_argument("--landmarks", required=True, metavar="T0.json", help="its landmarks JSON")
    layout_option(p)
    p.add_argument("--out", required=True, metavar="MUSCLES.json", help="the muscles, written here")
    p.set_defaults(run=_muscles, quiet=True)


def _muscles(args) -> int:
    out = Path(args.out)
    require_parent(out)
    mesh = read_mesh(args.mesh)
    points = read_landmarks(args.landmarks, mesh)
    model = muscles_for(None, mesh, points, layout_for(args.layout, points))
    write_json(out, model.to_json())
    moved = int((np.abs(model.linearised()).max(axis=(0, 2)) > 0).sum())
    print(f"placed {len(MUSCLE_TABLE)} kinds of muscle ({model.n_muscles} muscles) and the jaw on "
          f"{mesh.name or args.mesh}: {moved} of {mesh.n_vertices} vertices move; the linear form "
          f"(one morph target per dof) is {100 * linearisation_error(model):.1f} % off the exact "
          f"muscles -> {out}")
    return 0


def add_recognise(commands, parents) -> None:
    p = commands.add_parser(
        "recognise", parents=parents, help="name the expression of each frame",
        description="Recognise the expression of each frame (neutral or one of the six universal "
        "expressions) from muscle contractions, with the distance to each and a confidence, as CSV. "
        "FRAMES.npy is either (F, D) contractions (from 'transfer --drive muscles "
        "--contractions-out') or (F, N, 2|3) source points, solved on the target given.")
    p.add_argument("frames", metavar="FRAMES.npy", help="(F, D) contractions or (F, N, 2|3) source points")
    p.add_argument("--source-neutral", metavar="S0.npy", help="with source points: their neutral")
    p.add_argument("--target-mesh", metavar="MESH", help="with source points: the face they drive")
    p.add_argument("--target-landmarks", metavar="T0.json", help="with source points: its landmarks")
    layout_option(p)
    p.add_argument("--muscles", metavar="MUSCLES.json", help="muscles from 'retarget muscles' "
                   "(default: placed from the landmarks)")
    p.add_argument("--kernel", choices=list(KERNELS), default=DEFAULT_KERNEL, metavar="NAME",
                   help=f"RBF space-transform kernel (default: {DEFAULT_KERNEL})")
    p.add_argument("--fps", type=positive_float, default=30.0, help="frame rate for the time column (default 30)")
    p.add_argument("--out", required=True, metavar="LABELS.csv", help="the CSV, written here")
    p.set_defaults(run=_recognise)


def _recognise(args) -> int:
    out = Path(args.out)
    require_parent(out)
    frames = read_npy(args.frames, "frames")
    if frames.ndim == 3:
        missing = [f"--{k.replace('_', '-')}" for k in ("source_neutral", "target_mesh", "target_landmarks")
                   if getattr(args, k) is None]
        if missing:
            raise RetargetError(f"source points need {', '.join(missing)} to be solved into contractions")
        contractions, names = contractions_files(
            args.target_mesh, args.target_landmarks, args.source_neutral, args.frames,
            layout=args.layout, muscles=args.muscles, kernel=args.kernel, quiet=args.quiet)
    elif frames.ndim == 2:
        contractions, names = frames, dof_names()
        if frames.shape[1] != len(names):
            raise RetargetError(f"contractions {args.frames!r} must be (F, {len(names)}); got {frames.shape}")
    else:
        raise RetargetError(f"frames {args.frames!r} must be (F, D) contractions or (F, N, 2|3) "
                            f"source points; got {frames.shape}")
    if not np.isfinite(contractions).all():
        raise RetargetError(f"frames {args.frames!r}: contractions must be finite")
    recogniser = default_recogniser(names)
    recognition = recogniser.recognise(contractions)
    labels = list(recogniser.labels)
    try:
        with open(out, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["frame", "time_s", "expression", "confidence", *(f"distance_{e}" for e in labels)])
            for i, (label, conf, dist) in enumerate(zip(recognition.labels, recognition.confidence,
                                                        recognition.distances)):
                w.writerow([i, f"{i / args.fps:.4f}", label, f"{conf:.3f}", *(f"{d:.4f}" for d in dist)])
    except OSError as exc:
        raise RetargetError(f"could not write {str(out)!r}: {exc}") from exc
    counts = {e: int((recognition.labels == e).sum()) for e in labels}
    print(f"recognised {len(contractions)} frames: "
          + ", ".join(f"{e} {n}" for e, n in counts.items() if n) + f" -> {out}")
    return 0
