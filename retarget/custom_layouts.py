"""Custom layouts: a user's own markers as a `Layout`, from a JSON spec.

Real users stick their own markers, in their own number; the spec says what each one is::

    {"format": "retarget-layout/1",            # optional
     "description": "my 12 markers",            # optional, one line
     "points": [
        {"name": "brow_r", "region": "brows", "side": "right", "mirror": "brow_l"},
        {"name": "brow_l", "region": "brows", "side": "left", "mirror": "brow_r"},
        {"name": "nose", "region": "nose", "side": "center", "anchor": true},
        ...]}

Per point: ``name`` (a safe identifier: a letter or underscore, then letters, digits and
underscores, at most `MAX_NAME` characters; a take's column names must match them),
``region`` (one of `retarget.layouts.REGIONS`), ``side`` (``right``, ``center`` or
``left``, the subject's), and optionally ``mirror`` (the left/right partner's name: both
must name each other, one right and one left; none: its own), ``anchor`` (true for a
point that moves with the head only; give none or at least 3), ``ibug68`` /
``mediapipe468`` (the iBUG point / face-mesh vertex the point stands for, so 68-point and
face-mesh sources can drive it) and ``reference`` ([x, y, z] on a reference face, cm, +y
up, +x the subject's left; all points or none).

`layout_from_spec` checks everything with a `RetargetError` naming the point and field,
and registers the layout (`retarget.layouts.register_layout`) under the name
``custom-<hash of the spec>``, so the same spec is the same layout in every process and
every file that names it. `Layout.spec` gives the spec back.
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import replace
from pathlib import Path

import numpy as np

from retarget.errors import RetargetError
from retarget.layouts import REGIONS, SIDES, SPEC_FORMAT, Layout, get_layout, register_layout

__all__ = ["MAX_POINTS", "MAX_NAME", "MAX_DESCRIPTION", "MAX_SPEC_BYTES", "layout_from_spec",
           "load_layout_file", "spec_of_names", "stereo_reference", "take_reference"]

MAX_POINTS = 1000
"""Most points a custom layout may have (the dense built-in one has 468)."""

MAX_NAME = 64
"""Longest point name."""

MAX_DESCRIPTION = 200
"""Longest description."""

MAX_SPEC_BYTES = 512 * 1024
"""Largest layout file read (a 1000-point spec with references is about 150 kB)."""

_SAFE_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_POINT_KEYS = {"name", "region", "side", "mirror", "anchor", "ibug68", "mediapipe468", "reference"}


def layout_from_spec(spec: dict) -> Layout:
    """The custom layout `spec` describes (module docstring), registered in this process."""
    if not isinstance(spec, dict):
        raise RetargetError(f"a layout spec is a JSON object with 'points', got {type(spec).__name__}")
    unknown = sorted(set(spec) - {"format", "description", "points"})
    if unknown:
        raise RetargetError(f"layout spec has unknown keys {unknown}; it takes format, description, points")
    if spec.get("format", SPEC_FORMAT) != SPEC_FORMAT:
        raise RetargetError(f"layout spec format {spec['format']!r:.40} is not {SPEC_FORMAT!r}")
    points = spec.get("points")
    if not isinstance(points, list):
        raise RetargetError("layout spec 'points' must be a list of points")
    if not 3 <= len(points) <= MAX_POINTS:
        raise RetargetError(f"a custom layout needs 3 to {MAX_POINTS} points, got {len(points)}")
    description = spec.get("description", "")
    if not isinstance(description, str) or len(description) > MAX_DESCRIPTION:
        raise RetargetError(f"layout spec 'description' must be a string of at most {MAX_DESCRIPTION} characters")
    rows = [_point(i, p) for i, p in enumerate(points)]
    names = [row["name"] for row in rows]
    index = _unique_index(names)
    mirror = _mirror(rows, index)
    anchors = tuple(i for i, row in enumerate(rows) if row["anchor"])
    if 0 < len(anchors) < 3:
        raise RetargetError(f"head anchors: mark at least 3 points (3 fix the head's pose) or none; "
                            f"got {len(anchors)} ({', '.join(names[i] for i in anchors)})")
    given = [row["reference"] is not None for row in rows]
    if any(given) and not all(given):
        raise RetargetError(f"'reference': give every point one or none; point {given.index(False)} "
                            f"({names[given.index(False)]!r}) has none")
    layout = Layout(
        name="custom-" + "0" * 16,  # named below, after the hash of its canonical spec
        description=description or f"custom layout of {len(rows)} points",
        point_names=tuple(names),
        regions=tuple(row["region"] for row in rows),
        sides=tuple(row["side"] for row in rows),
        mirror=mirror,
        ibug68=tuple(row["ibug68"] for row in rows),
        mediapipe468=tuple(row["mediapipe468"] for row in rows),
        anchors=anchors,
        reference=tuple(row["reference"] for row in rows) if all(given) else None,
    )
    digest = hashlib.sha256(json.dumps(layout.spec(), sort_keys=True).encode()).hexdigest()[:16]
    layout = replace(layout, name=f"custom-{digest}")
    return register_layout(layout)


def load_layout_file(path) -> Layout:
    """The custom layout in a JSON spec file (its size bounded before it is parsed)."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_SPEC_BYTES:
            raise RetargetError(f"layout file {str(path)!r} is {size:,} bytes, above the limit of "
                                f"{MAX_SPEC_BYTES:,}")
        spec = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RetargetError(f"could not read layout file {str(path)!r}: {exc}") from None
    try:
        return layout_from_spec(spec)
    except RetargetError as exc:
        raise RetargetError(f"layout file {str(path)!r}: {exc}") from None


def spec_of_names(names: list[str], regions: list[str], sides: list[str] | None = None,
                  mirrors: list[str | None] | None = None, description: str = "") -> dict:
    """A spec from parallel lists (the CLI's ``--names/--regions/--sides/--mirror``);
    a side defaults to center. Checked when it is read (`layout_from_spec`)."""
    n = len(names)
    for what, values in (("regions", regions), ("sides", sides), ("mirror", mirrors)):
        if values is not None and len(values) != n:
            raise RetargetError(f"{what} has {len(values)} entries, names has {n}")
    points = []
    for i, name in enumerate(names):
        point = {"name": name, "region": regions[i], "side": sides[i] if sides else "center"}
        if mirrors and mirrors[i]:
            point["mirror"] = mirrors[i]
        points.append(point)
    return {"format": SPEC_FORMAT, "description": description, "points": points}


def take_reference(take) -> list[list[float]] | None:
    """Each marker's ``reference`` for a layout made from a marker take, so later takes (and
    live sessions) of the same markers are named by where they sit, not by the order a
    tracker met them.

    take : a `Take`. A 2D marker take (pixels, x right, y up): each marker's first
    position seen, z 0 on this picture plane; later 2D takes are named against it by a
    similarity and then affine fit (`retarget.sources.markers.assign_markers`), so any
    camera distance or roll the first take had works. A stereo take (``source`` "stereo",
    3D, mm): `stereo_reference` of each marker's median place over the frames it is seen;
    live stereo sessions are named against it (`retarget.sources.place_names`).
    Returns (M, 3) rows, centred and scaled to the built-in face's size (the layouts'
    reference convention: cm, +x the subject's left as the camera sees it, +y up), or None
    when a marker is never seen or the take is 3D from another source (its axes unknown).
    """
    p = np.asarray(take.points, dtype=np.float64)
    seen = np.isfinite(p).all(axis=2)
    if len(p) == 0 or not seen.any(axis=0).all():
        return None
    if p.shape[2] == 2:
        first = p[seen.argmax(axis=0), np.arange(p.shape[1])]
        xy = _face_sized(first)
        return None if xy is None else np.round(np.column_stack([xy, np.zeros(len(xy))]), 4).tolist()
    if take.source != "stereo":
        return None
    # A median, not the first sighting: a sticker first seen half hidden at a grazing
    # angle is millimetres off, and one the take opens on mid-expression is too.
    reference = stereo_reference(np.nanmedian(p, axis=0))
    return None if reference is None else np.round(reference, 4).tolist()


def stereo_reference(places) -> np.ndarray | None:
    """(M, 3) float64 stereo head-frame places as a layout's reference, None when they
    do not span a face (all at one point).

    places : (M, 3) float, a stereo take's or live session's head frame (the left
    camera's axes at the head's first pose, `retarget.sources.stereo`: x right, y down,
    z away from the camera), any unit.
    The layouts' convention is +x the subject's left as the camera sees it (the camera's
    x), +y up and +z out of the face towards the camera: the camera's y and z flip (a
    rotation, so a left sticker stays left). Then centred and scaled to the built-in
    face's 3D size (cm), as `take_reference` does a 2D take's.
    """
    p = np.asarray(places, dtype=np.float64) * [1.0, -1.0, -1.0]
    return _face_sized(p)


def _face_sized(points: np.ndarray) -> np.ndarray | None:
    """(M, D) `points` (M, D), D 2 or 3, centred and scaled to the root-mean-square radius
    of the built-in face's iBUG points in their first D axes (cm); None for no spread."""
    centred = points - points.mean(axis=0)
    spread = np.sqrt((centred ** 2).sum(axis=1).mean())
    if not spread > 0:
        return None
    face = get_layout("ibug68").reference_points()[:, :points.shape[1]]
    size = np.sqrt(((face - face.mean(axis=0)) ** 2).sum(axis=1).mean())
    return centred * (size / spread)


def _point(i: int, point) -> dict:
    """Point `i` of a spec checked and normalised (every key present)."""
    if not isinstance(point, dict):
        raise RetargetError(f"layout point {i} must be an object with name, region and side")
    unknown = sorted(set(point) - _POINT_KEYS)
    if unknown:
        raise RetargetError(f"layout point {i}: unknown keys {unknown}; a point takes {sorted(_POINT_KEYS)}")
    name = point.get("name")
    if not isinstance(name, str) or not _SAFE_NAME.fullmatch(name) or len(name) > MAX_NAME:
        raise RetargetError(
            f"layout point {i}: name {name!r:.80} is not a safe identifier (a letter or underscore, "
            f"then letters, digits or underscores, at most {MAX_NAME} characters)")
    where = f"layout point {i} ({name!r})"
    region, side = point.get("region"), point.get("side")
    if region not in REGIONS:
        raise RetargetError(f"{where}: region {region!r:.40} is not one of {', '.join(REGIONS)}")
    if side not in SIDES:
        raise RetargetError(f"{where}: side {side!r:.40} is not one of {', '.join(SIDES)}")
    mirror = point.get("mirror")
    if mirror is not None and not isinstance(mirror, str):
        raise RetargetError(f"{where}: mirror must be the partner's name or null, got {mirror!r:.40}")
    anchor = point.get("anchor", False)
    if not isinstance(anchor, bool):
        raise RetargetError(f"{where}: anchor must be true or false, got {anchor!r:.40}")
    return {"name": name, "region": region, "side": side, "mirror": mirror, "anchor": anchor,
            "ibug68": _source_index(point, "ibug68", 68, where),
            "mediapipe468": _source_index(point, "mediapipe468", 468, where),
            "reference": _reference(point.get("reference"), where)}


def _source_index(point: dict, key: str, size: int, where: str) -> int:
    value = point.get(key, -1)
    if isinstance(value, bool) or not isinstance(value, int) or not -1 <= value < size:
        raise RetargetError(f"{where}: {key} must be an integer in [0, {size}) (or -1: none), got {value!r:.40}")
    return value


def _reference(value, where: str) -> tuple[float, float, float] | None:
    if value is None:
        return None
    ok = (isinstance(value, list) and len(value) == 3
          and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value))
    if not ok or not all(abs(float(v)) < 1e6 for v in value):
        raise RetargetError(f"{where}: reference must be [x, y, z] finite numbers, got {value!r:.60}")
    return tuple(float(v) for v in value)


def _unique_index(names: list[str]) -> dict[str, int]:
    index: dict[str, int] = {}
    for i, name in enumerate(names):
        if name in index:
            raise RetargetError(f"layout point name {name!r} is repeated (points {index[name]} and {i})")
        index[name] = i
    return index


def _mirror(rows: list[dict], index: dict[str, int]) -> tuple[int, ...]:
    """Each point's partner index: both name each other, one right and one left; a
    center point is its own."""
    out = []
    for i, row in enumerate(rows):
        partner = row["mirror"]
        if partner is None or partner == row["name"]:
            out.append(i)
            continue
        if partner not in index:
            raise RetargetError(f"point {row['name']!r}: mirror partner {partner!r} is no point of the layout")
        j = index[partner]
        back = rows[j]["mirror"]
        if back != row["name"]:
            raise RetargetError(
                f"asymmetric mirror: point {row['name']!r} names {partner!r} its partner, but "
                f"{partner!r} names {back!r}; partners must name each other")
        if {row["side"], rows[j]["side"]} != {"right", "left"}:
            raise RetargetError(
                f"mirror partners {row['name']!r} ({row['side']}) and {partner!r} ({rows[j]['side']}) "
                "must be one right and one left")
        out.append(j)
    return tuple(out)
