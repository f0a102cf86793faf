"""A bounds-checked, pure-Python reader of a C3D file's header and parameter section, and
the check that a file is safe to hand to ezc3d.

ezc3d (1.7) reads C3D files in C++ and trusts what they say: it indexes parameter value
vectors and the frame list without bounds checks, sizes its containers from counts in
the file and, when a count runs past the end of the file, keeps reading. A file that
differs from a valid one in a byte or two can make it crash the process, loop or
allocate gigabytes. `c3d_layout` walks the file as ezc3d will (the same offsets, the
same reconciliation of header and parameters, `ezc3d::c3d::updateHeader`) and refuses,
with a `RetargetError` that names the byte offset, the record or the numbers, anything
ezc3d would read out of bounds or that would make it allocate beyond the budgets below.

The C3D format (https://www.c3d.org/HTML/default.htm, "The C3D file format"):

* The file is 512-byte blocks, numbered from 1. Block 1 is the header: byte 0 is the
  number of the parameter section's first block, byte 1 the key 0x50; then 16-bit
  words: 3D point count (bytes 2-3), analog measurements per frame (4-5), first and
  last frame, 1-based (6-7, 8-9), maximum interpolation gap (10-11), the point scale
  factor as a float (12-15; negative: the data are floats), the data section's first
  block (16-17), analog samples per frame (18-19) and the frame rate, a float (20-23).
* The parameter section starts with 4 bytes: two ignored ones, the block count and the
  processor type (84 Intel, 85 DEC, 86 MIPS), which sets the byte order and float
  format of every number in the file (Intel: little-endian IEEE; DEC: VAX F floats, in
  word-swapped little-endian order, 4 times the IEEE value; MIPS: big-endian IEEE).
  Then records: a signed name length (negative: locked; 0 ends the section), a signed
  group id (negative for a group, the owning group's id for a parameter), the name, a
  16-bit offset from that offset field to the next record (0: the last record), and
  for a group a signed description length and the description; for a parameter a
  signed element size (-1 char, 1 byte, 2 int16, 4 float), a dimension count, one byte
  per dimension, the values (column-major) and a description.
* The data section holds, per frame, every point (x, y, z as int16 with a camera-mask
  byte and a residual byte, or 4 floats when the scale is negative) then every analog
  sample of the frame (int16, or floats when the header's scale is negative).

Each refusal reads ``<label> is not a readable C3D file: <what, where>``.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field, replace

from retarget.errors import RetargetError

__all__ = ["C3dHeader", "C3dLayout", "C3dParameter", "MAX_C3D_ANALOG_SAMPLES",
           "MAX_C3D_POINT_SAMPLES", "MAX_C3D_SUBFRAMES", "c3d_header", "c3d_layout",
           "c3d_parameters"]

MAX_C3D_POINT_SAMPLES = 4_000_000
"""Most point samples (frames x points, plus rotation samples) a C3D file may declare.
ezc3d holds about 200 bytes per point sample (a point object with its camera-mask
vector, then the NumPy arrays), so this is about 800 MB: 100 markers for 5.5 minutes
at 120 fps."""

MAX_C3D_ANALOG_SAMPLES = 16_000_000
"""Most analog samples (frames x samples per frame x channels); about 40 bytes each in
ezc3d."""

MAX_C3D_SUBFRAMES = 4_000_000
"""Most frames plus analog and rotation sub-frames (frames x (1 + analog samples per
frame + rotation ratio)); ezc3d makes an object for each even when it holds no data, so
this bounds what a file can make it allocate out of nothing."""

MAX_C3D_RATE = 1e6
"""Highest point, analog or rotation rate (Hz) taken as sane."""

_BLOCK = 512
_PROCESSORS = {84: "Intel", 85: "DEC", 86: "MIPS"}
_TYPES = {-1: "CHAR", 1: "BYTE", 2: "INT", 4: "FLOAT"}
_MAX_RECORD = 0xFFFF  # a next-record offset is 16 bits: no record is longer
_DEFAULTS = {  # what ezc3d's setMandatoryParameters gives a group that lacks them
    "POINT": {"USED": [0], "SCALE": [-1.0], "RATE": [0.0], "FRAMES": [0]},
    "ANALOG": {"USED": [0], "RATE": [0.0], "GEN_SCALE": [1.0], "SCALE": [], "OFFSET": []},
}


@dataclass(frozen=True)
class C3dHeader:
    """The 512-byte header block, decoded in the processor's number format.

    parameter_block : 1-based block of the parameter section (byte 0).
    processor : "Intel", "DEC" or "MIPS" (from the parameter section's 4th byte).
    points, analog_measurements : the header's counts (words 2 and 3).
    first_frame, last_frame : 0-based, as ezc3d reads them (the file's are 1-based; a
        first frame of 0 is taken as 0-based already).
    scale : the point scale factor (negative: float data).
    data_block : 1-based first block of the data section.
    analog_per_frame : analog samples per point frame.
    frame_rate : Hz.
    """

    parameter_block: int
    processor: str
    points: int
    analog_measurements: int
    first_frame: int
    last_frame: int
    scale: float
    data_block: int
    analog_per_frame: int
    frame_rate: float

    @property
    def parameter_offset(self) -> int:
        """The byte where the parameter section starts."""
        return (self.parameter_block - 1) * _BLOCK

    @property
    def data_offset(self) -> int:
        """The byte where the data section starts (the parameter section ends there)."""
        return (self.data_block - 1) * _BLOCK


@dataclass(frozen=True)
class C3dParameter:
    """One parameter record: `offset` is the byte of its name-length byte, `type` one
    of -1 (char), 1 (byte), 2 (int16), 4 (float), `dims` its dimensions as ezc3d keeps
    them ((1,) for a scalar) and `values` what ezc3d will read: ints, floats, or strings
    (column-major, trailing spaces dropped)."""

    group: str
    name: str
    offset: int
    type: int
    dims: tuple[int, ...]
    values: tuple = field(repr=False)

    @property
    def where(self) -> str:
        return f"{self.group}:{self.name} (the parameter record at byte {self.offset})"

    @property
    def is_empty(self) -> bool:
        """ezc3d's emptiness: no dimension, or a single dimension of 0."""
        return self.dims == () or self.dims == (0,)


@dataclass(frozen=True)
class C3dLayout:
    """What ezc3d will read from a checked file, after it reconciles header and parameters.

    header : the `C3dHeader`.
    groups : {group name: {parameter name: `C3dParameter`}} (the first group of a name,
        as ezc3d looks groups up).
    frames, points : the frames and 3D points ezc3d will read.
    analog_channels, analog_per_frame : analog channels and samples per frame.
    frame_bytes : bytes per frame in the data section.
    labels : the POINT:LABELS (LABELS2, ...) strings.
    """

    header: C3dHeader
    groups: dict
    frames: int
    points: int
    analog_channels: int
    analog_per_frame: int
    frame_bytes: int
    labels: tuple[str, ...]


def c3d_header(data: bytes, label: str) -> C3dHeader:
    """The header of the C3D file `data`, its pointers and key checked (see the module
    docstring); raises `RetargetError` naming the byte. A file too short for a header or
    without the key is "not a C3D file (no C3D header)"."""
    refuse = _refuser(label)
    size = len(data)
    if size < _BLOCK:
        _refuser(label, "is not a C3D file (no C3D header)")(
            f"it is {size} bytes long, shorter than the {_BLOCK}-byte header")
    if data[1] != 0x50:
        _refuser(label, "is not a C3D file (no C3D header)")(
            f"byte 1 is 0x{data[1]:02X} where a C3D header has the key 0x50")
    block = data[0]
    if block == 0:
        refuse("byte 0, the block number of the parameter section, is 0 (files padded with "
               "leading zero bytes are not read)")
    if block == 1:
        refuse("byte 0 puts the parameter section in block 1, which is the header")
    start = (block - 1) * _BLOCK
    if start + 4 > size:
        refuse(f"byte 0 puts the parameter section in block {block}, at byte {start}, past the "
               f"end of the {size}-byte file")
    kind = data[start + 3]
    if kind not in _PROCESSORS:
        refuse(f"byte {start + 3}, the processor type in the parameter section's first 4 bytes, "
               f"is {kind}; C3D files have 84 (Intel), 85 (DEC) or 86 (MIPS)")
    processor = _PROCESSORS[kind]
    word = _word_reader(data, processor)
    data_block = word(16)
    if data_block <= block:
        refuse(f"bytes 16-17 put the data section in block {data_block}, not after the "
               f"parameter section (block {block}, byte 0)")
    if (data_block - 1) * _BLOCK > size:
        refuse(f"bytes 16-17 put the data section in block {data_block}, at byte "
               f"{(data_block - 1) * _BLOCK}, past the end of the {size}-byte file")
    first, last = word(6), word(8)
    if first != 0:  # 1-based, as ezc3d reads it (a first frame of 0 is taken as 0-based)
        first -= 1
        last = last - 1 if last != 0 else 0
    return C3dHeader(
        parameter_block=block, processor=processor, points=word(2), analog_measurements=word(4),
        first_frame=first, last_frame=last, scale=_float(data[12:16], processor),
        data_block=data_block, analog_per_frame=word(18),
        frame_rate=_float(data[20:24], processor))


def c3d_parameters(data: bytes, header: C3dHeader, label: str) -> dict:
    """{group name: {parameter name: C3dParameter}}: the parameter section walked record
    by record as ezc3d does, every length, offset and dimension checked against the
    record and the section (which ends where the header puts the data section).
    Parameters of a group id without a group record keep their group under the name
    ""; a repeated group name keeps its first group (as ezc3d's lookup by name), a
    repeated parameter its last record (ezc3d replaces it)."""
    refuse = _refuser(label)
    size = header.data_offset  # the parameter section ends where the data section starts
    section = f"the parameter section (bytes {header.parameter_offset}-{size - 1})"
    processor = header.processor
    pos = header.parameter_offset + 4
    names: dict[int, str] = {}
    params: dict[int, dict[str, C3dParameter]] = {}

    def need(end: int, what: str, at: int) -> None:
        if end > size:
            refuse(f"the {what} at byte {at} runs past the end of {section}, to byte {end}")

    while True:
        need(pos + 1, "parameter record", pos)
        name_length = _int8(data[pos])
        if name_length == 0:  # the end of the section
            break
        need(pos + 2, "parameter record", pos)
        ident = _int8(data[pos + 1])
        if ident == 0:
            refuse(f"the parameter record at byte {pos} has group id 0")
        name_end = pos + 2 + abs(name_length)
        need(name_end + 2, f"name ({abs(name_length)} bytes) of the record", pos)
        raw_name = data[pos + 2:name_end].rstrip(b"\0")
        odd = next((i for i, b in enumerate(raw_name) if b < 0x20 or b == 0x7F), None)
        if odd is not None:
            refuse(f"the name of the record at byte {pos} ({abs(name_length)} bytes by its "
                   f"length byte) holds the control byte 0x{raw_name[odd]:02X} at byte "
                   f"{pos + 2 + odd}: its name length is wrong or the record is damaged")
        name = _c_string(raw_name)
        offset_next = int.from_bytes(data[name_end:name_end + 2],
                                     "big" if processor == "MIPS" else "little")
        what = f"group {name!r}" if ident < 0 else f"parameter {name!r}"
        at = name_end + 2
        if ident < 0:
            need(at + 1, f"{what} record", pos)
            description = _int8(data[at])
            if description < 0:
                refuse(f"the {what} record at byte {pos} gives a negative description length "
                       f"({description}) at byte {at}")
            end = at + 1 + description
            need(end, f"description of the {what} record", pos)
            names[-ident] = name  # ezc3d renames a group on each of its records
        else:
            need(at + 2, f"{what} record", pos)
            size_code, ndim = _int8(data[at]), _int8(data[at + 1])
            if size_code not in _TYPES:
                refuse(f"the {what} record at byte {pos} has element size {size_code} at byte "
                       f"{at}; C3D has -1 (char), 1 (byte), 2 (int) and 4 (float)")
            if ndim < 0:
                refuse(f"the {what} record at byte {pos} has {ndim} dimensions (byte {at + 1})")
            if ndim == 0 and size_code == -1:
                refuse(f"the {what} record at byte {pos} is a character parameter without "
                       f"dimensions (byte {at + 1})")
            need(at + 2 + ndim, f"dimensions of the {what} record", pos)
            dims = tuple(data[at + 2:at + 2 + ndim]) if ndim else (1,)
            count = math.prod(dims)
            values_at = at + 2 + ndim
            length = count * abs(size_code)
            if values_at + length - pos > _MAX_RECORD:
                refuse(f"the {what} record at byte {pos} has dimensions {_dims(dims)}, {count} "
                       f"values of {abs(size_code)} byte(s), more than a parameter record can "
                       f"hold ({_MAX_RECORD} bytes)")
            need(values_at + length + 1, f"values ({length} bytes) of the {what} record", pos)
            description = _int8(data[values_at + length])
            if description < 0:
                refuse(f"the {what} record at byte {pos} gives a negative description length "
                       f"({description}) at byte {values_at + length}")
            end = values_at + length + 1 + description
            need(end, f"description of the {what} record", pos)
            values = _values(data[values_at:values_at + length], size_code, dims, processor)
            params.setdefault(ident, {})[name] = C3dParameter(
                "", name, pos, size_code, dims, values)
        if offset_next == 0:  # the last record
            break
        target = name_end + offset_next
        if target != end:
            refuse(f"the {what} record at byte {pos} ends at byte {end}, but its next-record "
                   f"offset ({offset_next}, at byte {name_end}) points to byte {target}"
                   + (", back inside the record" if target < end else
                      f", past the end of {section}" if target >= size else ""))
        pos = end

    groups: dict[str, dict[str, C3dParameter]] = {}
    for ident in sorted(set(names) | set(params)):
        group = names.get(ident, "")
        if group in groups:
            continue  # ezc3d finds the first group of a name
        groups[group] = {name: replace(p, group=group)
                         for name, p in params.get(ident, {}).items()}
    return groups


def c3d_layout(data: bytes, label: str) -> C3dLayout:
    """The checked `C3dLayout` of the C3D file `data`: header, parameter section, the
    counts ezc3d will reconcile them to, and the data section against the file's size
    and the budgets (`MAX_C3D_POINT_SAMPLES`, `MAX_C3D_ANALOG_SAMPLES`,
    `MAX_C3D_SUBFRAMES`). Only a file this returns for is safe to give to ezc3d;
    anything else raises `RetargetError` ("... is not a readable C3D file: ...")."""
    refuse = _refuser(label)
    header = c3d_header(data, label)
    if header.processor == "MIPS":
        refuse("its processor type is 86 (MIPS, big-endian), which ezc3d does not read; "
               "export it for Intel (PC) processors")
    groups = c3d_parameters(data, header, label)
    point = groups.get("POINT", {})

    def values(group: str, name: str, kind: str):
        """The parameter's values as ezc3d's valuesAsInt ("int"), valuesAsDouble
        ("float") or valuesConvertedAsInt ("number") give them; None when it is absent
        and ezc3d gives the group no default."""
        param = groups.get(group, {}).get(name)
        if param is None:
            return _DEFAULTS.get(group, {}).get(name)
        wanted = {"int": (1, 2), "float": (4,), "number": (1, 2, 4)}[kind]
        if param.type not in wanted:
            if kind == "number" or not param.is_empty:  # ezc3d throws; an empty one reads []
                refuse(f"{param.where} is {_TYPES[param.type]}; ezc3d reads it as "
                       + {"int": "an integer", "float": "a float", "number": "a number"}[kind])
            return []
        return list(param.values)

    def first(group: str, name: str, kind: str):
        """The parameter's first value, which ezc3d reads without checking there is one."""
        found = values(group, name, kind)
        if found is None:
            return None
        if not found:
            param = groups[group][name]
            refuse(f"{param.where} holds no value (dimensions {_dims(param.dims)}); ezc3d reads "
                   "its first")
        if kind != "int" and not math.isfinite(found[0]):
            refuse(f"{group}:{name} is {found[0]}")
        return found[0]

    def rate(group: str, name: str, value) -> float:
        if not 0 <= value <= MAX_C3D_RATE:
            refuse(f"{group}:{name} is {value:g} Hz; a rate is between 0 and {MAX_C3D_RATE:g} Hz")
        return value

    # ezc3d::c3d::updateHeader: the parameters win over the header
    point_used = first("POINT", "USED", "int")
    if point_used < 0:
        refuse(f"POINT:USED is {point_used}")
    frames_param = first("POINT", "FRAMES", "number")
    point_rate = rate("POINT", "RATE", first("POINT", "RATE", "float"))
    analog_rate = rate("ANALOG", "RATE", first("ANALOG", "RATE", "float"))
    analog_used = first("ANALOG", "USED", "int")
    if analog_used < 0:
        refuse(f"ANALOG:USED is {analog_used}")
    gen_scale = first("ANALOG", "GEN_SCALE", "float")
    del gen_scale  # read by ezc3d for every file: it must exist, its value does not matter here
    if not (math.isfinite(header.frame_rate) and 0 <= header.frame_rate <= MAX_C3D_RATE):
        refuse(f"the header's frame rate (bytes 20-23) is {header.frame_rate:g} Hz")
    rotation = "ROTATION" in groups

    per_frame = header.analog_per_frame
    header_analogs = header.analog_measurements // per_frame if per_frame else 0
    frames_before = 0 if header.points == 0 and header_analogs == 0 \
        else header.last_frame - header.first_frame + 1
    frames_declared = int(frames_param)  # ezc3d truncates a float FRAMES
    to_end = False  # whether ezc3d reads frames up to the end of the file
    if frames_declared < 0:
        if point["FRAMES"].type != 2:
            refuse(f"{point['FRAMES'].where} is {frames_param}")
        # an INT holds 32768-65535 frames as negative numbers; ezc3d then counts
        # 2**64 - n frames, so it reads to the end of the file
        frames_declared += 1 << 16
        to_end = True
    last = header.last_frame
    if frames_declared != 0 and frames_declared != frames_before:
        last = frames_declared + header.first_frame - 1
    frame_rate = header.frame_rate
    if _int(point_rate * 1e4) != _int(header.frame_rate * 1e4) \
            and not (point_rate == 0 and point_used):
        frame_rate = point_rate
    if int(point_rate) != 0 and int(analog_rate / point_rate) != per_frame \
            and not (per_frame == 1 and "SHADOW" in groups):
        per_frame = int(analog_rate / point_rate)
    analog_channels = analog_used if per_frame else 0
    points = point_used
    if points == 0 and analog_channels == 0 and not rotation:
        frames = 0
    else:
        frames = last - header.first_frame + 1
        if frames <= 0:
            refuse(f"the header's last frame ({header.last_frame}, 0-based, bytes 8-9) is before "
                   f"its first ({header.first_frame}, bytes 6-7)")
        if frames == 0xFFFF and not rotation:
            to_end = True  # more than 65535 frames, as Vicon writes them

    labels = _strings(groups, "POINT", "LABELS")
    if len(labels) < points:
        refuse(f"POINT:USED is {points} but POINT:LABELS (with LABELS2, ...) names "
               f"{len(labels)} points")

    # the data section (ezc3d::DataNS::Data)
    scales = []
    if points:
        scales = _numbered(groups, "POINT", "SCALE", values, "float")
        if not scales:
            refuse("POINT:SCALE holds no value; ezc3d reads the scale of each point from it")
        bad = next((s for s in scales if not math.isfinite(s)), None)
        if bad is not None:
            refuse(f"POINT:SCALE holds {bad}")
    if analog_channels:
        shadow = "SHADOW" in groups
        for name, kind in (("SCALE", "float"), ("OFFSET", "int")):
            found = _numbered(groups, "ANALOG", name, values, kind)
            if len(found) < analog_channels and not (shadow and not found):
                refuse(f"ANALOG:USED is {analog_channels} but ANALOG:{name} (with {name}2, ...) "
                       f"holds {len(found)} values, one per channel")
    point_bytes = sum(16 if (scales[i] if i < len(scales) else scales[0]) < 0 else 8
                      for i in range(points))
    sample_bytes = 4 if header.scale < 0 else 2
    frame_bytes = point_bytes + per_frame * analog_channels * sample_bytes
    available = len(data) - header.data_offset
    if to_end and rotation:
        refuse(f"POINT:FRAMES is {int(frames_param)} and the file has a ROTATION group, which "
               "ezc3d then reads out of bounds")
    contents = (f"{points} point(s) of {'4 floats' if scales and scales[0] < 0 else '4 int16'}"
                + (f", {per_frame} x {analog_channels} analog samples" if analog_channels else ""))
    if frames * frame_bytes > available:
        refuse(f"{frames} frames of {frame_bytes} bytes ({contents}) need "
               f"{frames * frame_bytes} bytes from byte {header.data_offset} (block "
               f"{header.data_block}), but the file has {available} bytes there")
    if to_end and frame_bytes:
        frames = available // frame_bytes
    _within("point samples", frames * points, MAX_C3D_POINT_SAMPLES, refuse,
            f"{frames} frames x {points} points")
    _within("analog samples", frames * per_frame * analog_channels, MAX_C3D_ANALOG_SAMPLES,
            refuse, f"{frames} frames x {per_frame} samples x {analog_channels} channels")
    ratio = 0
    if rotation:
        ratio = _rotations(groups, frames, frame_rate, len(data), first, rate, refuse)
    _within("frames and sub-frames", frames * (1 + per_frame + ratio), MAX_C3D_SUBFRAMES,
            refuse, f"{frames} frames x (1 + {per_frame} analog + {ratio} rotation sub-frames)")
    return C3dLayout(header=header, groups=groups, frames=frames, points=points,
                     analog_channels=analog_channels, analog_per_frame=per_frame,
                     frame_bytes=frame_bytes, labels=tuple(labels))


def _rotations(groups, frames, frame_rate, size, first, rate, refuse) -> int:
    """The rotation ratio (sub-frames per frame) of ezc3d's ROTATION group (which ezc3d
    writes into every file), its data checked to fit the file."""
    group = groups["ROTATION"]
    for name in ("DATA_START", "USED"):
        if name not in group:
            refuse(f"the ROTATION group has no {name} parameter")
    start = first("ROTATION", "DATA_START", "int")
    used = first("ROTATION", "USED", "int")
    if used < 0:
        refuse(f"ROTATION:USED is {used}")
    if "RATIO" in group:
        ratio = first("ROTATION", "RATIO", "int")
        if ratio < 0:
            refuse(f"ROTATION:RATIO is {ratio}")
    elif "RATE" in group:
        rotation_rate = rate("ROTATION", "RATE", first("ROTATION", "RATE", "float"))
        if frame_rate <= 0:
            refuse("ROTATION:RATE is given but the point rate is 0")
        ratio = int(rotation_rate / frame_rate)
    else:
        refuse("the ROTATION group has neither RATIO nor RATE")
    offset = (start - 1) * _BLOCK
    need = frames * ratio * used * 17 * 4  # a 4 x 4 matrix and a reliability, floats
    if 0 <= offset <= size and need > size - offset:
        refuse(f"{frames} frames of {ratio} x {used} rotations need {need} bytes from byte "
               f"{offset} (ROTATION:DATA_START {start}), but the file has {size - offset} there")
    _within("rotation samples", frames * ratio * used, MAX_C3D_POINT_SAMPLES, refuse,
            f"{frames} frames x {ratio} x {used} rotations")
    return ratio


def _within(what, count, limit, refuse, how) -> None:
    if count > limit:
        refuse(f"it declares {count} {what} ({how}); at most {limit} are read")


def _numbered(groups, group, name, values, kind) -> list:
    """NAME, NAME2, NAME3, ... concatenated, as ezc3d gathers scales and offsets."""
    out = list(values(group, name, kind) or [])
    i = 2
    while f"{name}{i}" in groups.get(group, {}):
        out += values(group, f"{name}{i}", kind)
        i += 1
    return out


def _strings(groups, group, name) -> list[str]:
    """NAME, NAME2, ... strings (ezc3d's pointNames); non-string parameters hold none."""
    table = groups.get(group, {})
    out, i = [], 1
    while (key := name if i == 1 else f"{name}{i}") in table:
        param = table[key]
        if param.type == -1:
            out += list(param.values)
        i += 1
    return out


def _values(raw: bytes, size_code: int, dims: tuple, processor: str) -> tuple:
    """The record's values as ezc3d reads them: signed ints, floats, or strings."""
    if size_code == -1:
        # ezc3d reads each character as a C string (a NUL reads as nothing) and joins
        # dims[0] of them per string; one string, or none when dims[0] is 0, for 1 dimension
        width = dims[0]
        if len(dims) == 1:
            return (_chars(raw),) if width else ()
        return tuple(_chars(raw[i * width:(i + 1) * width]) for i in range(math.prod(dims[1:])))
    if size_code == 1:
        return tuple(_int8(b) for b in raw)
    if size_code == 2:
        order = ">" if processor == "MIPS" else "<"
        return struct.unpack(f"{order}{len(raw) // 2}h", raw)
    return tuple(_float(raw[i:i + 4], processor) for i in range(0, len(raw), 4))


def _dims(dims: tuple) -> str:
    return "x".join(map(str, dims)) if dims else "none"


def _chars(raw: bytes) -> str:
    """A string of a character parameter: ezc3d reads each byte as a C string (a NUL
    reads as nothing) and drops trailing spaces."""
    return raw.replace(b"\0", b"").decode("latin-1").rstrip(" ")


def _c_string(raw: bytes) -> str:
    """The bytes up to the first NUL (ezc3d makes std::strings from char arrays)."""
    return raw.split(b"\0", 1)[0].decode("latin-1")


def _int(x: float) -> int:
    """C's static_cast<int> as x86 does it: out of range (or NaN) gives INT_MIN."""
    return int(x) if math.isfinite(x) and -2**31 <= x < 2**31 else -2**31


def _int8(byte: int) -> int:
    return byte - 256 if byte > 127 else byte


def _word_reader(data: bytes, processor: str):
    order = "big" if processor == "MIPS" else "little"
    return lambda at: int.from_bytes(data[at:at + 2], order)


def _float(raw: bytes, processor: str) -> float:
    """A 4-byte float in the processor's format: Intel little-endian IEEE, MIPS big-endian
    IEEE, DEC (VAX F) as ezc3d converts it (words swapped, exponent less one)."""
    if processor == "MIPS":
        return struct.unpack(">f", raw)[0]
    if processor == "DEC":
        high = raw[1] - 1 if raw[1] != 0 else 0
        raw = bytes([raw[2], raw[3], raw[0], high & 0xFF])
    return struct.unpack("<f", raw)[0]


def _refuser(label: str, problem: str = "is not a readable C3D file"):
    def refuse(what: str):
        raise RetargetError(f"{label} {problem}: {what}")
    return refuse
