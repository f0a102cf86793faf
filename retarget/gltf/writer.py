"""A rigged, animated target face as one glTF 2.0 binary file (.glb).

`export_gltf` (bytes) and `write_gltf` (to a file) write the mesh (positions, triangles,
and its normals, uv and material where it has them; the material's base colour image
only with uv), the feature points as joints, the deformation and one animation per `Clip`:

- The scene holds two root nodes: the mesh node, and ``root``, a static joint at the
  origin whose children are the N feature joints, one per feature point, named after
  the layout's points (``feature_00``... without a layout). A feature joint is a pure
  translation to its neutral position p_i (Dutreve §3: feature points as
  translation-only joints); an animation moves it to ``p_i + d_if`` at frame f, with
  LINEAR interpolation between the clip's times.
- Joint-based rigs (non-negative rows summing to at most 1: ellipsoid, geodesic) are a
  glTF skin over ``root`` and the features with inverse bind matrices ``T(-p_i)``, and
  per-vertex JOINTS_n / WEIGHTS_n (float weights, each vertex's summing to 1 with the
  root taking the remainder; as many sets of four as the busiest vertex needs: two for
  the four-influence sparse rigs). See `retarget.gltf.influences`.
- Other rigs (negative weights: dense RBF, region RBF, Laplacian, biharmonic) are not
  joint-based; the mesh carries 3N morph targets (``<feature>.x``... in
  ``mesh.extras.targetNames``, their scale in ``mesh.extras.targetScale``) animated by
  the displacements over that scale, within [-1, 1], and the joints move as plain nodes
  beside it. See `retarget.gltf.morph`. Blender 5.0's importer sets a shape key's
  slider range from the first key only and clamps the animation to it, so widen the
  ranges to [-1, 1] after import (tests/blender/evaluate_glb.py does).

- ``form="skin"`` makes any rig a skin of one JOINTS_0 / WEIGHTS_0 set (four influences
  a vertex, the root among them): the weights are first fitted to the clips' motion by
  `retarget.weights.skin_fit` (exact for rows that already fit), and the fit's error is
  recorded in ``extras.retarget.fit``. Large dense rigs become a few MiB instead of
  hundreds, approximately.

Animation keys: `retarget.gltf.keys` resamples the clips at a ``rate`` and drops the keys a
line reproduces within ``key_tolerance`` millimetres, each channel keyed apart.

Either way a glTF viewer draws ``v0 + W d_f``, what `retarget.skin.skin_displacements`
computes, to float32 rounding (W the fitted weights for the skin form); normals are not animated (translation-only joints keep
them; morph targets carry no NORMAL offsets).

`export_muscles_gltf` and `write_muscles_gltf` write a face driven by its muscles
(Woodward §4) in the form `retarget.muscles.morphs` plays them: one morph target per
muscle, named after it, then the correctives (``<muscle>*jaw``), all in
``mesh.extras.targetNames``; a skin of ``root`` and one ``jaw`` joint, a translation to
the hinge whose rotation about the hinge axis is the jaw angle, weighted per vertex by the
jaw's weights (the root takes the rest, as above). A `ContractionClip` is one animation
keying, per frame, the morph weights c_m / high_m and the correctives' products, and
the jaw joint's rotation quaternion (LINEAR: slerp about one axis is the angle
interpolated linearly). glTF morphs, then skins: a viewer draws
`retarget.muscles.morphs.played_displacements`, to float32 rounding.

Units: metres by default (glTF's convention, what Unity, Unreal and Blender assume): the
mesh's unit (given, or guessed from its size by `retarget.units.guess_units`) scales every
length in the vertex data before it is written, ``units="keep"`` writes the mesh's own
numbers; the scale is recorded and `retarget.gltf.reader` undoes it (`retarget.gltf.units`
says why the data and not a node scale). Head motion: clips with ``head_rotations`` animate
a ``head`` node over the face (`retarget.gltf.head`). The scene's ``extras.retarget``
records the landmarks (`SurfacePoints.to_json`), the rig's method, the deformation kind,
the units and the head node for the round trip.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import trimesh

from retarget import __version__
from retarget.errors import RetargetError
from retarget.clips import Clip, ContractionClip
from retarget.gltf.glb import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GlbBuilder
from retarget.gltf.head import add_head_motion, head_pivot
from retarget.gltf.influences import is_joint_based, joint_influences
from retarget.gltf.keys import Keys, KeyWriter
from retarget.gltf.morph import (AXES, SPARSE_SHARE, axis_offsets, feature_columns,
                                   morph_scale, target_bounds, target_names)
from retarget.gltf.sparse import add_morph_targets
from retarget.gltf.units import export_units, scaled_clip, scaled_mesh
from retarget.landmarks import SurfacePoints
from retarget.layouts import get_layout
from retarget.material import Material
from retarget.mesh import Mesh
from retarget.muscles.morphs import MuscleMorphs
from retarget.skin import SkinWeights
from retarget.weights.skin_fit import SLOTS, four_influence_skin, skin_fit_error

FORMAT = "retarget-gltf-1"
ROOT_NAME = "root"
JAW_NAME = "jaw"
MESH_NODE, ROOT_NODE, FIRST_FEATURE_NODE = 0, 1, 2
TRIANGLES = 4
FORMS = ("exact", "skin")


def joint_names(points: SurfacePoints) -> list[str]:
    """N feature joint names: the layout's point names when the landmarks follow a
    built-in layout of N points, else ``feature_00``, ``feature_01``..."""
    if points.layout:
        try:
            layout = get_layout(points.layout)
        except RetargetError:
            layout = None
        if layout is not None and layout.n_points == points.n_points:
            return list(layout.point_names)
    width = max(2, len(str(points.n_points - 1)))
    return [f"feature_{i:0{width}d}" for i in range(points.n_points)]


def export_gltf(mesh: Mesh, points: SurfacePoints, weights: SkinWeights, clips=(), *,
                form: str = "exact", rate: float | None = None, key_tolerance: float = 0.0,
                units: str = "m", mesh_units: str = "guess", progress=None) -> bytes:
    """The .glb bytes of `mesh` rigged with `weights` at `points`, with `clips` animated
    (arguments as for `write_gltf`)."""
    built = _built(mesh, points, weights, clips, progress, units, mesh_units, form,
                   Keys(rate, key_tolerance))
    data = built.glb_bytes()
    if progress is not None:
        progress(1.0)
    return data


def write_gltf(file, mesh: Mesh, points: SurfacePoints, weights: SkinWeights, clips=(), *,
               form: str = "exact", rate: float | None = None, key_tolerance: float = 0.0,
               units: str = "m", mesh_units: str = "guess", progress=None) -> int:
    """Write the .glb of `mesh` rigged with `weights` at `points`, with `clips` animated,
    to a binary file object, piece by piece (a large morph-target file is never whole in
    memory twice); returns the number of bytes written.

    mesh : the target, V vertices, in `mesh_units`.
    points : its N landmarks; the joints sit at ``points.positions(mesh.vertices)``.
    weights : (V, K) skin weights over the N features (any method; see the module
        docstring for skin versus morph targets).
    clips : `Clip` objects of N features each, one glTF animation per clip, in order;
        their ``head_rotations`` animate a ``head`` node (`retarget.gltf.head`).
    form : "exact" (the rig as it is: a skin when joint-based, else morph targets) or
        "skin" (any rig as a skin of four influences a vertex, fitted to the clips' motion
        by `retarget.weights.skin_fit`; its error is recorded in ``extras.retarget.fit``).
    rate : None (the clips' own frames) or 24, 25, 30, 60: keys resampled at that rate
        (`retarget.gltf.keys.resampled`).
    key_tolerance : millimetres; keys that linear interpolation reproduces this closely
        are dropped, each channel its own (`retarget.gltf.keys`); 0 keeps every key.
    units : "m" (every length in metres, the default) or "keep" (the mesh's numbers).
    mesh_units : the mesh's unit, "m", "cm", "mm", "in" or "guess" (from its size,
        `retarget.units.guess_units`).
    progress : optional callable taking the fraction done in [0, 1].

    Raises `RetargetError` when the sizes disagree (naming both) or the file would pass
    the GLB format's 4 GiB.
    """
    built = _built(mesh, points, weights, clips, progress, units, mesh_units, form,
                   Keys(rate, key_tolerance))
    n_bytes = built.write(file)
    if progress is not None:
        progress(1.0)
    return n_bytes


def export_muscles_gltf(mesh: Mesh, morphs: MuscleMorphs, clips=(), *, rate: float | None = None,
                        key_tolerance: float = 0.0, units: str = "m", mesh_units: str = "guess",
                        progress=None) -> bytes:
    """The .glb bytes of `mesh` driven by its muscles, with `clips` animated (arguments as
    for `write_muscles_gltf`)."""
    built = _built_muscles(mesh, morphs, clips, progress, units, mesh_units, Keys(rate, key_tolerance))
    data = built.glb_bytes()
    if progress is not None:
        progress(1.0)
    return data


def write_muscles_gltf(file, mesh: Mesh, morphs: MuscleMorphs, clips=(), *, rate: float | None = None,
                       key_tolerance: float = 0.0, units: str = "m", mesh_units: str = "guess",
                       progress=None) -> int:
    """Write the .glb of `mesh` driven by its muscles, with `clips` animated, to a binary
    file object (see the module docstring); returns the number of bytes written.

    mesh : the face, V vertices, in `mesh_units`.
    morphs : its muscles' played form (`retarget.muscles.morphs.muscle_morphs`), on V
        vertices.
    clips : `ContractionClip` objects of D = M + 1 dofs each, one animation per clip.
    rate, key_tolerance, units, mesh_units : as for `write_gltf`.
    progress : optional callable taking the fraction done in [0, 1].

    Raises `RetargetError` when the sizes disagree (naming both).
    """
    built = _built_muscles(mesh, morphs, clips, progress, units, mesh_units, Keys(rate, key_tolerance))
    n_bytes = built.write(file)
    if progress is not None:
        progress(1.0)
    return n_bytes


def export_mesh_gltf(mesh: Mesh) -> bytes:
    """The .glb bytes of `mesh` alone, one node without rig or animation: its positions,
    triangles, normals, uv and material as `export_gltf` writes them, so that
    `retarget.mesh.load_mesh` reads back the same vertices in the same order (how an
    imported export becomes a project's mesh file). A mesh with uv but no material gets
    glTF's default one (`Material()`): trimesh's reader drops TEXCOORD_0 without one."""
    out = GlbBuilder(f"retarget {__version__}")
    name = mesh.name or "face"
    if mesh.uv is not None and mesh.material is None:
        mesh = dataclasses.replace(mesh, material=Material())
    out.document["meshes"] = [{"name": name, "primitives": [_primitive(out, mesh)]}]
    out.document["nodes"] = [{"name": name, "mesh": 0}]
    out.document["scene"] = 0
    out.document["scenes"] = [{"name": name, "nodes": [MESH_NODE]}]
    return out.glb_bytes()


def _built(mesh, points, weights, clips, progress, units, mesh_units, form, keys) -> GlbBuilder:
    """The document and buffer of the export; progress reaches 0.95 (writing is left)."""
    clips = tuple(clips)
    _check_sizes(mesh, points, weights, clips)
    if form not in FORMS:
        raise RetargetError(f"the export form must be one of {', '.join(FORMS)}; got {form!r}")
    clips = keys.resampled(clips)
    unscaled_mesh, unscaled_clips = mesh, clips
    mesh, clips, scaling = _scaled(mesh, clips, units, mesh_units)
    fit = None
    if form == "skin":
        weights, fit = _fitted_skin(unscaled_mesh, points, weights, unscaled_clips,
                                    1000.0 * scaling["scale_to_metres"])
    names = joint_names(points)
    neutral = points.positions(mesh.vertices).astype(np.float32)  # (N, 3)
    skinned = is_joint_based(weights)
    step = _stepper(progress, 1 + len(clips) + (0 if skinned else points.n_points))
    out, doc, primitive = _face_document(mesh)
    doc["nodes"] = [{"name": mesh.name or "face", "mesh": 0},
                    {"name": _root_name(names),
                     "children": list(range(FIRST_FEATURE_NODE, FIRST_FEATURE_NODE + len(names)))}]
    doc["nodes"] += [{"name": name, "translation": [float(x) for x in p]}
                     for name, p in zip(names, neutral)]
    step()
    scale = None if skinned else morph_scale(clips)
    if skinned:
        _add_skin(out, primitive, weights, neutral, "features")
    else:
        _add_morph_targets(out, doc["meshes"][0], weights, names, scale, step)
    doc["scene"] = 0
    doc["scenes"] = [{
        "name": mesh.name or "face",
        "nodes": [MESH_NODE, ROOT_NODE],
        "extras": {"retarget": {
            "format": FORMAT,
            "deformation": "skin" if skinned else "morph",
            "method": weights.method,
            "landmarks": points.to_json(),
            **scaling,
            **({"fit": fit} if fit is not None else {}),
            **keys.record(),
        }},
    }]
    writers = [KeyWriter(out, clip.times, keys.file_tolerance(scaling)) for clip in clips]
    if clips:
        doc["animations"] = []
        for clip, writer in zip(clips, writers):
            doc["animations"].append(_animation(writer, clip, neutral, scale))
            step()
    _head(out, clips, mesh, [ROOT_NODE] if skinned else [MESH_NODE, ROOT_NODE], writers)
    return out


def _fitted_skin(mesh, points, weights, clips, mm: float) -> tuple[SkinWeights, dict]:
    """The four-influence skin of `weights` fitted to the clips' motion, and the
    ``extras.retarget.fit`` record of its error (millimetres, `mm` to a mesh unit; no
    error without clips)."""
    neutral = points.positions(mesh.vertices)
    motion = np.concatenate([c.displacements for c in clips]) if clips else None
    fitted = four_influence_skin(weights, neutral, motion)
    record = {"from": "skin" if is_joint_based(weights) else "morph", "influences": SLOTS}
    if motion is not None:
        error = skin_fit_error(weights, fitted, motion)
        record.update(rms_relative=error.rms_relative, rms_mm=error.rms * mm,
                      worst_vertex_mm=error.worst_vertex * mm, frames=error.frames)
    return fitted, record


def _scaled(mesh, clips, units, mesh_units):
    """(mesh, clips) in the file's units and the ``extras.retarget`` units record
    (`retarget.gltf.units`)."""
    chosen = export_units(mesh, units, mesh_units)
    scale = chosen.scale
    return scaled_mesh(mesh, scale), tuple(scaled_clip(c, scale) for c in clips), chosen.record()


def _head(out: GlbBuilder, clips, mesh: Mesh, moved: list[int], writers) -> None:
    """The ``head`` node over `moved` for clips with head rotations, keyed by each clip's
    `KeyWriter`, recorded in the scene's extras (`retarget.gltf.head`)."""
    pivot = head_pivot(mesh.vertices)
    reach = float(np.linalg.norm(mesh.vertices - pivot, axis=1).max(initial=0.0))
    record = add_head_motion(out, clips, pivot, moved, writers, reach)
    if record is not None:
        out.document["scenes"][0]["extras"]["retarget"]["head"] = record


def _built_muscles(mesh, morphs, clips, progress, units, mesh_units, keys) -> GlbBuilder:
    """The document and buffer of the muscle export; progress reaches 0.95."""
    clips = tuple(clips)
    _check_muscle_sizes(mesh, morphs, clips)
    clips = keys.resampled(clips)
    mesh, clips, scaling = _scaled(mesh, clips, units, mesh_units)
    morphs = _scaled_morphs(morphs, scaling["scale"])
    names = list(morphs.names) + list(morphs.corrective_names)
    step = _stepper(progress, 1 + len(names) + len(clips))
    out, doc, primitive = _face_document(mesh)
    pivot = morphs.jaw_pivot.astype(np.float32)
    # the jaw is the skin's one joint beside the root, where a rig's features would be
    doc["nodes"] = [{"name": mesh.name or "face", "mesh": 0},
                    {"name": ROOT_NAME, "children": [FIRST_FEATURE_NODE]},
                    {"name": JAW_NAME, "translation": [float(x) for x in pivot]}]
    jaw = SkinWeights(np.zeros((mesh.n_vertices, 1), np.int32), morphs.jaw_weights[:, None], 1, "muscles")
    _add_skin(out, primitive, jaw, pivot[None], JAW_NAME)
    step()
    add_morph_targets(out, doc["meshes"][0], itertools.chain(morphs.targets, morphs.correctives), names,
                      step=step)
    doc["scene"] = 0
    doc["scenes"] = [{
        "name": mesh.name or "face",
        "nodes": [MESH_NODE, ROOT_NODE],
        "extras": {"retarget": {"format": FORMAT, "deformation": "muscles", "method": "muscles",
                                **scaling, **keys.record()}},
    }]
    writers = [KeyWriter(out, clip.times, keys.file_tolerance(scaling)) for clip in clips]
    jawed = mesh.vertices[morphs.jaw_weights > 0]
    jaw_reach = float(np.linalg.norm(jawed - pivot, axis=1).max(initial=0.0))
    # the most a unit of any morph weight (muscle or corrective) moves a vertex
    reach = float(np.linalg.norm(np.concatenate([morphs.targets, morphs.correctives]), axis=2).max(initial=0.0))
    if clips:
        doc["animations"] = []
        for clip, writer in zip(clips, writers):
            doc["animations"].append(_muscle_animation(writer, clip, morphs, jaw_reach, reach))
            step()
    _head(out, clips, mesh, [ROOT_NODE], writers)
    return out


def _scaled_morphs(morphs: MuscleMorphs, scale: float) -> MuscleMorphs:
    """`morphs` with its lengths (targets, correctives, the hinge) times `scale`."""
    if scale == 1.0:
        return morphs
    return dataclasses.replace(morphs, targets=morphs.targets * np.float32(scale),
                               correctives=morphs.correctives * np.float32(scale),
                               jaw_pivot=morphs.jaw_pivot * scale)


def _stepper(progress, steps: int):
    """A callable reporting one more of `steps` steps done to `progress` (which reaches 0.95:
    writing the file is left)."""
    report = progress or (lambda fraction: None)
    done = [0]

    def step():
        done[0] += 1
        report(0.95 * done[0] / steps)

    return step


def _face_document(mesh: Mesh) -> tuple[GlbBuilder, dict, dict]:
    """A new document holding the face's mesh: the builder, its document and the primitive."""
    out = GlbBuilder(f"retarget {__version__}")
    primitive = _primitive(out, mesh)
    out.document["meshes"] = [{"name": mesh.name or "face", "primitives": [primitive]}]
    return out, out.document, primitive


def _check_muscle_sizes(mesh, morphs, clips) -> None:
    if not isinstance(morphs, MuscleMorphs):
        raise RetargetError(f"morphs must be a MuscleMorphs; got {type(morphs).__name__}")
    if morphs.targets.shape[1] != mesh.n_vertices:
        raise RetargetError(f"the muscles are placed on {morphs.targets.shape[1]} vertices but the "
                            f"mesh has {mesh.n_vertices}")
    for clip in clips:
        if not isinstance(clip, ContractionClip):
            raise RetargetError(f"clips must be ContractionClip objects; got {type(clip).__name__}")
        if clip.contractions.shape[1] != len(morphs.names) + 1:
            raise RetargetError(f"clip {clip.name!r} has {clip.contractions.shape[1]} dofs but the "
                                f"muscles have {len(morphs.names) + 1} (the muscles and the jaw)")


def _check_sizes(mesh, points, weights, clips) -> None:
    if weights.n_vertices != mesh.n_vertices:
        raise RetargetError(f"the rig has weights for {weights.n_vertices} vertices but the "
                            f"mesh has {mesh.n_vertices}")
    if weights.n_joints != points.n_points:
        raise RetargetError(f"the rig has {weights.n_joints} joints but there are "
                            f"{points.n_points} landmarks")
    if not np.isfinite(weights.weights).all():
        raise RetargetError("the rig's weights hold NaN or infinite values")
    for clip in clips:
        if not isinstance(clip, Clip):
            raise RetargetError(f"clips must be Clip objects; got {type(clip).__name__}")
        if clip.displacements.shape[1] != points.n_points:
            raise RetargetError(f"clip {clip.name!r} moves {clip.displacements.shape[1]} "
                                f"features but there are {points.n_points} landmarks")


def _root_name(names: list[str]) -> str:
    """``root``, or ``root_`` ... when a feature already has that name."""
    name = ROOT_NAME
    while name in names:
        name += "_"
    return name


def _primitive(out: GlbBuilder, mesh: Mesh) -> dict:
    """The triangle primitive with POSITION, NORMAL and TEXCOORD_0 where the mesh has
    them, and its material."""
    attributes = {"POSITION": out.accessor(mesh.vertices.astype(np.float32),
                                           target=ARRAY_BUFFER, bounds=True)}
    if mesh.normals is not None:
        attributes["NORMAL"] = out.accessor(_unit_normals(mesh), target=ARRAY_BUFFER)
    if mesh.uv is not None:
        # Mesh.uv has OBJ's v (up); glTF's v runs down the image
        uv = np.column_stack([mesh.uv[:, 0], 1.0 - mesh.uv[:, 1]]).astype(np.float32)
        attributes["TEXCOORD_0"] = out.accessor(uv, target=ARRAY_BUFFER)
    index_type = np.uint16 if mesh.n_vertices <= 65535 else np.uint32
    primitive = {"attributes": attributes, "mode": TRIANGLES,
                 "indices": out.accessor(mesh.faces.ravel().astype(index_type),
                                         target=ELEMENT_ARRAY_BUFFER)}
    if mesh.material is not None:
        primitive["material"] = _add_material(out, mesh.material, textured=mesh.uv is not None)
    return primitive


def _add_material(out: GlbBuilder, material: Material, textured: bool) -> int:
    """The material (and its base colour image, when the mesh has uv to sample it)."""
    pbr = {"baseColorFactor": list(material.base_color), "metallicFactor": material.metallic,
           "roughnessFactor": material.roughness}
    if material.base_color_texture is not None and textured:
        doc = out.document
        doc["images"] = [{"bufferView": out.view(material.base_color_texture),
                          "mimeType": "image/png"}]
        doc["samplers"] = [{}]
        doc["textures"] = [{"source": 0, "sampler": 0}]
        pbr["baseColorTexture"] = {"index": 0}
    out.document["materials"] = [{
        "name": material.name, "pbrMetallicRoughness": pbr,
        "doubleSided": material.double_sided, "alphaMode": material.alpha_mode,
    }]
    return 0


def _unit_normals(mesh: Mesh) -> np.ndarray:
    """(V, 3) float32 unit normals (glTF requires unit length): the mesh's, normalised;
    where one is zero, the area-weighted normal of the faces around the vertex, and +z
    where that is zero too (a vertex on no face or only on degenerate ones)."""
    n = np.asarray(mesh.normals, dtype=np.float64)
    length = np.linalg.norm(n, axis=1)
    zero = length < 1e-12
    if zero.any():
        computed = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).vertex_normals
        n = np.where(zero[:, None], computed, n)
        length = np.linalg.norm(n, axis=1)
        still = length < 1e-12
        n[still], length[still] = (0.0, 0.0, 1.0), 1.0
    return (n / length[:, None]).astype(np.float32)


def _add_skin(out: GlbBuilder, primitive: dict, weights: SkinWeights, neutral: np.ndarray,
              name: str):
    """JOINTS_n / WEIGHTS_n on the primitive and the skin `name` over root and the joints
    at `neutral` (N, 3) float32, nodes FIRST_FEATURE_NODE onwards."""
    joints, influence = joint_influences(weights)
    for s in range(joints.shape[1] // 4):
        cols = slice(4 * s, 4 * s + 4)
        primitive["attributes"][f"JOINTS_{s}"] = out.accessor(
            np.ascontiguousarray(joints[:, cols]), target=ARRAY_BUFFER)
        primitive["attributes"][f"WEIGHTS_{s}"] = out.accessor(
            np.ascontiguousarray(influence[:, cols]), target=ARRAY_BUFFER)
    n = len(neutral)
    inverse_bind = np.tile(np.eye(4, dtype=np.float32), (n + 1, 1, 1))
    inverse_bind[1:, :3, 3] = -neutral
    # glTF matrices are column-major
    ibm = inverse_bind.transpose(0, 2, 1).reshape(n + 1, 16)
    out.document["skins"] = [{
        "name": name,
        "joints": [ROOT_NODE] + list(range(FIRST_FEATURE_NODE, FIRST_FEATURE_NODE + n)),
        "inverseBindMatrices": out.accessor(ibm),
        "skeleton": ROOT_NODE,
    }]
    out.document["nodes"][MESH_NODE]["skin"] = 0


def _add_morph_targets(out: GlbBuilder, gltf_mesh: dict, weights: SkinWeights, names,
                       scale: float, step) -> None:
    """Three targets per feature, s W[:, i] e_a (see `retarget.gltf.morph`); sparse
    where few vertices move, the three axes sharing one index view."""
    columns = feature_columns(weights)
    v = weights.n_vertices
    index_type = np.uint16 if v <= 65536 else np.uint32
    targets = []
    for column in columns:
        full = column * np.float32(scale)
        rows = np.flatnonzero(full).astype(index_type)
        values = full[rows]
        sparse = len(rows) < SPARSE_SHARE * v
        view = out.view(rows) if sparse and len(rows) else None
        for a in range(len(AXES)):
            bounds = target_bounds(values, v, a)
            if sparse:
                accessor = out.sparse_accessor(v, rows, axis_offsets(values, a),
                                               indices_view=view, bounds=bounds)
            else:
                accessor = out.accessor(axis_offsets(full, a), target=ARRAY_BUFFER,
                                        bounds=bounds)
            targets.append({"POSITION": accessor})
        step()
    gltf_mesh["primitives"][0]["targets"] = targets
    gltf_mesh["weights"] = [0.0] * len(targets)
    gltf_mesh["extras"] = {"targetNames": target_names(names), "targetScale": scale}


def _muscle_animation(keys: KeyWriter, clip: ContractionClip, morphs: MuscleMorphs,
                      jaw_reach: float, reach: float) -> dict:
    """One animation: the jaw joint's rotation by each frame's jaw angle about the hinge
    axis, and the mesh's morph weights (muscles, then correctives), LINEAR. Key reduction
    measures a weight by `reach`, the most a target moves a vertex, a quaternion component
    (half the angle) by twice `jaw_reach`, how far from the hinge the jaw's vertices lie."""
    weights, angle = morphs.weights(clip.contractions)                   # (F, M), (F,)
    keyed = np.hstack([weights, morphs.corrective_weights(clip.contractions)])
    half = 0.5 * angle
    rotation = np.column_stack([np.sin(half)[:, None] * morphs.jaw_axis, np.cos(half)])  # (F, 4) xyzw
    samplers = [keys.sampler(rotation, scale=2.0 * max(jaw_reach, 1e-12)),
                keys.sampler(keyed, scale=max(reach, 1e-12), weights=True)]
    channels = [{"sampler": 0, "target": {"node": FIRST_FEATURE_NODE, "path": "rotation"}},
                {"sampler": 1, "target": {"node": MESH_NODE, "path": "weights"}}]
    return {"name": clip.name, "samplers": samplers, "channels": channels}


def _animation(keys: KeyWriter, clip: Clip, neutral: np.ndarray, scale: float | None) -> dict:
    """One animation: every feature joint's translation p_i + d_if (LINEAR), and for a
    morph rig (`scale` s given) the mesh's 3N target weights d_if / s."""
    f, n = clip.n_frames, len(neutral)
    moved = (neutral.astype(np.float64)[:, None] + clip.displacements.transpose(1, 0, 2))
    samplers = [keys.sampler(moved[i]) for i in range(n)]
    channels = [{"sampler": i, "target": {"node": FIRST_FEATURE_NODE + i, "path": "translation"}}
                for i in range(n)]
    if scale is not None:
        channels.append({"sampler": len(samplers),
                         "target": {"node": MESH_NODE, "path": "weights"}})
        samplers.append(keys.sampler(clip.displacements.reshape(f, n * 3) / np.float32(scale),
                                     scale=scale, weights=True))
    return {"name": clip.name, "samplers": samplers, "channels": channels}

