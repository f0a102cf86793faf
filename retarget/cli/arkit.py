"""``retarget arkit``: ARKit's 52 blendshapes generated on a face from its landmarks
(`retarget.arkit.shapes`), one dense morph target per ARKit name."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from retarget.arkit.shapes import arkit_shapes
from retarget.cli.parser import layout_option
from retarget.errors import RetargetError
from retarget.files import layout_for, read_landmarks, read_mesh, read_rig, require_parent, write_file

__all__ = ["add_arkit"]


def add_arkit(commands) -> None:
    p = commands.add_parser(
        "arkit", help="generate ARKit's 52 blendshapes on a face",
        description="Generate ARKit's 52 blendshapes (eyeBlinkLeft ... tongueOut; Left is the "
        "subject's left) on a face mesh from its landmarks: the reference face's motion of each "
        "shape, carried onto the face by the RBF space transform and a rig: the one given with --rig "
        "(on the landmarks), else the shapes' own (the reference's 468 face-mesh points carried onto "
        "the surface, an RBF rig). Writes an .npz with names (52,) and deltas (52, V, 3) float32 "
        "vertex displacements in the mesh's units, and at_points (52, N, 3) the feature points' "
        "displacements.")
    p.add_argument("mesh", metavar="MESH", help="the face mesh")
    p.add_argument("--landmarks", required=True, metavar="T0.json", help="its landmarks JSON")
    layout_option(p)
    p.add_argument("--rig", metavar="RIG.npz", help="skin weights from 'retarget rig' to make the "
                   "shapes with (default: the shapes' own rig)")
    p.add_argument("--out", required=True, metavar="SHAPES.npz", help="the shapes, written here")
    p.set_defaults(run=_arkit, quiet=True)


def _arkit(args) -> int:
    out = Path(args.out)
    require_parent(out)
    mesh = read_mesh(args.mesh)
    points = read_landmarks(args.landmarks, mesh)
    layout = layout_for(args.layout, points)
    if layout is None:
        raise RetargetError("the shapes need the landmarks' layout: give --layout or a \"layout\" "
                            "in the landmarks JSON")
    rig = None if args.rig is None else read_rig(args.rig, mesh, points.n_points)
    shapes = arkit_shapes(mesh.vertices, mesh.faces, points, layout, rig)
    write_file(out, shapes.save)
    largest = np.linalg.norm(shapes.deltas, axis=2).max(axis=1)
    top = np.argsort(-largest)[:3]
    print(f"made {len(shapes.names)} ARKit shapes on {mesh.name or args.mesh} ({mesh.n_vertices} "
          f"vertices, {layout.name}): largest motion "
          + ", ".join(f"{shapes.names[k]} {largest[k]:.3g}" for k in top)
          + f" (mesh units) -> {out}")
    return 0
