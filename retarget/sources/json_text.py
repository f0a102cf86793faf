"""JSON performance files parsed once, safely: nesting bounded before `json.loads` builds
anything (it recurses once per level), every failure a `RetargetError` naming the file.
Shared by the landmark-table reader (`files`) and the ARKit-curve reader (`arkit_curves`)."""

from __future__ import annotations

import json
import re

import numpy as np

from retarget.errors import RetargetError

__all__ = ["MAX_JSON_DEPTH", "json_document"]

MAX_JSON_DEPTH = 64  # a take is 4 deep
_JSON_STRING = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*"')
_JSON_STEPS = np.zeros(256, np.int8)  # +1 for [ and {, -1 for ] and }
_JSON_STEPS[[ord("["), ord("{")]] = 1
_JSON_STEPS[[ord("]"), ord("}")]] = -1


def json_document(text: str, label: str):
    """The JSON value of `text`; `label` names the file in refusals."""
    depth = _json_depth(text)
    if depth > MAX_JSON_DEPTH:
        raise RetargetError(
            f"{label} is nested too deeply: {depth} levels of [ and {{ (a take has 4; at most "
            f"{MAX_JSON_DEPTH} are read)")
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise RetargetError(f"{label} is not JSON: {exc}") from None
    except RecursionError:
        raise RetargetError(f"{label} is nested too deeply to be read as JSON") from None


def _json_depth(text: str) -> int:
    """How deep [ and { nest in a JSON text, its strings skipped: a cheap scan made before
    `json.loads` builds anything."""
    bare = np.frombuffer(_JSON_STRING.sub('""', text).encode("utf-8", "replace"), np.uint8)
    steps = _JSON_STEPS[bare]
    steps = steps[steps != 0]
    return int(np.cumsum(steps, dtype=np.int32).max(initial=0))
