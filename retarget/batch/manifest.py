"""The batch manifest: a YAML or JSON file read into checked, typed entries.

    version: 1
    outputs: [gltf, arkit_csv, npy]      # what each pair makes (default: [gltf])
    gltf: {form: skin, rate: 24, key_tolerance: 0.05}   # the .glb's rig form, key rate and
                                         # key reduction in mm (`retarget.gltf.write_gltf`;
                                         # default: exact, the take's frames, every key)
    characters:
      - name: alice                      # a folder name: letters, digits, . _ -
        mesh: alice.obj                  # a mesh and its landmarks JSON ...
        landmarks: alice.json
        layout: ibug68                   # default: the landmarks JSON's own; or a custom
                                         # layout file ('retarget layouts new')
        rig: {deformer: ellipsoid, k: 4, kernel: ..., smoothing: ...}   # or rig: RIG.npz
      - name: bob
        project: bob.glb                 # ... or a project exported from the app
    takes:
      - name: smile
        file: smile.csv                  # any file the app imports
        settings: {filter: one_euro}     # ConditionSettings JSON, or a JSON file of it
        regions: [mouth]                 # partial retargeting (default: all)
        fps: 30                          # mapping, labelled_vertices: as `retarget condition`
                                         # (a mapping, or a JSON file of one)
    pairs: all                           # or [{character: alice, take: smile}, ...]

Paths are relative to the manifest's folder. Only the manifest's structure is checked
here (names, keys, types, settings): a missing or unreadable mesh or take fails its own
pairs when they run, never the batch. Every refusal is a `RetargetError` naming the entry
(``characters[2] ('bob'): ...``).
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

from retarget.custom_layouts import load_layout_file
from retarget.errors import RetargetError
from retarget.layouts import LAYOUTS
from retarget.pipeline import DEFAULT_KERNEL
from retarget.rbf import KERNELS
from retarget.sources.conditioning import ConditionSettings
from retarget.weights import DEFAULT_METHOD, METHODS

__all__ = ["MAX_CHARACTERS", "MAX_MANIFEST_BYTES", "MAX_PAIRS", "MAX_TAKES", "OUTPUTS", "Character",
           "Manifest", "RigSettings", "TakeEntry", "manifest_from_dict", "read_manifest"]

OUTPUTS = {"gltf": "animation.glb", "arkit_csv": "arkit.csv", "npy": "vertices.npy"}
"""Output kind -> file name in ``OUT/<character>/<take>/``."""

# bounds: a manifest is written by people or the app; past these it is a mistake, and the
# plan's index (one JSON) stays small
MAX_MANIFEST_BYTES = 4 * 2**20
MAX_CHARACTERS = 1_000
MAX_TAKES = 10_000
MAX_PAIRS = 100_000
MAX_NAME = 100

_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9._-]*$")


@dataclass(frozen=True)
class RigSettings:
    """How a character is rigged and its space transform fitted.

    deformer : a name of `retarget.weights.METHODS` (ignored with a rig file or a project).
    k : influences kept per vertex, None for the method's own.
    kernel, smoothing : the RBF space transform's (`retarget.pipeline.Retargeter`).
    """

    deformer: str = DEFAULT_METHOD
    k: int | None = None
    kernel: str = DEFAULT_KERNEL
    smoothing: float | None = None

    def to_dict(self) -> dict:
        return {"deformer": self.deformer, "k": self.k, "kernel": self.kernel, "smoothing": self.smoothing}


@dataclass(frozen=True)
class Character:
    """A target face: `mesh` + `landmarks` (+ `rig_file`), or an exported `project` (.glb).

    Paths are absolute (resolved against the manifest's folder).
    """

    name: str
    mesh: Path | None = None
    landmarks: Path | None = None
    project: Path | None = None
    rig_file: Path | None = None
    layout: str | None = None
    rig: RigSettings = field(default_factory=RigSettings)
    layout_spec: dict | None = None
    """A custom layout's spec (`layout` is then its ``custom-<hash>`` name): the workers
    register it, since a layout file is read here, where the manifest is."""

    def files(self) -> tuple[Path, ...]:
        """The input files whose bytes the character depends on."""
        return tuple(p for p in (self.mesh, self.landmarks, self.project, self.rig_file) if p is not None)


@dataclass(frozen=True)
class TakeEntry:
    """A performance file and how it is read and conditioned.

    settings : the `ConditionSettings` dict (checked), {} for the defaults.
    regions : names of the regions, groups or points that move, None for all.
    fps, mapping, labelled_vertices : as `retarget.sources.files.read_take`.
    """

    name: str
    file: Path
    settings: dict = field(default_factory=dict)
    regions: tuple[str, ...] | None = None
    fps: float | None = None
    mapping: dict | None = None
    labelled_vertices: dict | None = None

    def to_dict(self) -> dict:
        """Its settings (not the file), as the pair's hash covers them."""
        return {"settings": self.settings, "regions": self.regions, "fps": self.fps,
                "mapping": self.mapping, "labelled_vertices": self.labelled_vertices}


@dataclass(frozen=True)
class Manifest:
    """The checked manifest: characters, takes, the outputs each pair makes, and the pairs
    (character name, take name) in the order they are run."""

    path: Path
    characters: tuple[Character, ...]
    takes: tuple[TakeEntry, ...]
    outputs: tuple[str, ...]
    pairs: tuple[tuple[str, str], ...]
    gltf: dict = field(default_factory=dict)

    def character(self, name: str) -> Character:
        return next(c for c in self.characters if c.name == name)

    def take(self, name: str) -> TakeEntry:
        return next(t for t in self.takes if t.name == name)


def read_manifest(path) -> Manifest:
    """The manifest in the YAML (``.yaml``/``.yml``) or JSON file `path`; relative paths in
    it are taken from its folder."""
    path = Path(path)
    if not path.is_file():
        raise RetargetError(f"manifest {str(path)!r} {'is not a file' if path.exists() else 'does not exist'}")
    size = path.stat().st_size
    if size > MAX_MANIFEST_BYTES:
        raise RetargetError(f"manifest {str(path)!r} is {size} bytes, over the limit of {MAX_MANIFEST_BYTES}")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise RetargetError(f"could not read manifest {str(path)!r}: {exc}") from None
    if path.suffix.lower() in (".yaml", ".yml"):
        import yaml

        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise RetargetError(f"manifest {str(path)!r} is not valid YAML: {exc}") from None
    else:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise RetargetError(f"manifest {str(path)!r} is not valid JSON: {exc}") from None
    return manifest_from_dict(data, path.resolve().parent, path=path)


def manifest_from_dict(data, folder, *, path=None) -> Manifest:
    """The `Manifest` of parsed YAML/JSON `data`; relative paths are taken from `folder`."""
    folder = Path(folder)
    where = f"manifest {str(path)!r}" if path is not None else "manifest"
    if not isinstance(data, dict):
        raise RetargetError(f"{where} must be a mapping with 'characters' and 'takes'")
    _known(data, {"version", "outputs", "gltf", "characters", "takes", "pairs"}, where)
    if data.get("version", 1) != 1:
        raise RetargetError(f"{where}: version {data.get('version')!r} is not supported (only 1)")
    outputs = data.get("outputs", ["gltf"])
    if isinstance(outputs, str):
        outputs = [outputs]
    if not isinstance(outputs, list) or not outputs or any(o not in OUTPUTS for o in outputs):
        raise RetargetError(f"{where}: outputs must be a list of {', '.join(OUTPUTS)}; got {outputs!r}")
    characters = tuple(_character(entry, i, folder) for i, entry in
                       enumerate(_entries(data, "characters", MAX_CHARACTERS, where)))
    takes = tuple(_take(entry, i, folder) for i, entry in enumerate(_entries(data, "takes", MAX_TAKES, where)))
    for kind, entries in (("characters", characters), ("takes", takes)):
        seen = set()
        for i, entry in enumerate(entries):
            if entry.name in seen:
                raise RetargetError(f"{kind}[{i}]: the name {entry.name!r} is used twice; names must be unique")
            seen.add(entry.name)
    pairs = _pairs(data.get("pairs", "all"), characters, takes)
    return Manifest(Path(path) if path is not None else folder, characters, takes,
                    tuple(dict.fromkeys(outputs)), pairs, _gltf_options(data.get("gltf", {}), where))


def _gltf_options(options, where: str) -> dict:
    """The checked ``gltf`` options: `retarget.gltf.write_gltf`'s form, rate, key_tolerance."""
    from retarget.gltf.keys import Keys
    from retarget.gltf.writer import FORMS

    if not isinstance(options, dict):
        raise RetargetError(f"{where}: gltf must be a mapping of form, rate and key_tolerance")
    _known(options, {"form", "rate", "key_tolerance"}, f"{where}: gltf")
    form = options.get("form", "exact")
    if form not in FORMS:
        raise RetargetError(f"{where}: gltf: form must be one of {', '.join(FORMS)}; got {form!r}")
    try:
        keys = Keys(options.get("rate"), options.get("key_tolerance", 0.0))
    except (RetargetError, TypeError) as exc:
        raise RetargetError(f"{where}: gltf: {exc}") from None
    return {"form": form, "rate": keys.rate, "key_tolerance": keys.tolerance}


def _entries(data: dict, key: str, limit: int, where: str) -> list:
    entries = data.get(key)
    if not isinstance(entries, list) or not entries:
        raise RetargetError(f"{where}: '{key}' must be a non-empty list")
    if len(entries) > limit:
        raise RetargetError(f"{where}: {len(entries)} {key}, over the limit of {limit}")
    return entries


def _character(entry, i: int, folder: Path) -> Character:
    where = _where("characters", i, entry)
    if not isinstance(entry, dict):
        raise RetargetError(f"{where} must be a mapping")
    _known(entry, {"name", "mesh", "landmarks", "project", "rig", "layout"}, where)
    name = _name(entry, where)
    project = _path(entry, "project", folder, where)
    mesh, landmarks = _path(entry, "mesh", folder, where), _path(entry, "landmarks", folder, where)
    if project is not None and (mesh or landmarks):
        raise RetargetError(f"{where}: give a 'project' (an exported .glb) or a 'mesh' and 'landmarks', not both")
    if project is None and (mesh is None or landmarks is None):
        raise RetargetError(f"{where}: needs 'mesh' and 'landmarks', or 'project' (a .glb exported by the app)")
    layout, layout_spec = entry.get("layout"), None
    if isinstance(layout, str) and layout.endswith(".json"):
        custom = load_layout_file(_path(entry, "layout", folder, where))
        layout, layout_spec = custom.name, custom.spec()
    elif layout is not None and layout not in LAYOUTS:
        raise RetargetError(f"{where}: unknown layout {layout!r}; choose one of {', '.join(LAYOUTS)}, "
                            "or a custom layout .json")
    rig, rig_file = entry.get("rig", {}), None
    if isinstance(rig, str):
        rig_file, rig = _path(entry, "rig", folder, where), {}
        if project is not None:
            raise RetargetError(f"{where}: a project holds its own rig; drop 'rig'")
    if not isinstance(rig, dict):
        raise RetargetError(f"{where}: 'rig' must be a mapping of settings or the path of a RIG.npz")
    _known(rig, {"deformer", "k", "kernel", "smoothing"}, f"{where} rig")
    deformer = rig.get("deformer", DEFAULT_METHOD)
    if deformer not in METHODS:
        raise RetargetError(f"{where}: unknown deformer {deformer!r}; choose one of {', '.join(METHODS)}")
    kernel = rig.get("kernel", DEFAULT_KERNEL)
    if kernel not in KERNELS:
        raise RetargetError(f"{where}: unknown kernel {kernel!r}; choose one of {', '.join(KERNELS)}")
    k = rig.get("k")
    if k is not None and (isinstance(k, bool) or not isinstance(k, int) or k < 1):
        raise RetargetError(f"{where}: rig k must be a positive integer; got {k!r}")
    smoothing = _number(rig.get("smoothing"), f"{where}: rig smoothing", positive=False)
    return Character(name, mesh, landmarks, project, rig_file, layout,
                     RigSettings(deformer, k, kernel, smoothing), layout_spec)


def _take(entry, i: int, folder: Path) -> TakeEntry:
    where = _where("takes", i, entry)
    if not isinstance(entry, dict):
        raise RetargetError(f"{where} must be a mapping")
    _known(entry, {"name", "file", "settings", "regions", "fps", "mapping", "labelled_vertices"}, where)
    file = _path(entry, "file", folder, where)
    if file is None:
        raise RetargetError(f"{where}: needs 'file', the performance file")
    if "name" not in entry:  # the file's stem names a take by default
        entry = {**entry, "name": file.stem}
    name = _name(entry, where)
    settings = _json_file(entry, "settings", folder, where) or {}
    if not isinstance(settings, dict):
        raise RetargetError(f"{where}: 'settings' must be a mapping (ConditionSettings) or a JSON file")
    try:
        settings = ConditionSettings.from_dict(settings).to_dict()
    except RetargetError as exc:
        raise RetargetError(f"{where}: settings: {exc}") from None
    regions = entry.get("regions")
    if regions is not None:
        if isinstance(regions, str):
            regions = [regions]
        if not isinstance(regions, list) or not all(isinstance(r, (str, int)) for r in regions):
            raise RetargetError(f"{where}: 'regions' must be a list of region, group or point names")
        regions = tuple(str(r) for r in regions) or None
    fps = _number(entry.get("fps"), f"{where}: fps", positive=True)
    maps = {}
    for key in ("mapping", "labelled_vertices"):
        value = _json_file(entry, key, folder, where)
        if value is not None and not isinstance(value, dict):
            raise RetargetError(f"{where}: '{key}' must be a mapping or a JSON file of one")
        maps[key] = value
    return TakeEntry(name, file, settings, regions, fps, maps["mapping"], maps["labelled_vertices"])


def _pairs(value, characters, takes) -> tuple[tuple[str, str], ...]:
    if value == "all":
        pairs = [(c.name, t.name) for c in characters for t in takes]
    elif isinstance(value, list):
        names_c, names_t = {c.name for c in characters}, {t.name for t in takes}
        pairs = []
        for i, pair in enumerate(value):
            if not isinstance(pair, dict) or set(pair) != {"character", "take"}:
                raise RetargetError(f"pairs[{i}] must be a mapping with 'character' and 'take'")
            if pair["character"] not in names_c:
                raise RetargetError(f"pairs[{i}]: no character named {pair['character']!r}")
            if pair["take"] not in names_t:
                raise RetargetError(f"pairs[{i}]: no take named {pair['take']!r}")
            pairs.append((pair["character"], pair["take"]))
        pairs = list(dict.fromkeys(pairs))
    else:
        raise RetargetError(f"'pairs' must be 'all' or a list of {{character, take}}; got {value!r}")
    if len(pairs) > MAX_PAIRS:
        raise RetargetError(f"the manifest makes {len(pairs)} pairs, over the limit of {MAX_PAIRS}")
    return tuple(pairs)


def _where(kind: str, i: int, entry) -> str:
    name = entry.get("name") if isinstance(entry, dict) else None
    return f"{kind}[{i}]" + (f" ({name!r})" if isinstance(name, str) else "")


def _known(mapping: dict, keys: set, where: str) -> None:
    unknown = sorted(str(k) for k in mapping if k not in keys)
    if unknown:
        raise RetargetError(f"{where}: unknown key(s) {', '.join(map(repr, unknown))}; "
                            f"known: {', '.join(sorted(keys))}")


def _name(entry: dict, where: str) -> str:
    """The entry's name, checked to be a safe folder name (it names the output folders)."""
    name = entry.get("name")
    if not isinstance(name, str) or not _NAME.match(name) or len(name) > MAX_NAME:
        raise RetargetError(f"{where}: 'name' must be 1-{MAX_NAME} letters, digits, '.', '_' or '-' "
                            f"(not starting with '.' or '-'); got {name!r}")
    return name


def _path(entry: dict, key: str, folder: Path, where: str) -> Path | None:
    value = entry.get(key)
    if value is None:
        return None
    if not isinstance(value, str) or not value.strip():
        raise RetargetError(f"{where}: '{key}' must be a file path; got {value!r}")
    return (folder / value).resolve()


def _json_file(entry: dict, key: str, folder: Path, where: str):
    """The entry's `key`: its value, or (a string) the JSON in that file, as `retarget
    condition` reads --settings, --mapping and --labelled-vertices."""
    value = entry.get(key)
    if not isinstance(value, str):
        return value
    path = _path(entry, key, folder, where)
    try:
        if path.stat().st_size > MAX_MANIFEST_BYTES:
            raise RetargetError(f"{where}: {key} file {str(path)!r} is over {MAX_MANIFEST_BYTES} bytes")
        return json.loads(path.read_text(encoding="utf-8-sig"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RetargetError(f"{where}: {key} file {str(path)!r} is not readable JSON: {exc}") from None


def _number(value, what: str, *, positive: bool) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or value < 0 or (positive and value == 0):
        raise RetargetError(f"{what} must be a {'positive' if positive else 'non-negative'} number; got {value!r}")
    return float(value)
