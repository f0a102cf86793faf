"""A batch as one zip: characters as exported projects (.glb), takes as take files
(``.npz``) with their conditioning settings, and the ``manifest.json`` that lists them,
what the web app's projects export as (``GET /api/manifest.zip``); ``retarget batch
BATCH.zip --out DIR`` runs it (`unpacked_bundle`: into ``DIR/.inputs/``), as does
``retarget batch manifest.json`` once unzipped.

The zip is deterministic: entries in a fixed order with a fixed date, so the same
projects give the same bytes (and a batch's content hashes do not change).
"""

from __future__ import annotations

import hashlib
import io
import json
import re
import zipfile
from pathlib import Path, PurePosixPath

from retarget.batch.manifest import OUTPUTS, manifest_from_dict
from retarget.errors import RetargetError
from retarget.sources.take import Take
from retarget.zips import check_members, opened_zip, unpacked

__all__ = ["MAX_BUNDLE_BYTES", "ZIP_DATE", "manifest_bundle", "safe_name", "unpacked_bundle"]

MAX_BUNDLE_BYTES = 16 * 2**30  # unpacked, all members: many takes of many characters
MAX_BUNDLE_MEMBER = 4 * 2**30

ZIP_DATE = (2000, 1, 1, 0, 0, 0)  # a fixed entry date: no time in the bytes


def safe_name(name: str, taken: set) -> str:
    """`name` as a manifest name (letters, digits, '.', '_', '-'; other runs as one '-'),
    made unique against `taken` (``-2``, ``-3`` ...), which it joins."""
    base = re.sub(r"[^A-Za-z0-9._-]+", "-", name).strip(".-")[:90] or "untitled"
    unique, n = base, 1
    while unique.lower() in taken:
        n += 1
        unique = f"{base}-{n}"
    taken.add(unique.lower())
    return unique


def manifest_bundle(characters, takes, outputs=("gltf",)) -> bytes:
    """The zip of a batch.

    characters : (name, .glb bytes) pairs: each a project exported with its mesh,
        landmarks and rig (`retarget.gltf.export_gltf` with no clips).
    takes : (name, `Take`, conditioning settings dict or None) triples.
    outputs : kinds of `retarget.batch.manifest.OUTPUTS`.
    Names are made safe and unique (`safe_name`); the manifest is checked as
    `retarget batch` will read it.
    """
    outputs = list(outputs)
    if not outputs or any(o not in OUTPUTS for o in outputs):
        raise RetargetError(f"outputs must be some of {', '.join(OUTPUTS)}; got {outputs!r}")
    files, entries_c, entries_t = {}, [], []
    taken_c, taken_t = set(), set()
    for name, glb in characters:
        name = safe_name(name, taken_c)
        files[f"characters/{name}.glb"] = bytes(glb)
        entries_c.append({"name": name, "project": f"characters/{name}.glb"})
    for name, take, settings in takes:
        if not isinstance(take, Take):
            raise RetargetError(f"take {name!r} is not a Take")
        name = safe_name(name, taken_t)
        buffer = io.BytesIO()
        take.save(buffer)
        files[f"takes/{name}.npz"] = _dated(buffer.getvalue())
        entries_t.append({"name": name, "file": f"takes/{name}.npz", "settings": settings or {}})
    manifest = {"version": 1, "outputs": outputs, "characters": entries_c, "takes": entries_t}
    manifest_from_dict(manifest, ".")  # what `retarget batch` will refuse, refused here
    return _zip([("manifest.json", (json.dumps(manifest, indent=1) + "\n").encode()), *files.items()])


def _zip(entries) -> bytes:
    """A deflated zip of (path, bytes) entries, in order, dated `ZIP_DATE`."""
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as zf:
        for path, data in entries:
            info = zipfile.ZipInfo(path, ZIP_DATE)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            zf.writestr(info, data)
    return out.getvalue()


def _dated(npz: bytes) -> bytes:
    """`numpy.savez`'s archive with its entries dated `ZIP_DATE` (numpy dates them now)."""
    with zipfile.ZipFile(io.BytesIO(npz)) as zf:
        return _zip([(info.filename, zf.read(info)) for info in zf.infolist()])


def unpacked_bundle(path, out) -> Path:
    """The ``manifest.json`` of the batch zip `path`, unpacked (bounds checked first,
    `retarget.zips`) into ``out/.inputs/<its sha256, 16 hex>/``, where Dask workers see it as
    the outputs (a shared folder); a zip already unpacked there is not unpacked again."""
    path = Path(path)
    label = repr(str(path))
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise RetargetError(f"could not read the batch zip {label}: {exc}") from None
    folder = Path(out) / ".inputs" / hashlib.sha256(data).hexdigest()[:16]
    manifest = folder / "manifest.json"
    if (folder / ".complete").is_file():
        return manifest
    archive = opened_zip(data, label)
    infos = [info for info in archive.infolist() if not info.is_dir()]
    check_members(infos, label, MAX_BUNDLE_BYTES, MAX_BUNDLE_MEMBER)
    if "manifest.json" not in {info.filename for info in infos}:
        raise RetargetError(f"{label} holds no manifest.json at its top: not a batch zip")
    for info in infos:  # every name checked before anything is written
        name = PurePosixPath(info.filename)
        if name.is_absolute() or ".." in name.parts or "\\" in info.filename:
            raise RetargetError(f"{label}: member {info.filename!r} points outside the archive's folder")
    budget = [MAX_BUNDLE_BYTES]
    for info in infos:
        target = folder.joinpath(*PurePosixPath(info.filename).parts)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(unpacked(archive, info, label, budget))
    (folder / ".complete").write_text("")  # a zip unpacked halfway is unpacked again
    return manifest
