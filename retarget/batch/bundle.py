"""A batch as one zip: characters as exported projects (.glb), takes as take files
(``.npz``) with their conditioning settings, and the ``manifest.json`` that lists them,
what the web app's projects export as (``GET /api/manifest.zip``); unzipped, ``retarget
batch manifest.json --out DIR`` runs it.

The zip is deterministic: entries in a fixed order with a fixed date, so the same
projects give the same bytes (and a batch's content hashes do not change).
"""

from __future__ import annotations

import io
import json
import re
import zipfile

from retarget.batch.manifest import OUTPUTS, manifest_from_dict
from retarget.errors import RetargetError
from retarget.sources.take import Take

__all__ = ["ZIP_DATE", "manifest_bundle", "safe_name"]

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
