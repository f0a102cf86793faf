"""The project store: an SQLite index plus one folder of files per project.

Layout on disk::

    <data_dir>/index.sqlite                      the index (WAL mode): one row per project
    <data_dir>/projects/<id>/mesh-r<R>.<ext>     the upload's bytes exactly as uploaded
    <data_dir>/projects/<id>/landmarks-r<R>.json
    <data_dir>/projects/<id>/rig-r<R>-<hex>.npz  `retarget.skin.SkinWeights.save`: the automatic rig
    <data_dir>/projects/<id>/paint-r<R>-<hex>.npz `retarget.weights.painting.WeightEdit.save`:
                                                 the rows painted over it, if any
    <data_dir>/projects/<id>/take-<take id>.npz  `retarget.sources.take.Take.save`, one per take
    <data_dir>/projects/<id>/take-<take id>.jpg  a tracked video's first frame (marker takes)
    <data_dir>/projects/<id>/muscles-r<R>-<hex>.json  `retarget.muscles.MuscleFace.to_json`:
                                                 the virtual muscles, placed or edited
    <data_dir>/projects/<id>/arkit-r<R>-<hex>.npz  `retarget.arkit.ArkitShapes.save`: the 52
                                                 ARKit shapes made for revision R
    <data_dir>/projects/<id>/arkit-settings-<hex>.json  `retarget.arkit.ArkitSettings.to_json`:
                                                 the user's gains, painted fixes and rig

A mesh revision made from the current one (the mouth cut open, `put_mesh_revision`) keeps
the mesh and landmarks it replaced (the row's ``previous_mesh``) until `revert_mesh` goes
back to them or a new upload replaces both.

R is the project revision the file was written for. The index is the source of truth:
its row names the current file of each kind, and a file counts only once the row says
so. A new file never overwrites the one in use: it is written atomically under a new
name (a temporary file in the same folder, fsync, `os.replace`, fsync of the folder),
then one SQLite transaction points the row at it, then the replaced files are deleted.
A crash at any step leaves the old or the new state whole (never a new mesh with the
old mesh's landmarks); files no row names are swept when the store opens, and a new
`ProjectStore` on the same folder finds everything a previous one committed.

A painted rig is stored as the automatic rig (``rig_file``, kept for resets) plus the
rows that differ from it (``painted_file``), so a save writes only the painted rows.
``rig_version`` counts every change of the rig (computed, painted, reset), so a paint
made on an older rig is refused (`StaleRig`). Rig files are never rewritten under the
same name, so the automatic rigs last read are kept in memory.

Takes (recorded performances) belong to the project, not to its mesh: they are source
points, so a new mesh or new landmarks keep them. A take's file is written once; renaming
and trimming change only its row (trimming is non-destructive: the row keeps the span
in seconds and `take()` applies it).

Muscles (`put_muscles`) are placed automatically from the landmarks of a revision the
first time they are needed, or saved by the user; placed muscles never replace muscles
the user saved for the same revision (edited ones outlive a landmarks change, placed ones
are placed again).

ARKit shapes (`put_arkit_shapes`) are made by a job from the mesh and landmarks of a
revision (and, on the project's rig, from its rig version): a landmarks, mesh or (for
those) rig change makes them stale, and they are made again on request. The user's ARKit
settings (`put_arkit_settings`) belong to the project and outlive those changes (painted
fixes are per vertex: the router drops them for a mesh they do not fit). So does the live
stereo cameras' calibration (`put_stereo_calibration`).

Custom layouts (a user's markers, `put_layout`) are saved in the index itself, as the
validated spec JSON keyed by the project and a name matched against `LAYOUT_NAME`, so no
name of theirs reaches the filesystem; a project holds at most `MAX_PROJECT_LAYOUTS`.

Project ids come from `secrets.token_urlsafe(16)` and every id is matched against
`ID_PATTERN` before it is joined to a path; uploaded file names never reach the
filesystem (only an allow-listed extension does). The store holds no maths: it takes and
gives bytes, JSON and `SkinWeights`.
"""

from __future__ import annotations

import json
import os
import re
import secrets
import shutil
import sqlite3
import tempfile
import threading
from datetime import datetime, timezone
from pathlib import Path

from retarget.arkit.shapes import ArkitShapes
from retarget.mesh import Mesh, load_mesh
from retarget.skin import SkinWeights
from retarget.sources.take import Take
from retarget.weights.painting import WeightEdit, painted_rig
from server.wire import quantised_weights

__all__ = ["ID_PATTERN", "LAYOUT_NAME", "MAX_PROJECT_LAYOUTS", "MESH_EXTENSIONS", "LayoutNotFound",
           "ProjectNotFound", "ProjectStore", "StaleRig", "TAKE_ID_PATTERN", "TakeNotFound"]

ID_PATTERN = re.compile(r"[A-Za-z0-9_-]{22}")
"""What `secrets.token_urlsafe(16)` returns: 22 URL-safe base64 characters."""

MESH_EXTENSIONS = ("obj", "ply", "stl", "off", "glb", "gltf", "zip")
"""File extensions a stored mesh may have (the formats `retarget.mesh.load_mesh` reads; a
zip holds a mesh file with its MTL, images or buffers)."""

_FILE_COLUMNS = ("mesh_file", "landmarks_file", "rig_file", "painted_file", "muscles_file", "arkit_file",
                 "arkit_settings_file", "stereo_calibration_file")
_FILE_PATTERN = re.compile(r"(mesh(-r\d+)?\.[a-z]+|landmarks(-r\d+)?\.json|rig(-r\d+(-[0-9a-f]+)?)?\.npz"
                           r"|paint-r\d+-[0-9a-f]+\.npz|muscles-r\d+-[0-9a-f]+\.json|arkit-r\d+-[0-9a-f]+\.npz"
                           r"|arkit-settings-[0-9a-f]+\.json|stereo-calibration(-[0-9a-f]+)?\.json|\.tmp-.*)")
"""Names the store writes in a project folder (plus its temporary files)."""

_RIG_CACHE_BYTES = 512 * 2**20
"""Memory for automatic rigs read lately (a dense rig of 100k vertices and 68 joints takes
55 MB); the last one read stays whatever its size."""

_MESH_CACHE_BYTES = 256 * 2**20
"""Memory for meshes read lately (the 133k-vertex face takes about 12 MB); the last one read stays
whatever its size."""

TAKE_ID_PATTERN = re.compile(r"[A-Za-z0-9_-]{16}")
"""What `secrets.token_urlsafe(12)` returns: a take id."""
_TAKE_FILE = re.compile(r"take-[A-Za-z0-9_-]{16}\.(npz|jpg)")

LAYOUT_NAME = re.compile(r"[A-Za-z0-9_-]{1,64}")
"""The name a project's custom layout is saved under (a URL path segment)."""

MAX_PROJECT_LAYOUTS = 32
"""Most custom layouts one project saves."""

_SCHEMA = """
CREATE TABLE IF NOT EXISTS projects (
    id            TEXT PRIMARY KEY,
    name          TEXT NOT NULL,
    created       TEXT NOT NULL,
    updated       TEXT NOT NULL,
    mesh_filename TEXT,              -- as uploaded, for display only
    mesh_format   TEXT,              -- one of MESH_EXTENSIONS, NULL = no mesh
    n_vertices    INTEGER,
    n_faces       INTEGER,
    layout        TEXT,              -- landmark layout name ('' = none given)
    n_landmarks   INTEGER,           -- NULL = no landmarks
    rig_method    TEXT,              -- NULL = no rig
    revision      INTEGER NOT NULL DEFAULT 0,  -- bumped when mesh or landmarks change
    settings      TEXT NOT NULL DEFAULT '{}',
    mesh_file     TEXT,              -- current file names in the project folder
    landmarks_file TEXT,
    rig_file      TEXT,              -- the automatic rig
    painted_file  TEXT,              -- rows painted over it, NULL = none
    rig_version   INTEGER NOT NULL DEFAULT 0,  -- bumped by every new rig, paint or reset
    rig_painted   INTEGER NOT NULL DEFAULT 0,  -- vertices whose rows differ from the automatic rig's
    previous_mesh TEXT,              -- JSON: the mesh and landmarks a mesh revision replaced, NULL = none
    muscles_file  TEXT,              -- the virtual muscles (JSON), NULL = none yet
    muscles_revision INTEGER,        -- the revision they were placed or saved on
    muscles_edited INTEGER NOT NULL DEFAULT 0, -- 1: saved by the user, not placed
    arkit_file    TEXT,              -- the 52 ARKit shapes (npz), NULL = none yet
    arkit_revision INTEGER,          -- the revision they were made for
    arkit_rig_version INTEGER,       -- the rig version they were made on, NULL = the default rig
    arkit_settings_file TEXT,        -- the user's ARKit settings (JSON), NULL = defaults
    stereo_calibration_file TEXT     -- the live stereo cameras' calibration (JSON), NULL = none
);
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS takes (
    id         TEXT PRIMARY KEY,
    project_id TEXT NOT NULL,
    name       TEXT NOT NULL,
    created    TEXT NOT NULL,
    source     TEXT NOT NULL,       -- what made it: markers, markerless, csv, c3d, live ...
    layout     TEXT,                -- layout of its point names, NULL = its own labels
    fps        REAL NOT NULL,
    n_frames   INTEGER NOT NULL,
    n_points   INTEGER NOT NULL,
    dims       INTEGER NOT NULL,
    duration   REAL NOT NULL,       -- seconds, untrimmed
    trim_start REAL NOT NULL DEFAULT 0,
    trim_stop  REAL,                -- NULL = to the end
    file       TEXT NOT NULL,
    upload_key TEXT                 -- the uploader's Idempotency-Key, NULL = none
);
CREATE INDEX IF NOT EXISTS takes_project ON takes(project_id);
CREATE TABLE IF NOT EXISTS layouts (
    project_id TEXT NOT NULL,
    name       TEXT NOT NULL,       -- the user's name for it, LAYOUT_NAME
    layout     TEXT NOT NULL,       -- the library's name, custom-<hash of the spec>
    n_points   INTEGER NOT NULL,
    spec       TEXT NOT NULL,       -- the validated spec JSON (retarget.custom_layouts)
    created    TEXT NOT NULL,
    updated    TEXT NOT NULL,
    PRIMARY KEY (project_id, name)
);
"""
_INDEXES = """
CREATE UNIQUE INDEX IF NOT EXISTS takes_upload_key ON takes(project_id, upload_key);
"""


class ProjectNotFound(LookupError):
    """No project with this id (or the id is malformed); the message names the id."""

    def __init__(self, project_id: str):
        super().__init__(f"no project with id {project_id!r}")
        self.project_id = project_id


class TakeNotFound(LookupError):
    """No take with this id in the project (or the id is malformed)."""

    def __init__(self, take_id: str):
        super().__init__(f"no take with id {take_id!r} in this project")
        self.take_id = take_id


class LayoutNotFound(LookupError):
    """No custom layout of this name in the project (or the name is malformed)."""

    def __init__(self, name: str):
        super().__init__(f"no custom layout named {name!r:.80} in this project")
        self.name = name


class StaleRig(RuntimeError):
    """A rig was computed for a mesh or landmarks that have changed since, or painted on
    a rig version that is no longer the current one."""

    @classmethod
    def painted_on(cls, version: int, current: int) -> "StaleRig":
        return cls(f"the rig changed (now version {current}) since version {version} that "
                   f"this edit was made on: reload the weights and paint again")


def _unique_name(db, name: str, project_id: str | None = None) -> str:
    """`name`, or when another project has it, `name (2)`, `name (3)`, ... the first free:
    two projects never share a name (an imported .glb beside its source, two windows
    making "Untitled 1" at once). Called inside the transaction that stores it."""
    taken = {row[0] for row in db.execute("SELECT name FROM projects WHERE id IS NOT ?", (project_id,))}
    if name not in taken:
        return name
    k = 2
    while f"{name} ({k})" in taken:
        k += 1
    return f"{name} ({k})"


def _preview_file(take_file: str) -> str:
    """The name of a take's first-frame JPEG beside its file ``take-<id>.npz``."""
    return take_file.removesuffix(".npz") + ".jpg"


def _mesh_bytes(mesh: Mesh) -> int:
    texture = mesh.material.base_color_texture if mesh.material is not None else None
    return len(texture or b"") + sum(array.nbytes for array in (
        mesh.vertices, mesh.faces, mesh.uv, mesh.normals) if array is not None)


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def write_atomic(path: Path, data: bytes | None = None, *, writer=None) -> None:
    """Write `data` (or call ``writer(file)``) to `path` atomically.

    A temporary file in the same folder is written, flushed and fsynced, then renamed
    over `path` (`os.replace` is atomic on POSIX and Windows), then the folder is
    fsynced so the rename itself survives a power cut.
    """
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=path.suffix)
    try:
        with os.fdopen(fd, "wb") as f:
            if writer is not None:
                writer(f)
            else:
                f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    _fsync_dir(path.parent)


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # folders cannot be opened on Windows
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


class ProjectStore:
    """Projects on disk under `data_dir`; safe to share between threads.

    Projects are returned as plain dicts (see `_project`), ready to serialise.
    """

    def __init__(self, data_dir: Path | str):
        self.data_dir = Path(data_dir)
        self.projects_dir = self.data_dir / "projects"
        self.projects_dir.mkdir(parents=True, exist_ok=True)
        # uploads waiting for a job (a video being tracked); a restart ends those jobs
        self.scratch_dir = self.data_dir / "scratch"
        shutil.rmtree(self.scratch_dir, ignore_errors=True)
        self.scratch_dir.mkdir()
        self._lock = threading.RLock()
        self._rig_cache: dict[Path, SkinWeights] = {}
        self._mesh_cache: dict[Path, Mesh] = {}
        self._db = sqlite3.connect(
            self.data_dir / "index.sqlite", check_same_thread=False, isolation_level=None
        )
        self._db.row_factory = sqlite3.Row
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=FULL")
        with self._transaction() as db:
            for statement in _SCHEMA.split(";"):
                if statement.strip():
                    db.execute(statement)
            self._upgrade(db)
            for statement in _INDEXES.split(";"):
                if statement.strip():
                    db.execute(statement)
        self._sweep_all()

    def _upgrade(self, db) -> None:
        """Index files from before per-revision file names: their fixed names become the
        row's file names."""
        columns = {row["name"] for row in db.execute("PRAGMA table_info(projects)")}
        for column in _FILE_COLUMNS:
            if column not in columns:
                db.execute(f"ALTER TABLE projects ADD COLUMN {column} TEXT")
        db.execute("UPDATE projects SET mesh_file = 'mesh.' || mesh_format "
                   "WHERE mesh_file IS NULL AND mesh_format IS NOT NULL")
        db.execute("UPDATE projects SET landmarks_file = 'landmarks.json' "
                   "WHERE landmarks_file IS NULL AND n_landmarks IS NOT NULL")
        db.execute("UPDATE projects SET rig_file = 'rig.npz' "
                   "WHERE rig_file IS NULL AND rig_method IS NOT NULL")
        for column in ("rig_version", "rig_painted"):
            if column not in columns:
                db.execute(f"ALTER TABLE projects ADD COLUMN {column} INTEGER NOT NULL DEFAULT 0")
        if "previous_mesh" not in columns:
            db.execute("ALTER TABLE projects ADD COLUMN previous_mesh TEXT")
        if "muscles_revision" not in columns:
            db.execute("ALTER TABLE projects ADD COLUMN muscles_revision INTEGER")
            db.execute("ALTER TABLE projects ADD COLUMN muscles_edited INTEGER NOT NULL DEFAULT 0")
        if "arkit_revision" not in columns:
            db.execute("ALTER TABLE projects ADD COLUMN arkit_revision INTEGER")
            db.execute("ALTER TABLE projects ADD COLUMN arkit_rig_version INTEGER")
        # a calibration saved before the store kept it, under the live router's fixed name
        for row in db.execute("SELECT id FROM projects WHERE stereo_calibration_file IS NULL").fetchall():
            if (self.folder(row["id"]) / "stereo-calibration.json").is_file():
                db.execute("UPDATE projects SET stereo_calibration_file = 'stereo-calibration.json' "
                           "WHERE id = ?", (row["id"],))
        if "upload_key" not in {row["name"] for row in db.execute("PRAGMA table_info(takes)")}:
            db.execute("ALTER TABLE takes ADD COLUMN upload_key TEXT")

    def _sweep(self, project_id: str, row: sqlite3.Row | None = None) -> None:
        """Delete the store's files in the project's folder that its row does not name:
        files replaced by the last commit, or left by a crash before a commit."""
        folder = self.folder(project_id)
        with self._lock:
            row = row if row is not None else self._db.execute(
                "SELECT * FROM projects WHERE id = ?", (project_id,)).fetchone()
            if row is None:
                return
            keep = {row[column] for column in _FILE_COLUMNS}
            if row["previous_mesh"] is not None:
                previous = json.loads(row["previous_mesh"])
                keep.update((previous["mesh_file"], previous["landmarks_file"]))
            for r in self._db.execute("SELECT file FROM takes WHERE project_id = ?", (project_id,)):
                keep.update((r["file"], _preview_file(r["file"])))
            for path in folder.iterdir() if folder.is_dir() else ():
                if path.is_file() and path.name not in keep and (
                        _FILE_PATTERN.fullmatch(path.name) or _TAKE_FILE.fullmatch(path.name)):
                    path.unlink(missing_ok=True)

    def _sweep_all(self) -> None:
        with self._lock:
            ids = [row["id"] for row in self._db.execute("SELECT id FROM projects")]
        for project_id in ids:
            self._sweep(project_id)

    # -- plumbing -----------------------------------------------------------------------

    def _transaction(self):
        store = self

        class _Tx:
            def __enter__(self):
                store._lock.acquire()
                store._db.execute("BEGIN IMMEDIATE")
                return store._db

            def __exit__(self, exc_type, exc, tb):
                try:
                    store._db.execute("ROLLBACK" if exc_type else "COMMIT")
                finally:
                    store._lock.release()
                return False

        return _Tx()

    def close(self) -> None:
        with self._lock:
            self._db.close()

    def scratch_file(self, extension: str) -> Path:
        """A fresh, unguessable path in the scratch folder with an allow-listed
        `extension` (the caller deletes it when done)."""
        if not re.fullmatch(r"[a-z0-9]{1,5}", extension):
            raise ValueError(f"bad scratch file extension {extension!r}")
        return self.scratch_dir / f"{secrets.token_urlsafe(16)}.{extension}"

    def folder(self, project_id: str) -> Path:
        """The project's folder; raises `ProjectNotFound` for a malformed id, before
        the id touches any path."""
        if not isinstance(project_id, str) or not ID_PATTERN.fullmatch(project_id):
            raise ProjectNotFound(project_id)
        return self.projects_dir / project_id

    def _row(self, project_id: str) -> sqlite3.Row:
        self.folder(project_id)  # validates
        row = self._db.execute("SELECT * FROM projects WHERE id = ?", (project_id,)).fetchone()
        if row is None:
            raise ProjectNotFound(project_id)
        return row

    @staticmethod
    def _project(row: sqlite3.Row) -> dict:
        mesh = None
        if row["mesh_format"] is not None:
            mesh = {
                "filename": row["mesh_filename"],
                "format": row["mesh_format"],
                "n_vertices": row["n_vertices"],
                "n_faces": row["n_faces"],
            }
        landmarks = None
        if row["n_landmarks"] is not None:
            landmarks = {"layout": row["layout"], "n_points": row["n_landmarks"]}
        previous = None
        if row["previous_mesh"] is not None:
            kept = json.loads(row["previous_mesh"])
            previous = {"n_vertices": kept["n_vertices"], "n_faces": kept["n_faces"]}
        return {
            "id": row["id"],
            "name": row["name"],
            "created": row["created"],
            "updated": row["updated"],
            "mesh": mesh,
            "landmarks": landmarks,
            "rig": None if row["rig_method"] is None else {"method": row["rig_method"]},
            "revision": row["revision"],
            "settings": json.loads(row["settings"]),
            "previous_mesh": previous,
        }

    # -- meta ---------------------------------------------------------------------------

    def meta(self, key: str) -> str | None:
        with self._lock:
            row = self._db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return None if row is None else row["value"]

    def set_meta(self, key: str, value: str) -> None:
        with self._transaction() as db:
            db.execute("INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)", (key, value))

    # -- projects -----------------------------------------------------------------------

    def create(self, name: str, settings: dict | None = None) -> dict:
        """A new empty project; its name made unique (`_unique_name`)."""
        project_id = secrets.token_urlsafe(16)
        folder = self.folder(project_id)
        folder.mkdir(parents=True, exist_ok=False)
        now = _now()
        with self._transaction() as db:
            db.execute(
                "INSERT INTO projects (id, name, created, updated, settings) "
                "VALUES (?, ?, ?, ?, ?)",
                (project_id, _unique_name(db, name), now, now, json.dumps(settings or {})),
            )
        return self.get(project_id)

    def list(self) -> list[dict]:
        with self._lock:
            rows = self._db.execute("SELECT * FROM projects ORDER BY created, id").fetchall()
        return [self._project(r) for r in rows]

    def get(self, project_id: str) -> dict:
        with self._lock:
            return self._project(self._row(project_id))

    def update(self, project_id: str, *, name: str | None = None,
               settings: dict | None = None) -> dict:
        """Rename (to a name made unique, `_unique_name`) and/or shallow-merge `settings`
        (a key set to None is removed)."""
        with self._transaction() as db:
            row = self._row(project_id)
            if name is not None and name != row["name"]:
                name = _unique_name(db, name, project_id)
            merged = json.loads(row["settings"])
            for key, value in (settings or {}).items():
                if value is None:
                    merged.pop(key, None)
                else:
                    merged[key] = value
            db.execute(
                "UPDATE projects SET name = ?, settings = ?, updated = ? WHERE id = ?",
                (row["name"] if name is None else name, json.dumps(merged), _now(),
                 project_id),
            )
        return self.get(project_id)

    def delete(self, project_id: str) -> None:
        folder = self.folder(project_id)
        with self._transaction() as db:
            self._row(project_id)
            db.execute("DELETE FROM takes WHERE project_id = ?", (project_id,))
            db.execute("DELETE FROM layouts WHERE project_id = ?", (project_id,))
            db.execute("DELETE FROM projects WHERE id = ?", (project_id,))
        # after the commit: a crash here leaves an orphan folder, never a dangling row
        shutil.rmtree(folder, ignore_errors=True)

    # -- mesh ---------------------------------------------------------------------------

    def put_mesh(self, project_id: str, data: bytes, extension: str, *, filename: str,
                 n_vertices: int, n_faces: int) -> dict:
        """Store an (already validated) mesh upload; drops the landmarks and rig, whose
        vertex indices referred to the previous mesh."""
        if extension not in MESH_EXTENSIONS:
            raise ValueError(f"extension {extension!r} is not one of {MESH_EXTENSIONS}")
        folder = self.folder(project_id)
        with self._transaction() as db:
            old = self._row(project_id)
            name = f"mesh-r{old['revision'] + 1}.{extension}"
            write_atomic(folder / name, data)
            db.execute(
                "UPDATE projects SET mesh_filename = ?, mesh_format = ?, n_vertices = ?, "
                "n_faces = ?, layout = NULL, n_landmarks = NULL, rig_method = NULL, "
                "mesh_file = ?, landmarks_file = NULL, rig_file = NULL, painted_file = NULL, "
                "rig_painted = 0, previous_mesh = NULL, "
                "revision = revision + 1, updated = ? WHERE id = ?",
                (filename[:255], extension, n_vertices, n_faces, name, _now(), project_id),
            )
        self._sweep(project_id)
        return self.get(project_id)

    def put_mesh_revision(self, project_id: str, data: bytes, extension: str, *, filename: str,
                          n_vertices: int, n_faces: int, landmarks: dict, n_points: int,
                          revision: int) -> dict:
        """Store a mesh made from the mesh and landmarks of `revision` (already validated)
        with its landmarks; the replaced mesh and landmarks are kept for `revert_mesh`.
        Drops the rig, as any new mesh does. Raises `StaleRig` if the mesh or landmarks
        changed since `revision`."""
        if extension not in MESH_EXTENSIONS:
            raise ValueError(f"extension {extension!r} is not one of {MESH_EXTENSIONS}")
        folder = self.folder(project_id)
        with self._transaction() as db:
            old = self._row(project_id)
            if old["revision"] != revision or old["n_landmarks"] is None:
                raise StaleRig("the mesh or landmarks changed meanwhile; try again")
            mesh_name = f"mesh-r{revision + 1}.{extension}"
            landmarks_name = f"landmarks-r{revision + 1}.json"
            write_atomic(folder / mesh_name, data)
            write_atomic(folder / landmarks_name, json.dumps(landmarks).encode())
            previous = {key: old[key] for key in (
                "mesh_file", "landmarks_file", "mesh_filename", "mesh_format", "n_vertices",
                "n_faces", "layout", "n_landmarks")}
            db.execute(
                "UPDATE projects SET mesh_filename = ?, mesh_format = ?, n_vertices = ?, "
                "n_faces = ?, n_landmarks = ?, rig_method = NULL, mesh_file = ?, "
                "landmarks_file = ?, rig_file = NULL, painted_file = NULL, rig_painted = 0, "
                "previous_mesh = ?, revision = revision + 1, updated = ? WHERE id = ?",
                (filename[:255], extension, n_vertices, n_faces, n_points, mesh_name,
                 landmarks_name, json.dumps(previous), _now(), project_id),
            )
        self._sweep(project_id)
        return self.get(project_id)

    def revert_mesh(self, project_id: str) -> dict:
        """Go back to the mesh and landmarks the last `put_mesh_revision` replaced (as a
        new revision: the rig is dropped). Raises `StaleRig` when there is none."""
        with self._transaction() as db:
            row = self._row(project_id)
            if row["previous_mesh"] is None:
                raise StaleRig(f"project {project_id!r} has no earlier mesh to go back to")
            previous = json.loads(row["previous_mesh"])
            db.execute(
                "UPDATE projects SET mesh_file = ?, landmarks_file = ?, mesh_filename = ?, "
                "mesh_format = ?, n_vertices = ?, n_faces = ?, layout = ?, n_landmarks = ?, "
                "rig_method = NULL, rig_file = NULL, painted_file = NULL, rig_painted = 0, "
                "previous_mesh = NULL, revision = revision + 1, updated = ? WHERE id = ?",
                (*(previous[key] for key in (
                    "mesh_file", "landmarks_file", "mesh_filename", "mesh_format", "n_vertices",
                    "n_faces", "layout", "n_landmarks")), _now(), project_id),
            )
        self._sweep(project_id)
        return self.get(project_id)

    def mesh_file(self, project_id: str) -> tuple[Path, str] | None:
        """(path, extension) of the stored mesh, or None when there is none."""
        with self._lock:
            row = self._row(project_id)
            if row["mesh_format"] is None:
                return None
            return self.folder(project_id) / row["mesh_file"], row["mesh_format"]

    def mesh(self, project_id: str) -> Mesh | None:
        """The stored mesh parsed by `retarget.mesh.load_mesh`, or None when there is none.

        Parsed from bytes, as the upload was checked: no resolver, so nothing beside the
        file is read."""
        with self._lock:  # a replacing upload deletes the old file after its commit
            found = self.mesh_file(project_id)
            if found is None:
                return None
            path, ext = found
            mesh = self._mesh_cache.get(path)
            data = None if mesh is not None else path.read_bytes()
        if mesh is None:
            mesh = load_mesh(data, ext)
        self._remember_mesh(path, mesh)
        return mesh

    def _remember_mesh(self, path: Path, mesh: Mesh) -> None:
        """Keep `mesh` for the next read of `path`: a mesh file is never rewritten under its
        name and a `Mesh` is read-only, while parsing the stored file again cost every
        request on a project's mesh tens of milliseconds of the server's CPU."""
        with self._lock:
            self._mesh_cache.pop(path, None)
            self._mesh_cache[path] = mesh  # most recent last
            while len(self._mesh_cache) > 1 and sum(
                    _mesh_bytes(m) for m in self._mesh_cache.values()) > _MESH_CACHE_BYTES:
                self._mesh_cache.pop(next(iter(self._mesh_cache)))

    # -- landmarks ----------------------------------------------------------------------

    def put_landmarks(self, project_id: str, landmarks: dict, *, n_points: int,
                      layout: str, revision: int) -> dict:
        """Store (already validated) landmarks JSON for the mesh of `revision`; drops
        the rig. Raises `StaleRig` if the mesh changed since `revision`."""
        with self._transaction() as db:
            row = self._row(project_id)
            if row["revision"] != revision:
                raise StaleRig("the mesh changed while the landmarks were checked; send them again")
            self._write_landmarks(db, project_id, landmarks, n_points=n_points, layout=layout,
                                  revision=revision)
        self._sweep(project_id)
        return self.get(project_id)

    def _write_landmarks(self, db, project_id: str, landmarks: dict, *, n_points: int, layout: str,
                         revision: int) -> None:
        """Inside a transaction: the landmarks of the next revision, the rig dropped."""
        name = f"landmarks-r{revision + 1}.json"
        write_atomic(self.folder(project_id) / name, json.dumps(landmarks).encode())
        db.execute(
            "UPDATE projects SET layout = ?, n_landmarks = ?, rig_method = NULL, "
            "landmarks_file = ?, rig_file = NULL, painted_file = NULL, rig_painted = 0, "
            "revision = revision + 1, updated = ? WHERE id = ?",
            (layout, n_points, name, _now(), project_id),
        )

    def put_found_landmarks(self, project_id: str, landmarks: dict, *, n_points: int,
                            layout: str, revision: int, replace: bool = False) -> str | None:
        """Store landmarks found with no clicks for the mesh of `revision`, unless that
        would overwrite someone's work; None when stored, else why not (a sentence).

        Never stored over: a mesh or landmarks changed since `revision`; unless `replace`
        (the user asked for it), landmarks saved by hand (found ones carry their
        ``"confidence"``) or the page's unsaved points for this mesh (the project's
        settings ``"draft"``: ``{revision, layout, points}``). Checked in the transaction
        that stores, so an edit saved meanwhile always wins."""
        folder = self.folder(project_id)
        with self._transaction() as db:
            row = self._row(project_id)
            if row["revision"] != revision:
                return "the mesh or its landmarks changed while the points were being found"
            if not replace:
                if row["n_landmarks"] is not None and "confidence" not in json.loads(
                        (folder / row["landmarks_file"]).read_text()):
                    return "the project has landmarks placed by hand"
                draft = json.loads(row["settings"]).get("draft")
                if isinstance(draft, dict) and draft.get("revision") == revision:
                    return "points are being placed by hand on this mesh"
            self._write_landmarks(db, project_id, landmarks, n_points=n_points, layout=layout,
                                  revision=revision)
        self._sweep(project_id)
        return None

    def landmarks(self, project_id: str) -> dict | None:
        with self._lock:
            row = self._row(project_id)
            if row["n_landmarks"] is None:
                return None
            return json.loads((self.folder(project_id) / row["landmarks_file"]).read_text())

    # -- rig ----------------------------------------------------------------------------

    def put_rig(self, project_id: str, weights: SkinWeights, *, revision: int) -> dict:
        """Store an automatic rig computed from the mesh and landmarks of `revision`
        (its painted rows go); raises `StaleRig` if either changed since."""
        folder = self.folder(project_id)
        with self._transaction() as db:
            row = self._row(project_id)
            if row["revision"] != revision:
                raise StaleRig(
                    "the mesh or landmarks changed while the rig was computed; start it again"
                )
            # a rig may be recomputed at the same revision (another method): new name each time
            name = f"rig-r{revision}-{secrets.token_hex(4)}.npz"
            # on the grid of the page's download (RTSW version 2): its copy is the stored rig
            weights = quantised_weights(weights)
            write_atomic(folder / name, writer=weights.save)
            db.execute(
                "UPDATE projects SET rig_method = ?, rig_file = ?, painted_file = NULL, "
                "rig_version = rig_version + 1, rig_painted = 0, updated = ? WHERE id = ?",
                (weights.method, name, _now(), project_id),
            )
        self._sweep(project_id)
        return self.get(project_id)

    def put_painting(self, project_id: str, painted: WeightEdit | None, *, version: int) -> dict:
        """Store the rows painted over the automatic rig (`painted_rows`; None or no rows:
        the automatic rig again). `version` is the rig version the paint was made on;
        raises `StaleRig` if the rig changed since. Answers `rig_status`."""
        folder = self.folder(project_id)
        with self._transaction() as db:
            row = self._row(project_id)
            if row["rig_method"] is None:
                raise StaleRig(f"project {project_id!r} has no rig any more")
            if row["rig_version"] != version:
                raise StaleRig.painted_on(version, row["rig_version"])
            name = None
            if painted is not None and painted.n_rows:
                name = f"paint-r{row['revision']}-{secrets.token_hex(4)}.npz"
                write_atomic(folder / name, writer=painted.save)
            n_painted = 0 if name is None else painted.n_rows
            db.execute(
                "UPDATE projects SET painted_file = ?, rig_version = rig_version + 1, "
                "rig_painted = ?, updated = ? WHERE id = ?",
                (name, n_painted, _now(), project_id),
            )
            # the status this paint made, from inside its transaction: read afterwards, a
            # concurrent landmark edit may already have dropped the rig (a 500 under fuzzing)
            status = {"version": row["rig_version"] + 1, "painted_vertices": n_painted}
        self._sweep(project_id)
        return status

    def rig(self, project_id: str) -> SkinWeights | None:
        """The rig in use (the automatic rig with its painted rows), or None."""
        found = self.rigs(project_id)
        return None if found is None else found[0]

    def rigs(self, project_id: str) -> tuple[SkinWeights, SkinWeights, int] | None:
        """(rig in use, automatic rig, rig version) read together, or None without a rig."""
        with self._lock:
            row = self._row(project_id)
            if row["rig_method"] is None:
                return None
            folder = self.folder(project_id)
            automatic = self._automatic_rig(folder / row["rig_file"])
            painted = None if row["painted_file"] is None else WeightEdit.load(folder / row["painted_file"])
            version = row["rig_version"]
        current = automatic if painted is None else painted_rig(automatic, painted)
        return current, automatic, version

    def _automatic_rig(self, path: Path) -> SkinWeights:
        """`SkinWeights.load(path)`, from memory when it was read lately (a rig file is
        never rewritten under its name; painting reads the automatic rig on every save)."""
        rig = self._rig_cache.pop(path, None)
        if rig is None:
            rig = SkinWeights.load(path)
            for array in (rig.indices, rig.weights):
                array.flags.writeable = False  # shared: a change would reach later readers
        self._rig_cache[path] = rig  # most recent last
        while len(self._rig_cache) > 1 and sum(
                r.indices.nbytes + r.weights.nbytes for r in self._rig_cache.values()) > _RIG_CACHE_BYTES:
            self._rig_cache.pop(next(iter(self._rig_cache)))
        return rig

    def rig_status(self, project_id: str) -> dict | None:
        """``{version, painted_vertices}`` of the rig, or None when there is none."""
        with self._lock:
            row = self._row(project_id)
        if row["rig_method"] is None:
            return None
        return {"version": row["rig_version"], "painted_vertices": row["rig_painted"]}

    # -- muscles ------------------------------------------------------------------------

    def put_muscles(self, project_id: str, muscles: dict, *, revision: int, edited: bool) -> bool:
        """Store (already validated) muscle JSON made for the mesh and landmarks of
        `revision`: `edited` by the user, or placed automatically. False, and nothing
        stored, when placed muscles would replace ones the user saved for this revision;
        raises `StaleRig` when the mesh or landmarks changed since `revision`."""
        with self._transaction() as db:
            row = self._row(project_id)
            if row["revision"] != revision:
                raise StaleRig("the mesh or landmarks changed while the muscles were made; make them again")
            if not edited and row["muscles_edited"] and row["muscles_revision"] == revision:
                return False
            name = f"muscles-r{revision}-{secrets.token_hex(4)}.json"
            write_atomic(self.folder(project_id) / name, json.dumps(muscles).encode())
            db.execute("UPDATE projects SET muscles_file = ?, muscles_revision = ?, muscles_edited = ?, "
                       "updated = ? WHERE id = ?", (name, revision, int(edited), _now(), project_id))
        self._sweep(project_id)
        return True

    def muscles(self, project_id: str) -> tuple[dict, int, bool] | None:
        """(muscle JSON, the revision it was made for, whether the user saved it), or None."""
        with self._lock:
            row = self._row(project_id)
            if row["muscles_file"] is None:
                return None
            data = json.loads((self.folder(project_id) / row["muscles_file"]).read_text())
            return data, row["muscles_revision"], bool(row["muscles_edited"])

    # -- ARKit shapes and settings -------------------------------------------------------

    def put_arkit_shapes(self, project_id: str, shapes: ArkitShapes, *, revision: int,
                         rig_version: int | None) -> None:
        """Store the ARKit shapes made from the mesh and landmarks of `revision` (and the
        rig at `rig_version`, None for the default rig); raises `StaleRig` when the mesh or
        landmarks (or that rig) changed since."""
        with self._transaction() as db:
            row = self._row(project_id)
            if row["revision"] != revision:
                raise StaleRig("the mesh or landmarks changed while the ARKit shapes were made; make them again")
            if rig_version is not None and (row["rig_method"] is None or row["rig_version"] != rig_version):
                raise StaleRig("the rig changed while the ARKit shapes were made on it; make them again")
            name = f"arkit-r{revision}-{secrets.token_hex(4)}.npz"
            write_atomic(self.folder(project_id) / name, writer=shapes.save)
            db.execute("UPDATE projects SET arkit_file = ?, arkit_revision = ?, arkit_rig_version = ?, "
                       "updated = ? WHERE id = ?", (name, revision, rig_version, _now(), project_id))
        self._sweep(project_id)

    def arkit_status(self, project_id: str) -> dict | None:
        """``{revision, rig_version}`` the stored shapes were made for, or None without any."""
        with self._lock:
            row = self._row(project_id)
        if row["arkit_file"] is None:
            return None
        return {"revision": row["arkit_revision"], "rig_version": row["arkit_rig_version"]}

    def arkit_shapes(self, project_id: str) -> ArkitShapes | None:
        """The stored ARKit shapes (whatever revision they were made for: `arkit_status`),
        or None."""
        with self._lock:
            row = self._row(project_id)
            if row["arkit_file"] is None:
                return None
            return ArkitShapes.load(self.folder(project_id) / row["arkit_file"])

    def put_arkit_settings(self, project_id: str, settings: dict) -> None:
        """Store the user's (already validated) ARKit settings JSON."""
        self._put_json(project_id, "arkit_settings_file", "arkit-settings", settings)

    def arkit_settings(self, project_id: str) -> dict | None:
        """The user's ARKit settings JSON, or None when never saved."""
        return self._json(project_id, "arkit_settings_file")

    def put_stereo_calibration(self, project_id: str, calibration: dict) -> None:
        """Store the live stereo cameras' calibration JSON (`StereoCalibration.to_dict`);
        it belongs to the project's capture set-up and outlives mesh and landmark changes."""
        self._put_json(project_id, "stereo_calibration_file", "stereo-calibration", calibration)

    def stereo_calibration(self, project_id: str) -> dict | None:
        """The live stereo calibration JSON, or None when never saved."""
        return self._json(project_id, "stereo_calibration_file")

    def _put_json(self, project_id: str, column: str, stem: str, data: dict) -> None:
        """A project-level JSON document (one the user's edits of mesh and landmarks leave
        alone) written to a new file ``stem-<hex>.json`` named in `column`; the old one swept."""
        with self._transaction() as db:
            self._row(project_id)
            name = f"{stem}-{secrets.token_hex(4)}.json"
            write_atomic(self.folder(project_id) / name, json.dumps(data).encode())
            db.execute(f"UPDATE projects SET {column} = ?, updated = ? WHERE id = ?", (name, _now(), project_id))
        self._sweep(project_id)

    def _json(self, project_id: str, column: str) -> dict | None:
        """The document `_put_json` wrote to `column`, or None."""
        with self._lock:
            row = self._row(project_id)
            if row[column] is None:
                return None
            return json.loads((self.folder(project_id) / row[column]).read_text())

    # -- takes --------------------------------------------------------------------------

    @staticmethod
    def _take_info(row: sqlite3.Row) -> dict:
        stop = row["duration"] if row["trim_stop"] is None else row["trim_stop"]
        return {
            "id": row["id"], "name": row["name"], "created": row["created"],
            "source": row["source"], "layout": row["layout"], "fps": row["fps"],
            "n_frames": row["n_frames"], "n_points": row["n_points"], "dims": row["dims"],
            "duration": row["duration"], "trim": [row["trim_start"], stop],
        }

    def _take_row(self, project_id: str, take_id: str) -> sqlite3.Row:
        self._row(project_id)
        if not isinstance(take_id, str) or not TAKE_ID_PATTERN.fullmatch(take_id):
            raise TakeNotFound(take_id)
        row = self._db.execute("SELECT * FROM takes WHERE id = ? AND project_id = ?",
                               (take_id, project_id)).fetchone()
        if row is None:
            raise TakeNotFound(take_id)
        return row

    def put_take(self, project_id: str, take: Take, *, name: str, key: str | None = None,
                 preview: bytes | None = None) -> dict:
        """Store a new take (an already validated `Take`); answers its info. With `key`
        (the uploader's Idempotency-Key) a take already stored under that key in the
        project is answered instead, and nothing is stored twice. `preview`: the JPEG of
        a tracked video's first frame, kept with the take (`take_preview`)."""
        folder = self.folder(project_id)
        take_id = secrets.token_urlsafe(12)
        file = f"take-{take_id}.npz"
        times = take.frame_times()
        duration = float(times[-1] - times[0]) if len(times) else 0.0
        with self._transaction() as db:
            self._row(project_id)
            earlier = self._keyed_take(project_id, key)
            if earlier is not None:
                return self._take_info(earlier)
            write_atomic(folder / file, writer=take.save)
            if preview is not None:
                write_atomic(folder / _preview_file(file), preview)
            db.execute(
                "INSERT INTO takes (id, project_id, name, created, source, layout, fps, n_frames, "
                "n_points, dims, duration, file, upload_key) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (take_id, project_id, name[:255], _now(), take.source or "", take.layout,
                 float(take.fps), take.n_frames, take.n_points, take.dims, duration, file, key))
        return self.take_info(project_id, take_id)

    def keyed_take(self, project_id: str, key: str | None) -> dict | None:
        """The info of the project's take stored under upload key `key`, or None."""
        with self._lock:
            self._row(project_id)
            row = self._keyed_take(project_id, key)
        return None if row is None else self._take_info(row)

    def _keyed_take(self, project_id: str, key: str | None) -> sqlite3.Row | None:
        if key is None:
            return None
        return self._db.execute("SELECT * FROM takes WHERE project_id = ? AND upload_key = ?",
                                (project_id, key)).fetchone()

    def takes(self, project_id: str) -> list[dict]:
        """The project's takes, oldest first."""
        with self._lock:
            self._row(project_id)
            rows = self._db.execute("SELECT * FROM takes WHERE project_id = ? ORDER BY created, id",
                                    (project_id,)).fetchall()
        return [self._take_info(r) for r in rows]

    def take_info(self, project_id: str, take_id: str) -> dict:
        with self._lock:
            return self._take_info(self._take_row(project_id, take_id))

    def take(self, project_id: str, take_id: str, *, trimmed: bool = True) -> Take:
        """The stored take, trimmed to its row's span unless `trimmed` is False."""
        with self._lock:
            row = self._take_row(project_id, take_id)
            take = Take.load(self.folder(project_id) / row["file"])
        if trimmed and (row["trim_start"] > 0 or row["trim_stop"] is not None):
            take = take.trimmed(row["trim_start"], row["trim_stop"])
        return take

    def take_preview(self, project_id: str, take_id: str) -> bytes | None:
        """The JPEG of the first frame of the video the take was tracked from, or None."""
        with self._lock:
            row = self._take_row(project_id, take_id)
            path = self.folder(project_id) / _preview_file(row["file"])
            return path.read_bytes() if path.is_file() else None

    def update_take(self, project_id: str, take_id: str, *, name: str | None = None,
                    trim: tuple[float, float | None] | None = None) -> dict:
        """Rename and/or set the trimmed span (seconds from the take's first frame; an
        already validated span)."""
        with self._transaction() as db:
            row = self._take_row(project_id, take_id)
            start, stop = (row["trim_start"], row["trim_stop"]) if trim is None else trim
            db.execute("UPDATE takes SET name = ?, trim_start = ?, trim_stop = ? WHERE id = ?",
                       (row["name"] if name is None else name[:255], start, stop, take_id))
        return self.take_info(project_id, take_id)

    def delete_take(self, project_id: str, take_id: str) -> None:
        with self._transaction() as db:
            row = self._take_row(project_id, take_id)
            db.execute("DELETE FROM takes WHERE id = ?", (take_id,))
        for file in (row["file"], _preview_file(row["file"])):  # after the commit
            (self.folder(project_id) / file).unlink(missing_ok=True)

    # -- custom layouts -----------------------------------------------------------------

    @staticmethod
    def _layout_info(row: sqlite3.Row) -> dict:
        return {"name": row["name"], "layout": row["layout"], "n_points": row["n_points"],
                "created": row["created"], "updated": row["updated"]}

    def put_layout(self, project_id: str, name: str, spec: dict, *, layout: str,
                   n_points: int) -> tuple[dict, bool]:
        """Save an (already validated) custom layout spec as `name`, replacing one of that
        name; answers its info and whether it is new. Raises `LayoutNotFound` for a
        malformed name and `ValueError` when the project has `MAX_PROJECT_LAYOUTS`."""
        if not isinstance(name, str) or not LAYOUT_NAME.fullmatch(name):
            raise LayoutNotFound(name)
        now = _now()
        with self._transaction() as db:
            self._row(project_id)
            old = db.execute("SELECT created FROM layouts WHERE project_id = ? AND name = ?",
                             (project_id, name)).fetchone()
            if old is None:
                count = db.execute("SELECT COUNT(*) FROM layouts WHERE project_id = ?",
                                   (project_id,)).fetchone()[0]
                if count >= MAX_PROJECT_LAYOUTS:
                    raise ValueError(f"the project has {count} custom layouts, the most it may "
                                     "save: delete one first")
            db.execute(
                "INSERT OR REPLACE INTO layouts (project_id, name, layout, n_points, spec, created, "
                "updated) VALUES (?, ?, ?, ?, ?, ?, ?)",
                (project_id, name, layout, n_points, json.dumps(spec),
                 now if old is None else old["created"], now))
        return self.layout(project_id, name)[0], old is None

    def layouts(self, project_id: str) -> list[dict]:
        """The project's custom layouts' infos, by name."""
        with self._lock:
            self._row(project_id)
            rows = self._db.execute("SELECT * FROM layouts WHERE project_id = ? ORDER BY name",
                                    (project_id,)).fetchall()
        return [self._layout_info(r) for r in rows]

    def layout(self, project_id: str, name: str) -> tuple[dict, dict]:
        """(info, spec) of the project's custom layout saved as `name` or whose library
        name (``custom-<hash>``) is `name`; raises `LayoutNotFound`."""
        if not isinstance(name, str) or not LAYOUT_NAME.fullmatch(name):
            raise LayoutNotFound(name)
        with self._lock:
            self._row(project_id)
            row = self._db.execute(
                "SELECT * FROM layouts WHERE project_id = ? AND (name = ? OR layout = ?) "
                "ORDER BY name = ? DESC LIMIT 1", (project_id, name, name, name)).fetchone()
        if row is None:
            raise LayoutNotFound(name)
        return self._layout_info(row), json.loads(row["spec"])

    def delete_layout(self, project_id: str, name: str) -> None:
        if not isinstance(name, str) or not LAYOUT_NAME.fullmatch(name):
            raise LayoutNotFound(name)
        with self._transaction() as db:
            self._row(project_id)
            if db.execute("DELETE FROM layouts WHERE project_id = ? AND name = ?",
                          (project_id, name)).rowcount == 0:
                raise LayoutNotFound(name)
