"""``retarget landmarks``: a mesh's feature points found with no clicks
(`retarget.facemesh.placement`), written as the landmarks JSON the other commands read."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from retarget.cli.parser import PROG
from retarget.facemesh.placement import CHECK_BELOW, find_face_mesh, layout_landmarks
from retarget.files import read_mesh, require_parent, write_json
from retarget.layouts import LAYOUTS, get_layout

__all__ = ["add_landmarks"]


def add_landmarks(commands) -> None:
    p = commands.add_parser(
        "landmarks", help="find a face mesh's feature points automatically",
        description="Find the feature points of a layout on a face mesh with no clicks: the mesh "
        "is pictured, MediaPipe's face mesh runs on the picture (any orientation; the mesh's "
        "texture when it has one) and each point is carried back onto the surface. Writes the "
        "landmarks JSON (with a per-point \"confidence\", 0..1) and lists the points worth checking.")
    p.add_argument("mesh", metavar="MESH", help="the face mesh (obj, ply, off, stl, gltf, glb)")
    p.add_argument("--layout", default="dutreve22", choices=list(LAYOUTS), metavar="NAME",
                   help="landmark layout (default dutreve22; `retarget layouts` lists them)")
    p.add_argument("--out", required=True, metavar="T0.json", help="the landmarks JSON, written here")
    p.set_defaults(run=_landmarks, quiet=True)


def _landmarks(args) -> int:
    out = Path(args.out)
    require_parent(out)
    mesh = read_mesh(args.mesh)
    layout = get_layout(args.layout)
    found = find_face_mesh(mesh)
    points, confidence = layout_landmarks(found, layout, mesh)
    write_json(out, {**points.to_json(), "layout": layout.name,
                     "confidence": np.round(confidence, 3).tolist()})
    check = [layout.point_names[i] for i in np.flatnonzero(confidence < CHECK_BELOW)]
    print(f"found {layout.n_points} {layout.name} points on {mesh.name or args.mesh} "
          f"(face presence {found.presence:.2f}) -> {out}")
    if check:
        print(f"check {len(check)} of them (confidence under {CHECK_BELOW}): {', '.join(check)}")
    print(f"next: {PROG} rig {args.mesh} --landmarks {out} ...")
    return 0
