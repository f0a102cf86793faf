"""glTF JSON into pygltflib's object model, without dataclasses_json's cost.

pygltflib decodes with dataclasses_json, which resolves a class's type hints
(`typing.get_type_hints`) and walks its generic-type predicates again for every object
and every value: reading a dense rig's export (hundreds of morph-target accessors) spent
seconds there. `gltf_from_json` and `gltf_from_glb` build the same `pygltflib.GLTF2` from
a plan made once per class.

The same objects, value for value and type for type, as dataclasses_json makes them:

- a scalar field keeps a value of its type and is otherwise converted by it, as
  dataclasses_json does (a count of 3.0 becomes 3, a name 5 becomes "5", a max of [1]
  becomes [1.0], a normalized of 1 becomes True); null stays None;
- an object field is decoded recursively; a list is decoded element by element (a null
  element of a list of objects stays None); extras and extensions are shallow copies;
  a primitive's attributes and targets stay as the JSON has them, and pygltflib's own
  pass then makes `Attributes` of each primitive's attributes;
- unknown keys are dropped, missing fields take the class's defaults.

Whatever has another shape (a string where a list belongs, a list where an object
belongs, a JSON that is no object...) and every error is handed to pygltflib itself: a
malformed file gets pygltflib's own result or exception, word for word, as before.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import typing

import pygltflib

__all__ = ["gltf_from_glb", "gltf_from_json"]


class _OtherShape(Exception):
    """A JSON value of a shape that only pygltflib's own decoding is trusted with."""


def gltf_from_json(text: str) -> pygltflib.GLTF2:
    """`pygltflib.GLTF2.from_json(text)`, fast for a well-formed document."""
    try:
        return _gltf(json.loads(text))
    except Exception:  # noqa: BLE001 - pygltflib's own decoding says what is wrong
        return pygltflib.GLTF2.from_json(text)


def gltf_from_glb(data: bytes) -> pygltflib.GLTF2:
    """`pygltflib.GLTF2.load_from_bytes(data)`, fast for a well-formed document."""
    try:
        return _GlbChunks.load_from_bytes(data)
    except Exception:  # noqa: BLE001 - pygltflib's own decoding says what is wrong
        return pygltflib.GLTF2.load_from_bytes(data)


class _GlbChunks(pygltflib.GLTF2):
    """pygltflib's own walk over a GLB's chunks (`load_from_bytes`, unchanged), its JSON
    chunk decoded by `_gltf`: the document it makes is a plain `pygltflib.GLTF2`."""

    @classmethod
    def from_json(cls, s, *, infer_missing=False, **kw):
        # infer_missing only matters to a JSON that is no object, which `_gltf` refuses
        return _gltf(json.loads(s))


def _gltf(data) -> pygltflib.GLTF2:
    """The document of parsed JSON `data`, with pygltflib's `from_json` pass that makes
    `Attributes` of every primitive's attributes."""
    if type(data) is not dict:
        raise _OtherShape("the document is no JSON object")
    result = _decode(pygltflib.GLTF2, data)
    for mesh in result.meshes:
        for primitive in mesh.primitives:
            raw_attributes = primitive.attributes
            if raw_attributes:
                primitive.attributes = pygltflib.Attributes(**raw_attributes)
    return result


def _decode(cls, data: dict):
    """An instance of the pygltflib dataclass `cls` from the JSON object `data`."""
    kwargs = {}
    for name, default, convert in _plan(cls):
        value = data[name] if name in data else default()
        kwargs[name] = None if value is None else convert(value)
    return cls(**kwargs)


@functools.cache
def _plan(cls) -> tuple:
    """(field name, its default's maker, its converter) of each field of `cls`: the type
    hints resolved once, where dataclasses_json resolves them for every object."""
    hints = typing.get_type_hints(cls)
    return tuple((f.name, _default(f), _converter(hints[f.name])) for f in dataclasses.fields(cls))


def _default(f: dataclasses.Field):
    """The maker of a missing field's value; a TypeError for a field without a default
    (dataclasses_json's KeyError or None for those is not copied here)."""
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory
    if f.default is dataclasses.MISSING:
        raise TypeError(f"pygltflib field {f.name} has no default")
    return lambda: f.default


def _converter(hint):
    """The function that decodes a non-null value of type `hint` as dataclasses_json does;
    a TypeError for a type pygltflib's classes did not use when this was written."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint in (int, float, str, bool):
        return functools.partial(_scalar, hint)
    if hint is pygltflib.Attributes:  # dataclasses_json passes the JSON value through
        return _same
    if dataclasses.is_dataclass(hint):
        return functools.partial(_nullable, functools.partial(_object, hint))
    if origin is typing.Union and len(args) == 2 and args[1] is type(None):
        return functools.partial(_nullable, _converter(args[0]))
    if origin is list and len(args) == 1:
        return functools.partial(_list, _converter(args[0]))
    if origin is dict and args == (str, typing.Any):
        return _dict
    raise TypeError(f"pygltflib field type {hint} is not decoded by retarget.gltf.decode")


def _scalar(kind, value):
    """dataclasses_json's `_support_extended_types` for int, float, str and bool."""
    return value if isinstance(value, kind) else kind(value)


def _same(value):
    return value


def _nullable(convert, value):
    return None if value is None else convert(value)


def _object(cls, value):
    if type(value) is not dict:
        raise _OtherShape(f"{cls.__name__} is no JSON object")
    return _decode(cls, value)


def _list(convert, value) -> list:
    if type(value) is not list:
        raise _OtherShape("a list is no JSON array")
    return [convert(item) for item in value]


def _dict(value) -> dict:
    if type(value) is not dict:
        raise _OtherShape("extras or extensions are no JSON object")
    return dict(value)
