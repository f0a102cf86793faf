"""The built-in sample project, so the first screen is never empty.

On the first start with an empty data dir the app creates "Sample face": the library's
procedural `retarget.sample_face.sample_face` (resolution 1, 8430 vertices, cm) saved
as OBJ by `retarget.mesh.save_mesh`, its 68 iBUG landmarks and a biharmonic rig. The
data go through the same library checks as an upload. A ``meta`` row remembers that it
was made, so deleting the sample does not bring it back on the next start.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from retarget.landmarks import landmarks_from_json
from retarget.layouts import get_layout
from retarget.mesh import load_mesh, mesh_from_arrays, save_mesh
from retarget.sample_face import sample_face
from retarget.weights import compute_weights
from server.store import ProjectStore

SAMPLE_NAME = "Sample face"
SAMPLE_LAYOUT = "ibug68"
SAMPLE_METHOD = "biharmonic"
_META_KEY = "sample_project"


def ensure_sample_project(store: ProjectStore) -> str | None:
    """Create the sample project if this data dir never had one and holds no project;
    returns its id, or None when nothing was made."""
    if store.meta(_META_KEY) is not None:
        return None
    if store.list():
        store.set_meta(_META_KEY, "")
        return None
    face = sample_face(1)
    project = store.create(SAMPLE_NAME, {"sample": True, "mesh_units": "cm"})  # generated in cm
    project_id = project["id"]
    with tempfile.TemporaryDirectory(dir=store.folder(project_id), prefix=".tmp-") as tmp:
        path = Path(tmp) / "sample_face.obj"
        save_mesh(mesh_from_arrays(face.vertices, face.faces, name="sample_face"), path)
        data = path.read_bytes()
    mesh = load_mesh(data, "obj")
    store.put_mesh(project_id, data, "obj", filename="sample_face.obj",
                   n_vertices=mesh.n_vertices, n_faces=mesh.n_faces)
    landmarks_json = {"vertex_indices": np.asarray(face.landmarks68).tolist(),
                      "layout": SAMPLE_LAYOUT}
    points = landmarks_from_json(landmarks_json, mesh.vertices, mesh.faces)
    project = store.put_landmarks(project_id, points.to_json(), n_points=points.n_points,
                                  layout=SAMPLE_LAYOUT, revision=store.get(project_id)["revision"])
    weights = compute_weights(SAMPLE_METHOD, mesh.vertices, mesh.faces, points,
                              get_layout(SAMPLE_LAYOUT))
    store.put_rig(project_id, weights, revision=project["revision"])
    store.set_meta(_META_KEY, project_id)
    return project_id
