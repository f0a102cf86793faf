"""A small batch the project generates: characters of the sample face in other identities
(meshes as OBJ + landmarks JSON, one as a project .glb exported the app's way), takes of
the built-in performance in the formats the app imports (landmark CSV, NPY, JSON) and,
when asked, a broken take file; and the manifest (`retarget.batch.manifest`) listing them.
For `tests/unit/test_batch.py` and `bench/batch.py`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from retarget.landmarks import landmarks_from_json
from retarget.layouts import get_layout
from retarget.mesh import mesh_from_arrays, save_mesh
from retarget.sample_face import demo_performance, sample_face
from retarget.sources.files import write_take_csv
from retarget.sources.take import Take
from retarget.weights import compute_weights

__all__ = ["IDENTITIES", "write_batch_fixture"]

IDENTITIES = {"wide": (1.2, -0.5, 0.8), "narrow": (-1.0, 0.6, -0.7), "lips": (0.0, 0.3, 0.0, 1.5, -0.5)}
"""Character name -> sample-face identity parameters (`retarget.sample_face.IDENTITY_PARAMETERS`)."""


def write_batch_fixture(folder, *, n_characters: int = 3, n_takes: int = 3, n_frames: int = 20,
                        broken: bool = True, deformer: str = "ellipsoid", project: bool = True,
                        outputs=("gltf", "arkit_csv", "npy")) -> Path:
    """Write the inputs and ``manifest.yaml`` into `folder`; returns the manifest's path.

    n_characters : up to 3 (`IDENTITIES`); with `project`, the last is an exported .glb.
    n_takes : good takes of `n_frames` frames each (in turn CSV, NPY, JSON), different
        stretches of the built-in performance, 30 fps; `broken` adds one more, a CSV that
        does not parse.
    deformer : the characters' rig (ellipsoid is fast).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    layout = get_layout("ibug68")
    characters = []
    for i, (name, identity) in enumerate(list(IDENTITIES.items())[:n_characters]):
        face = sample_face(identity=np.asarray(identity, float))
        mesh = mesh_from_arrays(face.vertices, face.faces, uv=face.uv, name=name)
        landmarks = {"vertex_indices": np.asarray(face.landmarks68).tolist(), "layout": "ibug68"}
        if project and i == n_characters - 1 and n_characters > 1:
            from retarget.gltf import export_gltf

            points = landmarks_from_json(landmarks, mesh.vertices, mesh.faces)
            weights = compute_weights(deformer, mesh.vertices, mesh.faces, points, layout)
            (folder / f"{name}.glb").write_bytes(export_gltf(mesh, points, weights, []))
            characters.append({"name": name, "project": f"{name}.glb"})
            continue
        save_mesh(mesh, folder / f"{name}.obj")
        (folder / f"{name}.json").write_text(json.dumps(landmarks))
        characters.append({"name": name, "mesh": f"{name}.obj", "landmarks": f"{name}.json",
                           "rig": {"deformer": deformer}})
    _, frames = demo_performance(n_frames=n_frames * n_takes)
    takes = []
    for k in range(n_takes):
        points = frames[k * n_frames:(k + 1) * n_frames].astype(np.float32)
        take = Take(points, layout.point_names, 30.0, layout="ibug68")
        kind = ("csv", "npy", "json")[k % 3]
        path = folder / f"take{k}.{kind}"
        if kind == "csv":
            write_take_csv(take, path)
        elif kind == "npy":
            np.save(path, points)
        else:
            path.write_text(json.dumps({"layout": "ibug68", "fps": 30.0,
                                        "frames": [p.tolist() for p in points]}))
        takes.append({"name": f"take{k}", "file": path.name, "settings": {}})
    if broken:
        (folder / "broken.csv").write_text("frame,time,not_a_point_x\n0,zero,abc\n1,\n")
        takes.append({"name": "broken", "file": "broken.csv"})
    import yaml

    manifest = folder / "manifest.yaml"
    manifest.write_text(yaml.safe_dump({"version": 1, "outputs": list(outputs), "characters": characters,
                                        "takes": takes}, sort_keys=False))
    return manifest
