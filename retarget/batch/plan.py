"""A batch's plan: every pair (character x take) with the content hash of its inputs and
settings, and which of them the output folder's index says are done already.

The index, ``OUT/.retarget-batch.json``, maps ``"<character>/<take>"`` to the pair's hash,
its status ("done" or "failed"), its files and, for a failure, the reason and whether it
lasts (a bad input fails again until the input changes; a write error or a lost task may
not). A pair is skipped when its hash is the one recorded as done and its files are all
there, or as a lasting failure (reported again as failed, unless `retry_failed`); any
other failed pair, a pair whose hash changed (an input's bytes, a setting, the outputs
asked for, the project's version) or whose files are gone runs again. The hash reads every input file
once per plan (sha256; a missing file hashes as missing, and its pairs run to fail with the
reason), a mesh's side files too (`side_files`: an OBJ's MTL and texture, a .gltf's
buffers and images), so a new texture redoes the glTF outputs. The index is rewritten atomically, so a batch killed at any point leaves it valid.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

from retarget import __version__
from retarget.batch.manifest import OUTPUTS, Manifest
from retarget.batch.work import PairJob, PairResult, write_atomic
from retarget.errors import RetargetError
from retarget.material import material_from_mtl

__all__ = ["INDEX_NAME", "Plan", "plan_batch", "read_index", "side_files", "write_index"]

INDEX_NAME = ".retarget-batch.json"
INDEX_FORMAT = 1


@dataclass
class Plan:
    """The pairs to run and those skipped, for the manifest and output root `out`.

    jobs : the `PairJob`s to run, manifest order.
    skipped : keys (``"<character>/<take>"``) of the pairs already done.
    failed_before : key -> reason of the pairs not run because they failed before with the
        same inputs (a lasting failure).
    arkit : names of the characters whose pairs need ARKit shapes.
    index : the index as read (key -> entry), updated by `record`.
    """

    manifest: Manifest
    out: Path
    jobs: list[PairJob]
    skipped: list[str]
    failed_before: dict[str, str]
    arkit: set[str]
    index: dict

    def record(self, result: PairResult) -> None:
        """Note a pair's result in the index (written by `write_index`)."""
        entry = {"hash": result.digest, "status": "done" if result.ok else "failed"}
        if result.ok:
            entry["files"] = list(result.files)
        else:
            entry["reason"], entry["lasting"] = result.reason, result.lasting
        self.index[result.key] = entry


def plan_batch(manifest: Manifest, out, *, force: bool = False, retry_failed: bool = False) -> Plan:
    """The plan of `manifest` into the output root `out` (created if missing); `force`
    runs every pair whatever the index says, `retry_failed` also the pairs whose inputs
    failed before and have not changed."""
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RetargetError(f"could not create the output folder {str(out)!r}: {exc}") from None
    index = read_index(out)
    digests: dict[Path, str] = {}

    def file_digest(path: Path) -> str:
        if path not in digests:
            try:
                digests[path] = hashlib.sha256(path.read_bytes()).hexdigest()
            except OSError:
                digests[path] = "missing"
        return digests[path]

    characters = {}
    for c in manifest.characters:
        settings = {"layout": c.layout, "rig": c.rig.to_dict(), "project": c.project is not None,
                    "rig_file": c.rig_file is not None}
        files = list(c.files()) + (side_files(c.mesh) if c.mesh is not None else [])
        characters[c.name] = _digest({"settings": settings, "files": [file_digest(p) for p in files]})
    jobs, skipped, failed_before, arkit = [], [], {}, set()
    for character, take_name in manifest.pairs:
        take = manifest.take(take_name)
        digest = _digest({"format": INDEX_FORMAT, "version": __version__, "character": characters[character],
                          "take": file_digest(take.file), "take_settings": take.to_dict(),
                          "outputs": list(manifest.outputs), "gltf": manifest.gltf})
        key = f"{character}/{take_name}"
        folder = out / character / take_name
        entry = index.get(key)
        done = (not force and isinstance(entry, dict) and entry.get("hash") == digest
                and entry.get("status") == "done"
                and all((folder / OUTPUTS[kind]).is_file() for kind in manifest.outputs))
        if done:
            skipped.append(key)
            continue
        if (not force and not retry_failed and isinstance(entry, dict) and entry.get("hash") == digest
                and entry.get("status") == "failed" and entry.get("lasting")):
            failed_before[key] = str(entry.get("reason", ""))
            continue
        jobs.append(PairJob(character, take, manifest.outputs, str(folder.resolve()), digest, manifest.gltf))
        if "arkit_csv" in manifest.outputs:
            arkit.add(character)
    return Plan(manifest, out, jobs, skipped, failed_before, arkit, index)


def side_files(mesh: Path) -> list[Path]:
    """The files `retarget.mesh.load_mesh` reads beside the mesh file `mesh`, found by base
    name in its folder as the loader finds them: an OBJ's MTL libraries and the texture
    they name (`retarget.material.material_from_mtl`), a .gltf's external buffers and
    images. Unreadable or missing ones are listed all the same (they hash as missing)."""
    folder, found = mesh.parent, []

    def read(name: str):
        path = folder / name
        found.append(path)
        try:
            return path.read_bytes()
        except OSError:
            return None

    try:
        kind = mesh.suffix.lower()
        if kind == ".obj":
            text = mesh.read_bytes().decode("utf-8", errors="replace")
            if "mtllib" in text:
                material_from_mtl(text, read)
        elif kind == ".gltf":
            doc = json.loads(mesh.read_text(encoding="utf-8"))
            for item in [*(doc.get("buffers") or []), *(doc.get("images") or [])]:
                uri = item.get("uri") if isinstance(item, dict) else None
                if isinstance(uri, str) and not uri.startswith("data:"):
                    found.append(folder / uri.replace("\\", "/").rsplit("/", 1)[-1])
    except (OSError, ValueError, AttributeError, RetargetError):
        pass  # the mesh itself is unreadable: its own hash says so, and its pairs fail with the reason
    return list(dict.fromkeys(found))


def read_index(out: Path) -> dict:
    """The index in `out` (key -> entry); empty when there is none or it is unreadable
    (then every pair runs again, which is safe)."""
    try:
        data = json.loads((Path(out) / INDEX_NAME).read_text())
    except (OSError, ValueError):
        return {}
    if not isinstance(data, dict) or data.get("format") != INDEX_FORMAT or not isinstance(data.get("pairs"), dict):
        return {}
    return data["pairs"]


def write_index(plan: Plan) -> None:
    """Write the plan's index atomically (sorted keys: the same results, the same bytes)."""
    text = json.dumps({"format": INDEX_FORMAT, "pairs": plan.index}, indent=1, sort_keys=True) + "\n"
    write_atomic(plan.out / INDEX_NAME, text.encode())


def _digest(value) -> str:
    return hashlib.sha256(json.dumps(value, sort_keys=True, default=str).encode()).hexdigest()
