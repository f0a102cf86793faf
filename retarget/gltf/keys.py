"""An export's animation keys: the rate they sit at and which of them are written.

Rate: a take is recorded at the camera's rate, often uneven (a webcam delivers 29.7 fps
with jitter), while an animator works at the project's rate. `resampled` puts a clip's
frames on the grid t0 + k / fps (24, 25, 30 or 60 fps: `RATES`), linearly between the
take's frames (head rotations by slerp), so Blender's importer lands every key on a whole
frame; the last part of a frame interval past the final grid point is dropped.

Key reduction: a LINEAR channel keyed every frame carries long runs where the motion is a
straight line to within what anyone can see. `kept_keys` drops every key that linear
interpolation between the kept ones reproduces within a tolerance (Ramer-Douglas-Peucker
on the key values: split a span at its worst key until every span fits), so the curve a
viewer draws stays within the tolerance of every dropped key and exact at the kept ones.
`KeyWriter` writes one animation's samplers this way: each channel its own key times when
reducing (a still jaw needs two keys while the lips need hundreds), one shared times
accessor when not (the file is then what it was without the option).

Tolerances are lengths: the export's ``key_tolerance`` in millimetres, turned into file
units by the writer. A morph weight w = d / s moves a feature by s w, so its tolerance is
the length over s; a rotation by angle θ moves a point r from the pivot by at most r θ,
so a quaternion's components (half-angle) get the length over 2 r.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from retarget.errors import RetargetError
from retarget.gltf.glb import GlbBuilder

__all__ = ["RATES", "KeyWriter", "Keys", "kept_keys", "resampled"]

RATES = (24.0, 25.0, 30.0, 60.0)


@dataclasses.dataclass(frozen=True)
class Keys:
    """An export's choice of keys: `rate` (None: the clips' own frames, else one of
    `RATES`) and `tolerance` (millimetres; 0 keeps every key). Refused when made with a
    bad value, before any work."""

    rate: float | None = None
    tolerance: float = 0.0

    def __post_init__(self):
        if self.rate is not None and (isinstance(self.rate, bool) or self.rate not in RATES):
            raise RetargetError(f"the animation rate must be one of "
                                f"{', '.join(f'{r:g}' for r in RATES)} fps; got {self.rate!r}")
        if isinstance(self.tolerance, bool) or not (np.isfinite(self.tolerance) and self.tolerance >= 0):
            raise RetargetError(f"the key tolerance must be a number of millimetres >= 0; "
                                f"got {self.tolerance!r}")

    def resampled(self, clips) -> tuple:
        """The clips at `rate` (`resampled`)."""
        return tuple(resampled(clip, self.rate) for clip in clips)

    def file_tolerance(self, units: dict) -> float:
        """The tolerance in file units, from the export's units record
        (`retarget.gltf.units.ExportUnits.record`: file = source x scale, source unit
        ``scale_to_metres`` metres)."""
        return self.tolerance * 1e-3 / units["scale_to_metres"] * units["scale"]

    def record(self) -> dict:
        """What ``extras.retarget`` records of the choice (nothing for the defaults)."""
        out = {}
        if self.rate is not None:
            out["rate"] = float(self.rate)
        if self.tolerance > 0:
            out["key_tolerance_mm"] = float(self.tolerance)
        return out


def resampled(clip, fps: float | None):
    """`clip` (`Clip`, `ContractionClip`, `ArkitClip`) with its frames at ``t0 + k / fps``:
    every per-frame array interpolated linearly at those times, ``head_rotations`` by
    slerp; the clip itself when `fps` is None. `RetargetError` for a rate not in `RATES`."""
    if fps is None:
        return clip
    Keys(fps)  # refuses a rate not in RATES
    old = np.asarray(clip.times, dtype=np.float64)
    steps = int(np.floor((old[-1] - old[0]) * fps + 1e-6))
    new = old[0] + np.arange(steps + 1) / float(fps)
    changes = {"times": new}
    for field in dataclasses.fields(clip):
        value = getattr(clip, field.name)
        if field.name == "times" or not isinstance(value, np.ndarray) or len(value) != len(old):
            continue
        changes[field.name] = (_slerped(old, value, new) if field.name == "head_rotations"
                               else _lerped(old, value, new))
    return dataclasses.replace(clip, **changes)


def _lerped(old: np.ndarray, values: np.ndarray, new: np.ndarray) -> np.ndarray:
    """(len(new), ...) `values` (len(old), ...) linear in time, in their own dtype."""
    flat = values.reshape(len(old), -1).astype(np.float64)
    i = np.clip(np.searchsorted(old, new, side="right") - 1, 0, max(len(old) - 2, 0))
    if len(old) == 1:
        return np.repeat(values[:1], len(new), axis=0)
    u = ((new - old[i]) / (old[i + 1] - old[i]))[:, None]
    out = (1 - u) * flat[i] + u * flat[i + 1]
    return out.reshape((len(new),) + values.shape[1:]).astype(values.dtype)


def _slerped(old: np.ndarray, q: np.ndarray, new: np.ndarray) -> np.ndarray:
    """(len(new), 4) unit quaternions slerped between the (len(old), 4) keys."""
    from retarget.gltf.animation import sampled  # the glTF sampler, the reader's too
    return sampled(old, np.asarray(q, dtype=np.float64), "LINEAR", new, rotation=True)


def kept_keys(times: np.ndarray, values: np.ndarray, tolerance: float) -> np.ndarray:
    """(K,) ascending indices of the keys to keep of (F,) `times` and (F, C) `values`:
    the first and last always, and enough between that every dropped key's components lie
    within `tolerance` of the line between its kept neighbours. All of them at 0."""
    f = len(times)
    if tolerance <= 0 or f <= 2:
        return np.arange(f)
    t = np.asarray(times, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64).reshape(f, -1)
    keep = np.zeros(f, dtype=bool)
    keep[[0, f - 1]] = True
    spans = [(0, f - 1)]
    while spans:
        a, b = spans.pop()
        if b - a < 2:
            continue
        u = ((t[a + 1:b] - t[a]) / (t[b] - t[a]))[:, None]
        line = (1 - u) * v[a] + u * v[b]
        error = np.abs(v[a + 1:b] - line).max(axis=1)
        worst = int(np.argmax(error))
        if error[worst] > tolerance:
            split = a + 1 + worst
            keep[split] = True
            spans += [(a, split), (split, b)]
    return np.flatnonzero(keep)


class KeyWriter:
    """The samplers of one animation over a clip's (F,) `times`, LINEAR, their keys
    reduced to `tolerance` file units (0: every frame, one shared times accessor)."""

    def __init__(self, out: GlbBuilder, times: np.ndarray, tolerance: float = 0.0):
        self.out = out
        self.times = np.asarray(times, dtype=np.float64)
        self.tolerance = float(tolerance)
        self._time_accessors: dict[bytes, int] = {}

    def sampler(self, values: np.ndarray, scale: float = 1.0, weights: bool = False) -> dict:
        """A LINEAR sampler keying (F, C) `values` (as float32: VEC3 or VEC4 rows, or
        with `weights` a morph-weights channel's scalars), keys dropped within the
        tolerance divided by `scale` (how far a unit of these values moves the face)."""
        values = np.asarray(values, dtype=np.float32).reshape(len(self.times), -1)
        kept = kept_keys(self.times, values, self.tolerance / scale)
        output = np.ascontiguousarray(values[kept].ravel() if weights else values[kept])
        return {"input": self._times(kept), "output": self.out.accessor(output),
                "interpolation": "LINEAR"}

    def _times(self, kept: np.ndarray) -> int:
        """The times accessor of these keys, shared by every channel keyed alike."""
        key = kept.tobytes()
        if key not in self._time_accessors:
            self._time_accessors[key] = self.out.accessor(
                self.times[kept].astype(np.float32), bounds=True)
        return self._time_accessors[key]
