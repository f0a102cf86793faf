"""The face-mesh models: shipped in ``retarget/facemesh/models/``, extracted from the npm
package ``@mediapipe/face_mesh`` (the one the web app serves to the browser).

The package packs its files into one ``face_mesh_solution_packed_assets.data``; its
loader script lists each file's byte range. ``python -m retarget.facemesh.assets
web/node_modules/@mediapipe/face_mesh`` writes the two models this project runs (the
legacy 468-point landmark model and the short-range face detector), the canonical face
model's geometry and ``MODELS.json``
(their SHA-256 and the package version), which `model_bytes` checks on every load, so a
damaged or swapped file is refused by name rather than run.
"""

from __future__ import annotations

import hashlib
import json
import re
import sys
from pathlib import Path

from retarget.errors import RetargetError

__all__ = ["MODEL_DIR", "MODELS", "extract_models", "model_bytes", "model_interpreter"]

MODEL_DIR = Path(__file__).resolve().parent / "models"
MODELS = {
    "face_landmark.tflite": "/third_party/mediapipe/modules/face_landmark/face_landmark.tflite",
    "face_detection_short_range.tflite":
        "/third_party/mediapipe/modules/face_detection/face_detection_short_range.tflite",
    "geometry_pipeline_metadata_landmarks.binarypb":
        "/third_party/mediapipe/modules/face_geometry/data/geometry_pipeline_metadata_landmarks.binarypb",
}
"""File name here -> path inside the npm package's packed assets: the two models and the
face geometry's metadata, which holds the canonical face mesh (`retarget.facemesh.canonical`)."""

_PACKED = "face_mesh_solution_packed_assets.data"
_LOADER = "face_mesh_solution_packed_assets_loader.js"
_ENTRY = re.compile(r'"filename":\s*"([^"]+)",\s*"start":\s*(\d+),\s*"end":\s*(\d+)')


def extract_models(package_dir: Path, out_dir: Path = MODEL_DIR) -> dict:
    """Write `MODELS` from the npm package at `package_dir` into `out_dir`, with
    ``MODELS.json``; returns what ``MODELS.json`` holds."""
    package_dir = Path(package_dir)
    loader = (package_dir / _LOADER).read_text()
    ranges = {name: (int(start), int(end)) for name, start, end in _ENTRY.findall(loader)}
    packed = (package_dir / _PACKED).read_bytes()
    version = json.loads((package_dir / "package.json").read_text())["version"]
    out_dir.mkdir(parents=True, exist_ok=True)
    manifest = {"source": f"@mediapipe/face_mesh {version} (npm, Apache-2.0)", "files": {}}
    for name, inside in MODELS.items():
        if inside not in ranges:
            raise RetargetError(f"{package_dir / _LOADER} lists no {inside}")
        start, end = ranges[inside]
        if not 0 <= start < end <= len(packed):
            raise RetargetError(f"{inside} lies at bytes {start}..{end}, outside {_PACKED} ({len(packed)} bytes)")
        data = packed[start:end]
        (out_dir / name).write_bytes(data)
        manifest["files"][name] = {"sha256": hashlib.sha256(data).hexdigest(), "bytes": len(data)}
    (out_dir / "MODELS.json").write_text(json.dumps(manifest, indent=2) + "\n")
    return manifest


def model_bytes(name: str, model_dir: Path = MODEL_DIR) -> bytes:
    """The bytes of model `name` (a key of `MODELS`), checked against ``MODELS.json``."""
    if name not in MODELS:
        raise RetargetError(f"unknown face-mesh model {name!r}; the models are {', '.join(MODELS)}")
    try:
        manifest = json.loads((model_dir / "MODELS.json").read_text())
        data = (model_dir / name).read_bytes()
    except OSError as exc:
        raise RetargetError(f"the face-mesh model {name} is missing from {model_dir} ({exc.strerror}); "
                            "reinstall the package") from None
    expected = manifest["files"][name]["sha256"]
    if hashlib.sha256(data).hexdigest() != expected:
        raise RetargetError(f"the face-mesh model {model_dir / name} is damaged: its SHA-256 is not "
                            f"the one MODELS.json names; reinstall the package")
    return data


def model_interpreter(name: str, threads: int = 1):
    """A LiteRT interpreter of model `name`, tensors allocated, and its output tensor
    indices by name."""
    from ai_edge_litert.interpreter import Interpreter

    interpreter = Interpreter(model_content=model_bytes(name), num_threads=threads)
    interpreter.allocate_tensors()
    return interpreter, {d["name"]: d["index"] for d in interpreter.get_output_details()}


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit("usage: python -m retarget.facemesh.assets PATH/TO/node_modules/@mediapipe/face_mesh")
    print(json.dumps(extract_models(Path(sys.argv[1])), indent=2))
