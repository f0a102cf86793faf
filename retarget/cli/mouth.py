"""``retarget open-mouth``: a closed-lip mesh cut open along its lip contact line
(`retarget.lips.opened_mouth`), so the rig's upper and lower lips separate."""

from __future__ import annotations

from pathlib import Path

from retarget.cli.parser import PROG, layout_option
from retarget.errors import RetargetError
from retarget.files import layout_for, read_landmarks, read_mesh, require_parent, write_json
from retarget.lips import opened_mouth
from retarget.mesh import save_mesh

__all__ = ["add_open_mouth"]


def add_open_mouth(commands) -> None:
    p = commands.add_parser(
        "open-mouth", help="cut a mesh's joined lips apart along their contact line",
        description="Cut the surface of a mesh whose lips are joined along the lip contact "
        "line, from one mouth corner to the other, duplicating the vertices on the cut so the "
        "upper and lower lips separate. The original vertices stay first and in their order "
        "(with their uv and normals); the duplicates are appended. Writes the opened mesh and "
        "its landmarks (lower-lip points on the cut move to the lower lip).")
    p.add_argument("mesh", metavar="MESH", help="the mesh with joined lips")
    p.add_argument("--landmarks", required=True, metavar="T0.json",
                   help="its landmarks JSON (a layout with mouth corners and lip points)")
    p.add_argument("--out", required=True, metavar="OPENED.obj",
                   help="the opened mesh, written here (obj, ply, off, gltf, glb)")
    p.add_argument("--landmarks-out", required=True, metavar="T0_OPENED.json",
                   help="the landmarks on the opened mesh, written here")
    layout_option(p)
    p.set_defaults(run=_open_mouth, quiet=True)


def _open_mouth(args) -> int:
    out, landmarks_out = Path(args.out), Path(args.landmarks_out)
    if out.suffix.lower() == ".stl":  # STL keeps no shared vertices: the landmarks would not hold
        raise RetargetError(f"--out {str(out)!r}: STL keeps no vertex order; write obj, ply, off, "
                            "gltf or glb")
    require_parent(out)
    require_parent(landmarks_out)
    mesh = read_mesh(args.mesh)
    points = read_landmarks(args.landmarks, mesh)
    layout = layout_for(args.layout, points)
    if layout is None:
        raise RetargetError("the lips are found from the layout's mouth points: give --layout "
                            "or a \"layout\" in the landmarks JSON")
    opened = opened_mouth(mesh, points, layout)
    try:
        save_mesh(opened.mesh, out)
    except OSError as exc:
        raise RetargetError(f"could not write {str(out)!r}: {exc}") from exc
    write_json(landmarks_out, {**opened.points.to_json(), "layout": layout.name})
    print(f"opened the mouth: {len(opened.cut)} vertices on the lip contact line duplicated, "
          f"{mesh.n_vertices} -> {opened.mesh.n_vertices} vertices -> {out}, {landmarks_out}"
          f" ({PROG} rig {out} --landmarks {landmarks_out} ...)")
    return 0
