"""What one batch task does: a character made ready once (mesh, feature points, rig, ARKit
shapes), and one pair's outputs made from it and a take, each written atomically.

Both are plain functions of picklable values, so the same code runs in this process
(``--workers 0``) and on Dask workers, and gives the same bytes: nothing written holds a
time or a path. A bad input is not an exception out of a task: `character_state` returns
a `CharacterFailure` and `pair_outputs` a failed `PairResult`, each with the reason, so one
bad file fails its own pairs and never the batch (a task that raises anyway, or whose
worker dies, is retried by the scheduler).
"""

from __future__ import annotations

import os
import time
import uuid
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np

from retarget.arkit.shapes import ArkitShapes, arkit_shapes
from retarget.arkit.solve import ArkitSolver
from retarget.batch.manifest import OUTPUTS, Character, TakeEntry
from retarget.custom_layouts import layout_from_spec
from retarget.errors import RetargetError
from retarget.files import computed_weights, layout_for, read_landmarks, read_mesh, read_rig, require_file
from retarget.landmarks import SurfacePoints
from retarget.layouts import get_layout
from retarget.mesh import Mesh
from retarget.performance import Performance
from retarget.skin import SkinWeights, skin_displacements
from retarget.sources.arkit_curves import ArkitCurves, live_link_csv
from retarget.sources.files import read_take

__all__ = ["CharacterFailure", "CharacterState", "PairJob", "PairResult", "character_state",
           "pair_outputs", "remove_leftovers", "write_atomic"]


@dataclass(frozen=True)
class CharacterState:
    """A character ready to drive: computed once, shared by all its pairs.

    mesh : the target mesh, V vertices, its own units.
    points : its N feature points, `layout`'s order.
    layout : the layout's name.
    weights : (V, K) skin weights over the N points.
    shapes : ARKit's 52 shapes (deltas (52, V, 3)) when a pair asks for ARKit weights, else None.
    kernel, smoothing : the space transform's.
    """

    name: str
    mesh: Mesh
    points: SurfacePoints
    layout: str
    weights: SkinWeights
    shapes: ArkitShapes | None
    kernel: str
    smoothing: float | None


@dataclass(frozen=True)
class CharacterFailure:
    """A character that could not be made ready, and why (`lasting` as `PairResult`'s)."""

    name: str
    reason: str
    lasting: bool = True


@dataclass(frozen=True)
class PairJob:
    """One pair to make: the take, the outputs (kinds of `OUTPUTS`), the folder
    ``OUT/<character>/<take>`` they go to (absolute), the pair's content hash and the
    .glb's options (`Manifest.gltf`)."""

    character: str
    take: TakeEntry
    outputs: tuple[str, ...]
    folder: str
    digest: str
    gltf: dict = field(default_factory=dict)

    @property
    def key(self) -> str:
        return f"{self.character}/{self.take.name}"


@dataclass(frozen=True)
class PairResult:
    """What a pair task did: ok, or the reason it failed; the files written (names in the
    pair's folder) and its wall time in seconds. `lasting`: the failure comes from the
    inputs (a bad file, a bad setting), so it happens again until they change; else (a
    write error, a lost task) a rerun may succeed."""

    key: str
    digest: str
    ok: bool
    reason: str = ""
    files: tuple[str, ...] = ()
    seconds: float = 0.0
    lasting: bool = False


def character_state(character: Character, arkit: bool) -> CharacterState | CharacterFailure:
    """The character's mesh, points and rig (read from its files, or from an exported
    project .glb), and with `arkit` its ARKit shapes; a `CharacterFailure` naming the
    problem when an input is missing or bad."""
    try:
        if character.layout_spec is not None:
            layout_from_spec(character.layout_spec)  # registered in this worker too
        if character.project is not None:
            from retarget.gltf import read_gltf

            require_file(character.project, "project")
            face = read_gltf(character.project)
            mesh, points, weights = face.mesh, face.points, face.weights
            layout = _layout_name(character.layout or points.layout or None, points)
        else:
            mesh = read_mesh(character.mesh)
            points = read_landmarks(character.landmarks, mesh)
            layout = _layout_name(character.layout, points)
            if character.rig_file is not None:
                weights = read_rig(character.rig_file, mesh, points.n_points)
            else:
                options = {} if character.rig.k is None else {"k": character.rig.k}
                weights = computed_weights(character.rig.deformer, mesh, points, get_layout(layout),
                                           quiet=True, **options)
        points = replace(points, layout=layout)  # the glTF joints are named after it
        shapes = arkit_shapes(mesh.vertices, mesh.faces, points, get_layout(layout), weights) if arkit else None
        return CharacterState(character.name, mesh, points, layout, weights, shapes,
                              character.rig.kernel, character.rig.smoothing)
    except RetargetError as exc:
        return CharacterFailure(character.name, str(exc))
    except OSError as exc:
        return CharacterFailure(character.name, str(exc), lasting=False)


def _layout_name(name: str | None, points: SurfacePoints) -> str:
    """The layout named (or the landmarks'), checked against the N points; iBUG 68 for 68
    points without one, as the app takes a project saved without one."""
    layout = layout_for(name, points)
    if layout is not None:
        return layout.name
    if points.n_points == 68:
        return "ibug68"
    raise RetargetError(f"the landmarks ({points.n_points} points) name no layout: give the "
                        "character a 'layout'")


def pair_outputs(state: CharacterState | CharacterFailure, job: PairJob) -> PairResult:
    """Read and condition the take as the app plays it, retarget it onto the character
    (`retarget.performance.Performance`, Dutreve et al. 2008 §4) and write the job's
    outputs into its folder, each atomically: ``animation.glb`` (the rigged face with the
    take, `retarget.gltf.export_gltf`), ``arkit.csv`` (the take solved into ARKit's 52
    weights, Live Link Face CSV at the take's rate), ``vertices.npy`` ((F, V, 3) float32,
    mesh units and vertex order)."""
    start = time.perf_counter()
    if isinstance(state, CharacterFailure):
        return PairResult(job.key, job.digest, False, f"character {state.name!r}: {state.reason}",
                          lasting=state.lasting)
    try:
        take = read_take(job.take.file, layout=state.layout, mapping=job.take.mapping, fps=job.take.fps,
                         labelled_vertices=job.take.labelled_vertices)
        if take.n_points != state.points.n_points:
            raise RetargetError(f"the take has {take.n_points} points, the character {state.points.n_points}")
        performance = Performance(state.points.positions(state.mesh.vertices), state.layout,
                                  job.take.settings, job.take.regions, kernel=state.kernel,
                                  smoothing=state.smoothing)
        clip = performance.play(take, job.take.name)
        files = []
        folder = Path(job.folder)
        folder.mkdir(parents=True, exist_ok=True)
        for kind in job.outputs:
            path = folder / OUTPUTS[kind]
            write_atomic(path, partial(_write_output, kind, state, clip, take.fps, job.gltf))
            files.append(path.name)
        return PairResult(job.key, job.digest, True, files=tuple(files), seconds=time.perf_counter() - start)
    except (RetargetError, OSError) as exc:
        return PairResult(job.key, job.digest, False, f"take {job.take.name!r}: {exc}",
                          seconds=time.perf_counter() - start, lasting=isinstance(exc, RetargetError))


def _write_output(kind: str, state: CharacterState, clip, fps: float, gltf: dict, f) -> None:
    """Write one output of the retargeted `clip` ((F, N, 3) feature displacements, mesh
    units) to the binary file `f`; `gltf` the .glb's options."""
    if kind == "gltf":
        from retarget.gltf import export_gltf

        f.write(export_gltf(state.mesh, state.points, state.weights, [clip], **gltf))
    elif kind == "npy":
        # streamed in chunks of frames: a long take on a dense face is (F, V, 3) float32 of
        # gigabytes, never held at once; the bytes are np.save's
        rest = state.mesh.vertices.astype(np.float64)
        matrix = state.weights.matrix()
        np.lib.format.write_array_header_1_0(f, {"descr": np.lib.format.dtype_to_descr(np.dtype("<f4")),
                                                 "fortran_order": False,
                                                 "shape": (clip.n_frames, len(rest), 3)})
        for i in range(0, clip.n_frames, NPY_CHUNK):
            frames = rest + skin_displacements(matrix, clip.displacements[i:i + NPY_CHUNK])
            f.write(np.ascontiguousarray(frames, dtype="<f4").tobytes())
    elif kind == "arkit_csv":
        weights = ArkitSolver(state.shapes.at_points).solve_frames(clip.displacements)
        f.write(live_link_csv(ArkitCurves(weights, float(fps), None, None, {})).encode())
    else:
        raise RetargetError(f"unknown output {kind!r}")


NPY_CHUNK = 64  # frames skinned at once: (64, V, 3) float64 at most in memory


def write_atomic(path: Path, data) -> None:
    """Write `data` (bytes, or a callable writing to a binary file) to `path` so that a
    reader (or a rerun after a crash) sees the old file or the whole new one, never a part:
    a temporary file beside it, then `os.replace`."""
    temporary = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    try:
        with open(temporary, "wb") as f:
            if callable(data):
                data(f)
            else:
                f.write(data)
        os.replace(temporary, path)
    finally:
        if temporary.exists():
            temporary.unlink()


def remove_leftovers(folder) -> None:
    """Delete the temporary files `write_atomic` left in `folder` when its process was killed
    mid-write (called where no task writes there: before and after a batch)."""
    for path in Path(folder).glob(".*.tmp"):
        try:
            path.unlink()
        except OSError:
            pass  # gone already, or not ours to delete: harmless either way
