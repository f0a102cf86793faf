"""Morph targets written sparse: only the vertices a target moves.

A glTF accessor may be *sparse* (glTF 2.0 §3.6.2.3): no base buffer view (all zeros) and a
list of (index, value) substitutions. A morph target that moves part of a face (a blink,
a smile: most of ARKit's 52, each muscle of the muscle export) then costs its moving rows
only, 12 bytes of offset plus a 2-byte (up to 65,536 vertices) or 4-byte index each,
instead of 12 bytes for every vertex. Blender's importer, three.js's GLTFLoader and the
Khronos validator read sparse accessors; tests/unit/test_blender.py and
tests/e2e/test_export_threejs.py play such files.

`tolerance` (mesh units) drops a vertex whose offset is at most that long: a target's
smooth tail (a dense RBF rig's shapes move every vertex a little) is rounding, not
motion, below a small share of the face's size. Dropping it moves a posed vertex by at
most ``tolerance`` times the sum of the target weights; a target stays dense whenever
sparse would not be smaller, and then it is written exactly.
"""

from __future__ import annotations

import numpy as np

from retarget.gltf.glb import ARRAY_BUFFER, GlbBuilder

__all__ = ["add_morph_targets", "index_type", "kept_rows", "sparse_is_smaller", "target_accessor"]


def kept_rows(offsets: np.ndarray, tolerance: float = 0.0) -> np.ndarray:
    """(n,) int64 ascending rows of `offsets` (V, 3) whose length is above `tolerance`
    (mesh units; 0 keeps every row that moves at all)."""
    offsets = np.asarray(offsets, dtype=np.float32)
    if tolerance <= 0:
        return np.flatnonzero(offsets.any(axis=1))
    # squared, in float64: no square root per vertex, and no float32 round-off at the cut
    length2 = np.einsum("ij,ij->i", offsets, offsets, dtype=np.float64)
    return np.flatnonzero(length2 > float(tolerance) ** 2)


def index_type(count: int) -> np.dtype:
    """The smallest unsigned integer type glTF allows for sparse indices below `count`."""
    return np.dtype(np.uint16) if count <= 65536 else np.dtype(np.uint32)


def sparse_is_smaller(n_rows: int, count: int) -> bool:
    """Whether `n_rows` substitutions (an index and a VEC3 float each) take fewer bytes
    than `count` dense VEC3 floats."""
    return n_rows * (12 + index_type(count).itemsize) < 12 * count


def target_accessor(out: GlbBuilder, offsets: np.ndarray, tolerance: float = 0.0) -> int:
    """The POSITION accessor of one morph target of (V, 3) `offsets` (mesh units): sparse,
    holding the rows `kept_rows` keeps, when that is smaller, else dense and exact.
    ``min``/``max`` are those of the values stored (glTF requires them for POSITION)."""
    offsets = np.asarray(offsets, dtype=np.float32)
    v = len(offsets)
    rows = kept_rows(offsets, tolerance)
    if sparse_is_smaller(len(rows), v):
        return out.sparse_accessor(v, rows.astype(index_type(v)), offsets[rows], bounds=True)
    return out.accessor(offsets, target=ARRAY_BUFFER, bounds=True)


def add_morph_targets(out: GlbBuilder, gltf_mesh: dict, targets, names, *, tolerance: float = 0.0,
                      step=None) -> None:
    """Morph targets on the mesh's one primitive from (V, 3) offsets in `targets` (an
    iterable, so that they are never stacked), each by `target_accessor`, named `names`
    in ``mesh.extras.targetNames`` (what Blender's importer and three.js's GLTFLoader
    read) and in the primitive's ``extras.targetNames`` (what UniVRM reads), with default
    weights 0. `step` is called after each target (progress)."""
    accessors = []
    for offsets in targets:
        accessors.append({"POSITION": target_accessor(out, offsets, tolerance)})
        if step is not None:
            step()
    names = list(names)
    primitive = gltf_mesh["primitives"][0]
    primitive["targets"] = accessors
    primitive.setdefault("extras", {})["targetNames"] = names
    gltf_mesh["weights"] = [0.0] * len(accessors)
    gltf_mesh.setdefault("extras", {})["targetNames"] = names
