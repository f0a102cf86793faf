"""Tests for retarget.sources.files: every take format read back against the ground truth
it was written from (CSV, JSON, NPY, TRC, C3D by ezc3d, glTF morph-target and skinned
animation by pygltflib, OBJ-sequence zips by trimesh), and the errors for bad files."""

from __future__ import annotations

import io
import json
import zipfile

import numpy as np
import pygltflib
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from retarget.errors import RetargetError
from retarget.layouts import IBUG68_TO_MEDIAPIPE468, get_layout
from retarget.mesh import load_mesh
from retarget.sample_face import demo_weights, posed_vertices, sample_face
from retarget.sources import c3d_header, files, obj_sequence
from retarget.sources import take as take_module
from retarget.sources.c3d_header import c3d_layout
from retarget.sources.files import read_take, write_take_csv
from retarget.sources.take import Take

IBUG = get_layout("ibug68")
DUTREVE = get_layout("dutreve21")
FACE = sample_face(1)
N_FRAMES = 10
# demo frames where something moves, taken every 0.1 s from 3.5 s (jaw, brows)
WEIGHTS = demo_weights(int(4.5 * 30), 30)[105::3][:N_FRAMES]
TRUTH = posed_vertices(FACE, WEIGHTS)[:, FACE.landmarks68]          # (F, 68, 3) cm


def _truth_take(dims=3) -> Take:
    return Take(TRUTH[..., :dims], IBUG.point_names, 10.0, layout="ibug68", source="truth")


# --- landmark tables ---------------------------------------------------------------------

def test_csv_round_trip_with_lost_points(tmp_path):
    take = _truth_take()
    take.points[3, 5] = np.nan
    path = tmp_path / "take.csv"
    write_take_csv(take, path)
    back = read_take(path)
    assert back.layout == "ibug68" and back.source == "csv"
    np.testing.assert_array_equal(back.points, take.points)
    np.testing.assert_allclose(back.frame_times(), take.frame_times())
    assert back.fps == pytest.approx(10.0)
    sub = read_take(path.read_bytes(), filename="take.csv", layout="dutreve21")
    np.testing.assert_array_equal(sub.points, take.points[:, list(DUTREVE.ibug68)])


def test_csv_accepts_other_separators_orders_quotes_and_a_bom():
    text = "\ufeff\"Time\",b.Y,a.x,a.y,b.X\n0.0,1,2,3,4\n0.5,5,6,,8\n"
    take = read_take(text.encode(), filename="x.csv")
    assert take.names == ("b", "a") and take.dims == 2
    np.testing.assert_array_equal(take.points[0], [[4, 1], [2, 3]])
    assert np.isnan(take.points[1, 1]).all()
    assert take.fps == 2.0 and not take.meta["fps_assumed"]
    no_time = read_take(b"p_x,p_y\n1,2\n3,4\n", filename="x.csv")
    assert no_time.fps == 30.0 and no_time.meta["fps_assumed"]
    assert read_take(b"p_x,p_y\n1,2\n3,4\n", filename="x.csv", fps=50).fps == 50.0


@pytest.mark.parametrize("text, message", [
    ("frame,a_x,a_y\n0,1,2\n1,1,oops\n", r"row 3, column 'a_y': 'oops' is not a number"),
    ("a_x,a_y,b_x\n1,2,3\n", r"point 'b' has no y column"),
    ("a_x,a_y,a_z,b_x,b_y\n1,2,3,4,5\n", r"point 'b' has no z column \(other points have z\)"),
    ("a_x,a_y\n1,2\n1,2,3\n", "row 3 has 3 cells, the header has 2"),
    ("a_x,a_y,conf\n1,2,0.9\n", "column 'conf' is neither frame, time nor a coordinate"),
    ("a_x,a_y,b_x,b_y\n1,2,,\n3,4,nan,nan\n", r"point\(s\) have no position in any frame: b"),
    ("a_x,a_y\n", "has a header but no frames"),
    ("", "is empty"),
    ("a_x,a_y\n1,inf\n", "row 2, column 'a_y' is infinite"),
    ("time,a_x,a_y\n0.2,1,2\n0.1,1,2\n", "times go backwards at frame 1"),
])
def test_csv_errors_name_the_row_column_or_point(text, message):
    with pytest.raises(RetargetError, match=message):
        read_take(text.encode(), filename="bad.csv")


def test_csv_cell_over_the_csv_field_limit_is_refused_naming_the_row():
    text = "a_x,a_y\n1,2\n3," + "9" * 200_000 + "\n"
    with pytest.raises(RetargetError, match=r"'big.csv': row 3 has a cell longer than 131072 characters"):
        read_take(text.encode(), filename="big.csv")


def test_csv_and_trc_tables_over_the_value_budget_are_refused_before_their_arrays(monkeypatch):
    monkeypatch.setattr(files, "MAX_TAKE_VALUES", 10)
    with pytest.raises(RetargetError, match=r"row 7 takes the table past 10 values \(6 rows of 2 columns\)"):
        read_take(b"a_x,a_y\n" + b"1,2\n" * 8, filename="long.csv")
    text = _trc(["A"], np.ones((3, 1, 3)))  # 5 columns a row
    with pytest.raises(RetargetError, match=r"row 9 takes the table past 10 values \(3 rows of 5 columns\)"):
        read_take(text.encode(), filename="long.trc")


def test_csv_missing_layout_points_are_listed():
    take = _truth_take().to_layout("dutreve21")
    buffer = io.StringIO()
    write_take_csv(Take(take.points[:, 2:], take.names[2:], 10), buffer)
    with pytest.raises(RetargetError, match="lacks 2 of the 21 points.*brow_right_outer, brow_right_middle"):
        read_take(buffer.getvalue().encode(), filename="t.csv", layout="dutreve21")


def test_json_names_and_layout_forms():
    frames = TRUTH.tolist()
    frames[2][7] = None
    frames[4][9] = [None, None, None]
    doc = {"fps": 10, "names": list(IBUG.point_names), "frames": frames, "units": "cm"}
    take = read_take(json.dumps(doc).encode(), filename="t.json", layout="dutreve21")
    expected = TRUTH.astype(np.float32).copy()
    expected[2, 7] = expected[4, 9] = np.nan
    np.testing.assert_array_equal(take.points, expected[:, list(DUTREVE.ibug68)])
    assert take.meta["units"] == "cm" and take.fps == 10
    sub = TRUTH[:, list(DUTREVE.ibug68), :2].tolist()
    doc = {"layout": "dutreve21", "frames": sub, "times": [0.5 + 0.04 * i for i in range(N_FRAMES)]}
    take = read_take(json.dumps(doc).encode(), filename="t.json")
    assert take.layout == "dutreve21" and take.dims == 2
    np.testing.assert_allclose(take.times, 0.04 * np.arange(N_FRAMES))
    assert take.fps == pytest.approx(25.0)


@pytest.mark.parametrize("doc, message", [
    ({"frames": [[[1, 2]]]}, 'give "names" or "layout"'),
    ({"names": ["a", "b"], "frames": [[[1, 2], [3, 4]], [[1, 2]]]}, "frame 1 has 1 points, names has 2"),
    ({"names": ["a", "b"], "frames": [[[1, 2], [3, 4, 5]]]}, r"frame 0, point 'b' must be \[x, y\] or"),
    ({"names": ["a"], "frames": [[[1, "x"]]]}, "frame 0, point 'a': 'x' is not a number"),
    ({"names": ["a"], "frames": [[None]]}, "every point is null"),
    ({"names": ["a"], "frames": [[[1, 2]]], "times": [0, 1]}, "one time per frame"),
    ([1, 2], 'an object with "frames"'),
])
def test_json_errors(doc, message):
    with pytest.raises(RetargetError, match=message):
        read_take(json.dumps(doc).encode(), filename="bad.json")
    with pytest.raises(RetargetError, match="is not JSON"):
        read_take(b"{", filename="bad.json")


def test_json_nested_too_deeply_is_refused_before_parsing():
    with pytest.raises(RetargetError, match=r"'deep.json' is nested too deeply: 200000 levels of \[ and \{"):
        read_take(b"[" * 200_000, filename="deep.json")
    with pytest.raises(RetargetError, match="nested too deeply: 65 levels"):
        read_take(b'{"frames": ' + b"[" * 64 + b"]" * 64 + b"}", filename="deep.json")
    # brackets inside strings do not count
    doc = {"names": ["[" * 100 + '\\"{'], "frames": [[[1, 2]]]}
    assert read_take(json.dumps(doc).encode(), filename="ok.json").names == ("[" * 100 + '\\"{',)


def test_json_take_over_the_value_budget_is_refused_before_its_array(monkeypatch):
    monkeypatch.setattr(files, "MAX_TAKE_VALUES", 10)
    doc = {"names": ["a", "b"], "frames": [[[1, 2, 3], [4, 5, 6]]] * 2}
    with pytest.raises(RetargetError, match="2 frames of 2 points in 3D are 12 values; at most 10"):
        read_take(json.dumps(doc).encode(), filename="long.json")


def test_npy_of_layout_ibug_and_mediapipe_points():
    def npy(array):
        buffer = io.BytesIO()
        np.save(buffer, array)
        return buffer.getvalue()

    take = read_take(npy(TRUTH), filename="t.npy", layout="dutreve21", fps=24)
    np.testing.assert_array_equal(take.points, TRUTH[:, list(DUTREVE.ibug68)].astype(np.float32))
    assert take.fps == 24 and take.layout == "dutreve21"
    same = read_take(npy(take.points), filename="t.npy", layout="dutreve21")
    np.testing.assert_array_equal(same.points, take.points)
    mesh = np.random.default_rng(0).normal(size=(3, 468, 3))
    take = read_take(npy(mesh), filename="m.npy", layout="ibug51")
    expected = mesh[:, [IBUG68_TO_MEDIAPIPE468[i] for i in range(17, 68)]]
    np.testing.assert_array_equal(take.points, expected.astype(np.float32))
    with pytest.raises(RetargetError, match="choose its layout"):
        read_take(npy(TRUTH), filename="t.npy")
    with pytest.raises(RetargetError, match="has 5 points per frame; layout 'ibug68' has 68"):
        read_take(npy(np.zeros((2, 5, 3))), filename="t.npy", layout="ibug68")
    with pytest.raises(RetargetError, match=r"expected an \(F, N, 2\|3\) numeric array"):
        read_take(npy(np.zeros((2, 68))), filename="t.npy", layout="ibug68")
    with pytest.raises(RetargetError, match="not a NumPy .npy array"):
        read_take(b"junk", filename="t.npy", layout="ibug68")


def _npy_with_header(header: dict, data: bytes = b"\0" * 24) -> bytes:
    out = io.BytesIO()
    np.lib.format.write_array_header_1_0(out, header)
    return out.getvalue() + data


@pytest.mark.parametrize("header, message", [
    # 1.48 TiB claimed by a 152-byte file
    ({"descr": "<f8", "fortran_order": False, "shape": (10 ** 8, 678, 3)},
     r"'t.npy': its header declares a 100000000x678x3 float64 array, 1627200000000 bytes, but "
     r"24 bytes of data follow it"),
    ({"descr": "<f8", "fortran_order": False, "shape": (-1, 68, 3)}, "negative shape"),
    ({"descr": "<f8", "fortran_order": 1, "shape": (1, 1, 3)},
     r"is not a NumPy .npy array: its header is malformed \(ValueError: fortran_order is not a valid bool"),
    ({"descr": [("x", "<f8"), ("y", "<f8")], "fortran_order": False, "shape": (1, 1, 3)},
     r"has dtype \[\('x', '<f8'\), \('y', '<f8'\)\]; a plain number or string type is read"),
], ids=["claims-1.48-TiB", "negative-shape", "fortran-order-not-bool", "fields"])
def test_npy_header_is_checked_before_the_array_is_loaded(header, message):
    with pytest.raises(RetargetError, match=message):
        read_take(_npy_with_header(header), filename="t.npy", layout="ibug68")


def test_npy_objects_budget_and_fortran_order(monkeypatch):
    buffer = io.BytesIO()
    np.save(buffer, np.array([[[1, 2]]], dtype=object), allow_pickle=True)
    with pytest.raises(RetargetError, match=r"'o.npy' holds Python objects \(dtype object\)"):
        read_take(buffer.getvalue(), filename="o.npy", layout="ibug68")
    buffer = io.BytesIO()
    np.save(buffer, np.asfortranarray(TRUTH))
    take = read_take(buffer.getvalue(), filename="f.npy", layout="ibug68")
    np.testing.assert_array_equal(take.points, TRUTH.astype(np.float32))
    monkeypatch.setattr(take_module, "MAX_TAKE_VALUES", 100)
    with pytest.raises(RetargetError, match=r"declares a 10x68x3 array, 2040 values; at most 100 are read"):
        read_take(buffer.getvalue(), filename="f.npy", layout="ibug68")


def test_npz_take_files_are_read():
    buffer = io.BytesIO()
    _truth_take().save(buffer)
    take = read_take(buffer.getvalue(), filename="t.npz", layout="dutreve21")
    np.testing.assert_array_equal(take.points, TRUTH[:, list(DUTREVE.ibug68)].astype(np.float32))


def test_unsupported_extension_and_missing_file(tmp_path):
    with pytest.raises(RetargetError, match="unsupported take file type '.bvh'"):
        read_take(b"", filename="a.bvh")
    with pytest.raises(RetargetError, match="could not read"):
        read_take(tmp_path / "none.csv")
    with pytest.raises(RetargetError, match="fps must be a positive number"):
        read_take(b"a_x,a_y\n1,2\n", filename="a.csv", fps=-1)


# --- motion capture ----------------------------------------------------------------------

def _trc(labels, points, rate=100.0, units="mm", drop=()) -> str:
    f, n = points.shape[:2]
    lines = ["PathFileType\t4\t(X/Y/Z)\ttake.trc",
             "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
             f"{rate}\t{rate}\t{f}\t{n}\t{units}\t{rate}\t1\t{f}",
             "Frame#\tTime\t" + "\t\t\t".join(labels) + "\t\t",
             "\t\t" + "\t".join(f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(n)),
             ""]
    for i in range(f):
        cells = [str(i + 1), f"{i / rate:.5f}"]
        for j in range(n):
            cells += [""] * 3 if (i, j) in drop else [f"{v:.6f}" for v in points[i, j]]
        lines.append("\t".join(cells))
    return "\n".join(lines) + "\n"


def test_trc_markers_with_gaps_and_a_mapping():
    labels = [f"M{i}" for i in range(21)]
    mm = TRUTH[:, list(DUTREVE.ibug68)] * 10
    text = _trc(labels, mm, drop={(2, 4), (N_FRAMES - 1, 20)})
    mapping = dict(zip(labels, DUTREVE.point_names))
    take = read_take(text.encode(), filename="t.trc", layout="dutreve21", mapping=mapping)
    expected = mm.astype(np.float32).copy()
    expected[2, 4] = expected[N_FRAMES - 1, 20] = np.nan
    np.testing.assert_allclose(take.points, expected, atol=1e-5, equal_nan=True)
    assert take.fps == 100 and take.meta["units"] == "mm" and take.source == "trc"
    np.testing.assert_allclose(take.times, np.arange(N_FRAMES) / 100, atol=1e-5)
    # a row that stops early (the last marker empty, trailing cells left out)
    short = text.rstrip("\n").rsplit("\n", 1)[0] + "\n" + "\t".join(
        [str(N_FRAMES), "0.09"] + [f"{v:.6f}" for v in mm[-1, :20].ravel()]) + "\n"
    take = read_take(short.encode(), filename="t.trc")
    assert take.names == tuple(labels) and np.isnan(take.points[-1, 20]).all()


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("PathFileType", "Path"), "must start with a PathFileType line"),
    (lambda t: t.replace("\t3\tmm", "\t4\tmm"), "NumMarkers is 4 but line 4 names 3 markers"),
    (lambda t: t.replace("0.000000", "x0"), r"row 7, column 'A X': 'x0' is not a number"),
    (lambda t: t.rstrip("\n") + "\t1\t2\t3\n", "has 14 cells; 3 markers take 11"),
])
def test_trc_errors(edit, message):
    points = np.ones((2, 3, 3))
    points[0, 0, 0] = 0.0
    text = _trc(["A", "B", "C"], points)
    with pytest.raises(RetargetError, match=message):
        read_take(edit(text).encode(), filename="bad.trc")


def _c3d_bytes(tmp_path, labels, points, rate=120.0, residual_lost=()):
    import ezc3d

    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c3d["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    if not labels:  # analog data only (an EMG recording, say)
        c3d["parameters"]["ANALOG"]["RATE"]["value"] = [1000.0]
        c3d["parameters"]["ANALOG"]["LABELS"]["value"] = ("emg",)
        c3d["data"]["points"] = np.zeros((4, 0, 5))
        c3d["data"]["analogs"] = np.zeros((1, 1, 50))
    else:
        c3d["parameters"]["POINT"]["LABELS"]["value"] = tuple(labels)
        f, n = points.shape[:2]
        data = np.ones((4, n, f))
        data[:3] = points.transpose(2, 1, 0)
        c3d["data"]["points"] = data
        residuals = np.zeros((1, n, f))
        for frame, point in residual_lost:
            residuals[0, point, frame] = -1.0
        c3d["data"]["meta_points"]["residuals"] = residuals
        c3d["data"]["meta_points"]["camera_masks"] = np.zeros((7, n, f), dtype=bool)
    path = tmp_path / "take.c3d"
    c3d.write(str(path))
    return path.read_bytes()


def test_c3d_labels_rate_units_and_lost_markers(tmp_path):
    mm = TRUTH * 10
    labels = list(IBUG.point_names)
    labels[30] = "NOSE"
    data = _c3d_bytes(tmp_path, labels, mm, residual_lost=[(3, 17), (5, 30)])
    take = read_take(data, filename="t.c3d", layout="dutreve21", mapping={"NOSE": "nose_tip"})
    expected = mm.astype(np.float32)[:, list(DUTREVE.ibug68)].copy()
    expected[3, DUTREVE.index("brow_right_outer")] = np.nan
    expected[5, DUTREVE.index("nose_tip")] = np.nan
    np.testing.assert_allclose(take.points, expected, rtol=1e-6, equal_nan=True)
    assert take.fps == 120 and take.meta["units"] == "mm" and take.source == "c3d"
    raw = read_take(data, filename="t.c3d")
    assert raw.names == tuple(labels) and raw.layout is None


def test_c3d_without_points_and_repeated_labels(tmp_path):
    with pytest.raises(RetargetError, match="holds no 3D point data"):
        read_take(_c3d_bytes(tmp_path, [], None), filename="empty.c3d")
    take = read_take(_c3d_bytes(tmp_path, ["A", "A", "B"], np.ones((2, 3, 3))), filename="r.c3d")
    assert take.names == ("A", "A_2", "B")
    with pytest.raises(RetargetError, match="is not a C3D file"):
        read_take(b"x" * 600, filename="bad.c3d")


def _c3d_points_and_analogs(tmp_path) -> bytes:
    """A valid 2 KB C3D written by ezc3d: 6 frames of 3 float points at 100 Hz and 2
    analog channels at 400 Hz (4 samples per frame)."""
    import ezc3d

    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c3d["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = ("A", "B", "C")
    c3d["parameters"]["ANALOG"]["RATE"]["value"] = [400.0]
    c3d["parameters"]["ANALOG"]["LABELS"]["value"] = ("emg1", "emg2")
    points = np.ones((4, 3, 6))
    points[:3] = np.random.default_rng(0).normal(size=(3, 3, 6))
    c3d["data"]["points"] = points
    c3d["data"]["analogs"] = np.random.default_rng(1).normal(size=(1, 2, 24))
    c3d["data"]["meta_points"]["residuals"] = np.zeros((1, 3, 6))
    c3d["data"]["meta_points"]["camera_masks"] = np.zeros((7, 3, 6), dtype=bool)
    path = tmp_path / "valid.c3d"
    c3d.write(str(path))
    return path.read_bytes()


def test_c3d_check_passes_a_valid_file_which_reads_as_ezc3d_reads_it(tmp_path):
    import ezc3d

    data = _c3d_points_and_analogs(tmp_path)
    layout = c3d_layout(data, "'v.c3d'")
    assert (layout.frames, layout.points, layout.analog_channels, layout.analog_per_frame) == (6, 3, 2, 4)
    assert layout.labels == ("A", "B", "C") and layout.header.processor == "Intel"
    assert layout.frame_bytes == 3 * 16 + 4 * 2 * 4  # float points, float analog samples
    take = read_take(data, filename="v.c3d")
    direct = ezc3d.c3d(str(tmp_path / "valid.c3d"))["data"]["points"]
    np.testing.assert_array_equal(take.points, direct[:3].transpose(2, 1, 0).astype(np.float32))
    assert take.names == ("A", "B", "C") and take.fps == 100


def _record(data: bytes, group: str, name: str) -> tuple[int, int]:
    """(byte of the record's name-length byte, byte of its next-record offset)."""
    offset = c3d_layout(data, "x").groups[group][name].offset
    return offset, offset + 2 + len(name)


def _set(data: bytes, at: int, raw: bytes) -> bytes:
    return data[:at] + raw + data[at + len(raw):]


def _labels_dims(data, dims: bytes) -> bytes:
    """POINT:LABELS given len(dims) dimensions of those sizes (over its values)."""
    _, field = _record(data, "POINT", "LABELS")
    return _set(data, field + 3, bytes([len(dims)]) + dims)


def _frames(data, count: int) -> bytes:
    _, field = _record(data, "POINT", "FRAMES")
    return _set(data, field + 4, count.to_bytes(2, "little"))


@pytest.mark.parametrize("corrupt, message", [
    (lambda d: _set(d, 1, b"\x51"),
     r"'c.c3d' is not a C3D file \(no C3D header\): byte 1 is 0x51 where a C3D header has the key 0x50"),
    (lambda d: _set(d, 0, b"\xc8"),
     r"not a readable C3D file: byte 0 puts the parameter section in block 200, at byte 101888, "
     r"past the end of the 2048-byte file"),
    (lambda d: _set(d, 515, b"\x63"),
     r"byte 515, the processor type in the parameter section's first 4 bytes, is 99"),
    (lambda d: _set(d, 16, (100).to_bytes(2, "little")),
     r"bytes 16-17 put the data section in block 100, at byte 50688, past the end of the 2048-byte file"),
    (lambda d: _set(d, _record(d, "POINT", "USED")[0], b"\x7f"),
     r"the name of the record at byte 526 \(127 bytes by its length byte\) holds the control "
     r"byte 0x07 at byte 532: its name length is wrong"),
    (lambda d: _set(d, _record(d, "POINT", "USED")[1], b"\x01\x00"),
     r"the parameter 'USED' record at byte 526 ends at byte 539, but its next-record offset "
     r"\(1, at byte 532\) points to byte 533, back inside the record"),
    (lambda d: _set(d, _record(d, "POINT", "USED")[1], b"\xff\xff"),
     r"points to byte 66067, past the end of the parameter section \(bytes 512-1535\)"),
    (lambda d: _labels_dims(d, b"\xff" * 4),
     r"the parameter 'LABELS' record at byte 539 has dimensions 255x255x255x255, 4228250625 "
     r"values of 1 byte\(s\), more than a parameter record can hold \(65535 bytes\)"),
    (lambda d: _set(d, _record(d, "POINT", "LABELS")[1] + 3, b"\xa0"),
     r"the parameter 'LABELS' record at byte 539 has -96 dimensions \(byte 550\)"),
    (lambda d: _set(d, _record(d, "POINT", "USED")[1] + 6, b"\xff"),
     r"the parameter 'USED' record at byte 526 gives a negative description length \(-1\) at byte 538"),
    (lambda d: _frames(d, 1000),
     r"1000 frames of 80 bytes \(3 point\(s\) of 4 floats, 4 x 2 analog samples\) need 80000 "
     r"bytes from byte 1536 \(block 4\), but the file has 512 bytes there"),
    (lambda d: _set(d, _record(d, "POINT", "USED")[1] + 4, b"\x07"),
     r"POINT:USED is 7 but POINT:LABELS \(with LABELS2, ...\) names 3 points"),
    (lambda d: _set(d, _record(d, "ANALOG", "USED")[1] + 4, b"\x05"),
     r"ANALOG:USED is 5 but ANALOG:SCALE \(with SCALE2, ...\) holds 2 values, one per channel"),
    (lambda d: _set(d, 16, b"\x02"),
     r"bytes 16-17 put the data section in block 2, not after the parameter section \(block 2"),
], ids=["key", "parameter-block-past-eof", "processor", "data-block-past-eof", "name-length",
        "next-offset-backwards", "next-offset-out", "dims-4e9", "negative-dims", "negative-description",
        "frames-past-data", "used-over-labels", "analog-used-over-scales", "data-block-in-parameters"])
def test_c3d_corruptions_are_refused_before_ezc3d_naming_the_byte(tmp_path, corrupt, message):
    data = corrupt(_c3d_points_and_analogs(tmp_path))
    with pytest.raises(RetargetError, match=message):
        read_take(data, filename="c.c3d")


def test_c3d_budget_is_checked_before_ezc3d_reads(tmp_path, monkeypatch):
    monkeypatch.setattr(c3d_header, "MAX_C3D_POINT_SAMPLES", 10)
    with pytest.raises(RetargetError, match=r"declares 18 point samples \(6 frames x 3 points\); at most 10"):
        read_take(_c3d_points_and_analogs(tmp_path), filename="big.c3d")


def test_c3d_header_decodes_dec_and_mips_numbers_and_refuses_mips(tmp_path):
    import struct

    data = _c3d_points_and_analogs(tmp_path)
    # DEC (VAX F) floats: the IEEE bytes with the words swapped and the exponent one higher
    dec = _set(_set(_set(data, 515, b"\x55"), 12, b"\x80\xc0\x00\x00"), 20, b"\xc8\x43\x00\x00")
    header = c3d_header.c3d_header(dec, "'d.c3d'")
    assert (header.processor, header.scale, header.frame_rate) == ("DEC", -1.0, 100.0)
    mips = _set(_set(data, 515, b"\x56"), 20, struct.pack(">f", 100.0))
    mips = _set(_set(mips, 2, (3).to_bytes(2, "big")), 16, (4).to_bytes(2, "big"))
    header = c3d_header.c3d_header(mips, "'m.c3d'")
    assert (header.processor, header.points, header.frame_rate) == ("MIPS", 3, 100.0)
    with pytest.raises(RetargetError, match=r"processor type is 86 \(MIPS, big-endian\), which ezc3d does not read"):
        read_take(mips, filename="m.c3d")
    with pytest.raises(RetargetError, match=r"byte 0, the block number of the parameter section, is 0"):
        read_take(_set(data, 0, b"\x00"), filename="z.c3d")


def _mutants(data: bytes, count: int, seed: int):
    """`count` copies of `data` with 1 to 4 random bytes changed (seeded)."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        mutant = bytearray(data)
        for at in rng.choice(len(mutant), size=int(rng.integers(1, 5)), replace=False):
            mutant[at] = (mutant[at] + int(rng.integers(1, 256))) % 256
        yield bytes(mutant)


def _read_in_child(data: bytes, filename: str, result) -> None:
    """read_take in a forked child; result[0]: 0 read, 1 RetargetError, 2 anything else;
    result[1]: how far the child's peak RSS grew (KiB)."""
    import resource
    import signal

    signal.alarm(60)  # a hang ends the child with SIGALRM
    start = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # the parent's, inherited
    try:
        read_take(data, filename=filename)
        result[0] = 0
    except RetargetError:
        result[0] = 1
    except BaseException:
        result[0] = 2
    result[1] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - start


def test_c3d_random_mutants_read_or_are_refused_and_never_crash(tmp_path):
    """300 mutants of a valid file, each read in its own forked child. Given to ezc3d
    without the check, 6 of them segfault and 1 hangs."""
    import multiprocessing

    context = multiprocessing.get_context("fork")
    data = _c3d_points_and_analogs(tmp_path)
    results = []
    for i, mutant in enumerate(_mutants(data, 300, seed=0)):
        result = context.Array("q", [-1, 0])
        child = context.Process(target=_read_in_child, args=(mutant, "m.c3d", result))
        child.start()
        child.join()
        results.append((i, child.exitcode, result[0], result[1]))
    crashed = [(i, code) for i, code, _, _ in results if code != 0]
    assert not crashed, f"mutants that killed their child (index, -signal): {crashed}"
    assert not [i for i, _, value, _ in results if value == 2], "mutants raised other than RetargetError"
    counts = np.bincount([value for _, _, value, _ in results], minlength=2)
    assert counts[0] > 100 and counts[1] > 30  # both outcomes occur
    assert max(grown for *_, grown in results) < 256 << 10  # KiB: no mutant made ezc3d allocate


# --- animated meshes ---------------------------------------------------------------------

class _GlbBuilder:
    """A minimal glTF 2.0 writer over pygltflib: one binary buffer, accessors appended."""

    def __init__(self):
        self.blob = bytearray()
        self.doc = pygltflib.GLTF2(scene=0, scenes=[pygltflib.Scene(nodes=[])], nodes=[], meshes=[],
                                   accessors=[], bufferViews=[], buffers=[], animations=[], skins=[])

    def accessor(self, array, kind, component=pygltflib.FLOAT, target=None) -> int:
        array = np.ascontiguousarray(array, dtype={pygltflib.FLOAT: np.float32,
                                                   pygltflib.UNSIGNED_INT: np.uint32,
                                                   pygltflib.UNSIGNED_SHORT: np.uint16}[component])
        self.blob += b"\0" * (-len(self.blob) % 4)
        self.doc.bufferViews.append(pygltflib.BufferView(buffer=0, byteOffset=len(self.blob),
                                                         byteLength=array.nbytes, target=target))
        self.blob += array.tobytes()
        width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[kind]
        flat = array.reshape(len(array), -1) if array.ndim > 1 else array[:, None]
        extra = {}
        if kind == "VEC3" and component == pygltflib.FLOAT:
            extra = {"min": flat.min(0).tolist(), "max": flat.max(0).tolist()}
        self.doc.accessors.append(pygltflib.Accessor(bufferView=len(self.doc.bufferViews) - 1,
                                                     componentType=component,
                                                     count=array.size // width, type=kind, **extra))
        return len(self.doc.accessors) - 1

    def sparse_vec3(self, array) -> int:
        """An accessor without a buffer view: zeros but for the rows that are not."""
        rows = np.flatnonzero(np.any(array != 0, axis=1)).astype(np.uint32)
        indices, values = self.accessor(rows, "SCALAR", pygltflib.UNSIGNED_INT), self.accessor(array[rows], "VEC3")
        self.doc.accessors.append(pygltflib.Accessor(
            componentType=pygltflib.FLOAT, count=len(array), type="VEC3",
            sparse=pygltflib.Sparse(count=len(rows), indices=pygltflib.AccessorSparseIndices(
                bufferView=self.doc.accessors[indices].bufferView, componentType=pygltflib.UNSIGNED_INT),
                values=pygltflib.AccessorSparseValues(bufferView=self.doc.accessors[values].bufferView))))
        return len(self.doc.accessors) - 1

    def mesh(self, vertices, faces, targets=(), joints=None, weights=None, sparse=False) -> int:
        attributes = pygltflib.Attributes(POSITION=self.accessor(vertices, "VEC3"))
        if joints is not None:
            attributes.JOINTS_0 = self.accessor(joints, "VEC4", pygltflib.UNSIGNED_SHORT)
            attributes.WEIGHTS_0 = self.accessor(weights, "VEC4")
        primitive = pygltflib.Primitive(
            attributes=attributes, indices=self.accessor(faces.ravel(), "SCALAR", pygltflib.UNSIGNED_INT),
            targets=[{"POSITION": self.sparse_vec3(t) if sparse else self.accessor(t, "VEC3")}
                     for t in targets] or None)
        self.doc.meshes.append(pygltflib.Mesh(primitives=[primitive]))
        return len(self.doc.meshes) - 1

    def node(self, root=True, **kw) -> int:
        self.doc.nodes.append(pygltflib.Node(**kw))
        if root:
            self.doc.scenes[0].nodes.append(len(self.doc.nodes) - 1)
        return len(self.doc.nodes) - 1

    def animate(self, channels) -> None:
        """channels: [(node, path, times, values, interpolation)]."""
        samplers, targets = [], []
        for node, path, times, values, interpolation in channels:
            kind = {"translation": "VEC3", "rotation": "VEC4", "scale": "VEC3", "weights": "SCALAR"}[path]
            samplers.append(pygltflib.AnimationSampler(
                input=self.accessor(times, "SCALAR"), output=self.accessor(
                    np.asarray(values).reshape(-1) if kind == "SCALAR" else values, kind),
                interpolation=interpolation))
            targets.append(pygltflib.AnimationChannel(
                sampler=len(samplers) - 1, target=pygltflib.AnimationChannelTarget(node=node, path=path)))
        self.doc.animations.append(pygltflib.Animation(samplers=samplers, channels=targets, name="performance"))

    def gltf(self) -> bytes:
        """The document as .gltf JSON with its buffer as a data URI."""
        self.doc.buffers = [pygltflib.Buffer(byteLength=len(self.blob))]
        self.doc.set_binary_blob(bytes(self.blob))
        self.doc.convert_buffers(pygltflib.BufferFormat.DATAURI)
        return self.doc.gltf_to_json().encode()

    def glb(self) -> bytes:
        self.doc.buffers = [pygltflib.Buffer(byteLength=len(self.blob))]
        self.doc.set_binary_blob(bytes(self.blob))
        data = self.doc.save_to_bytes()
        return b"".join(data) if isinstance(data, list) else bytes(data)


KEYS = np.arange(N_FRAMES) / 10.0  # keyframes at 10 fps


def _morph_glb(lift_at=None) -> bytes:
    b = _GlbBuilder()
    mesh = b.mesh(FACE.vertices, FACE.faces, targets=FACE.expressions)
    node = b.node(mesh=mesh)
    channels = [(node, "weights", KEYS, WEIGHTS, "LINEAR")]
    if lift_at is not None:
        channels.append((node, "translation", np.array([0.0, lift_at]),
                         np.array([[0, 0, 0], [0, 1.0, 0]]), "STEP"))
    b.animate(channels)
    return b.glb()


def test_gltf_morph_target_animation_at_its_keyframes():
    labelled = {"vertex_indices": FACE.landmarks68.tolist(), "layout": "ibug68"}
    take = read_take(_morph_glb(), filename="face.glb", labelled_vertices=labelled, layout="dutreve21")
    assert take.fps == pytest.approx(10.0) and take.n_frames == N_FRAMES and take.source == "gltf"
    np.testing.assert_allclose(take.points, TRUTH[:, list(DUTREVE.ibug68)], atol=1e-4)


def test_gltf_sampled_between_keys_with_step_translation_and_surface_points():
    data = _morph_glb(lift_at=0.45)
    # surface points: the landmark vertex's triangle corners, weights 0.5/0.3/0.2
    tri = np.stack([FACE.faces[np.flatnonzero((FACE.faces == v).any(1))[0]] for v in FACE.landmarks68])
    bary = np.tile([0.5, 0.3, 0.2], (68, 1))
    labelled = {"triangles": tri.tolist(), "barycentric": bary.tolist(), "layout": "ibug68"}
    take = read_take(data, filename="face.glb", labelled_vertices=labelled, fps=30)
    times = np.arange(28) / 30
    assert take.n_frames == 28
    weights = np.stack([np.interp(times, KEYS, WEIGHTS[:, e]) for e in range(WEIGHTS.shape[1])], 1)
    posed = posed_vertices(FACE, weights)
    expected = np.einsum("fkjd,kj->fkd", posed[:, tri], bary)
    expected[times >= 0.45, :, 1] += 1.0
    np.testing.assert_allclose(take.points, expected, atol=1e-4)


def test_gltf_json_with_a_data_uri_sparse_targets_and_cubic_spline_weights():
    b = _GlbBuilder()
    node = b.node(mesh=b.mesh(FACE.vertices, FACE.faces, targets=FACE.expressions, sparse=True))
    # CUBICSPLINE keys hold (in-tangent, value, out-tangent); zero tangents give smoothstep
    cubic = np.stack([np.zeros_like(WEIGHTS), WEIGHTS, np.zeros_like(WEIGHTS)], axis=1)
    b.animate([(node, "weights", KEYS, cubic, "CUBICSPLINE")])
    labelled = {"vertex_indices": FACE.landmarks68.tolist(), "layout": "ibug68"}
    take = read_take(b.gltf(), filename="face.gltf", labelled_vertices=labelled, fps=40)
    times = np.arange(37) / 40
    k = np.minimum((times * 10).astype(int), N_FRAMES - 2)
    u = times * 10 - k
    h = (3 * u**2 - 2 * u**3)[:, None]
    weights = (1 - h) * WEIGHTS[k] + h * WEIGHTS[k + 1]
    np.testing.assert_allclose(take.points, posed_vertices(FACE, weights)[:, FACE.landmarks68], atol=1e-4)
    linear = np.stack([np.interp(times, KEYS, WEIGHTS[:, e]) for e in range(WEIGHTS.shape[1])], 1)
    assert np.abs(weights - linear).max() > 0.05  # the test tells cubic from linear


def _skinned_glb():
    """Head (root joint: turn about y, nod translation) and jaw (child joint at a pivot:
    opening about x); vertices below the mouth follow the jaw by a graded weight."""
    b = _GlbBuilder()
    y = FACE.vertices[:, 1]
    w_jaw = np.clip((-2.0 - y) / 3.0, 0.0, 1.0)
    joints = np.zeros((len(y), 4), dtype=np.uint16)
    joints[:, 1] = 1
    weights = np.zeros((len(y), 4))
    weights[:, 0], weights[:, 1] = 1 - w_jaw, w_jaw
    mesh = b.mesh(FACE.vertices, FACE.faces, joints=joints, weights=weights)
    pivot = np.array([0.0, -3.0, -2.0])
    b.node(mesh=mesh, skin=0)
    jaw = b.node(root=False, translation=pivot.tolist())
    head = b.node(children=[jaw])
    inverse = np.stack([np.eye(4), np.eye(4)])
    inverse[1, :3, 3] = -pivot
    b.doc.skins.append(pygltflib.Skin(joints=[head, jaw], inverseBindMatrices=b.accessor(
        inverse.transpose(0, 2, 1).reshape(2, 16), "MAT4")))
    turn = np.radians(25) * np.sin(KEYS * 3)
    nod = 0.5 * np.sin(KEYS * 5)
    opening = np.radians(20) * (1 - np.cos(KEYS * 4)) / 2
    b.animate([
        (head, "rotation", KEYS, Rotation.from_euler("y", turn[:, None]).as_quat(), "LINEAR"),
        (head, "translation", KEYS, np.c_[0 * nod, nod, 0 * nod], "LINEAR"),
        (jaw, "rotation", KEYS, Rotation.from_euler("x", opening[:, None]).as_quat(), "LINEAR"),
    ])

    def truth(t):
        a, n, o = (np.interp(t, KEYS, v) for v in (turn, nod, opening))
        head_m = np.zeros((len(t), 4, 4))
        head_m[:, :3, :3] = Rotation.from_euler("y", a[:, None]).as_matrix()
        head_m[:, :3, 3] = np.c_[0 * n, n, 0 * n]
        head_m[:, 3, 3] = 1
        jaw_local = np.zeros_like(head_m)
        jaw_local[:, :3, :3] = Rotation.from_euler("x", o[:, None]).as_matrix()
        jaw_local[:, :3, 3] = pivot
        jaw_local[:, 3, 3] = 1
        jaw_m = head_m @ jaw_local @ inverse[1]
        v = np.c_[FACE.vertices, np.ones(len(y))]
        return ((1 - w_jaw)[None, :, None] * np.einsum("fij,vj->fvi", head_m, v)
                + w_jaw[None, :, None] * np.einsum("fij,vj->fvi", jaw_m, v))[..., :3]

    return b.glb(), truth


def test_gltf_skinned_animation_follows_linear_blend_skinning():
    data, truth = _skinned_glb()
    labelled = {name: int(v) for name, v in zip(IBUG.point_names, FACE.landmarks68)}
    take = read_take(data, filename="skinned.glb", labelled_vertices=labelled, fps=20)
    times = np.arange(19) / 20
    assert take.layout == "ibug68" and take.n_frames == 19
    np.testing.assert_allclose(take.points, truth(times)[:, FACE.landmarks68], atol=2e-4)
    # the chin opens with the jaw and the head turn moves everything
    assert np.ptp(take.points[:, IBUG.index("chin"), 1]) > 0.5


def test_gltf_meshes_count_in_load_mesh_order():
    b = _GlbBuilder()
    face = b.node(mesh=b.mesh(FACE.vertices, FACE.faces, targets=FACE.expressions))
    quad = b.mesh(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float), np.array([[0, 1, 2], [0, 2, 3]]))
    b.node(mesh=quad, translation=[20.0, 0.0, 0.0])
    b.animate([(face, "weights", KEYS, WEIGHTS, "LINEAR")])
    data = b.glb()
    mesh = load_mesh(data, "glb")
    # where the app (load_mesh) puts the face's landmark vertices and the quad's corner
    offset = int(np.flatnonzero(np.all(mesh.vertices == FACE.vertices[0].astype(np.float32), axis=1))[0])
    corner = int(np.flatnonzero(np.all(mesh.vertices == [21.0, 1.0, 0.0], axis=1))[0])
    labelled = {"nose_tip": offset + int(FACE.landmarks68[30]), "corner": corner}
    take = read_take(data, filename="two.glb", labelled_vertices=labelled)
    np.testing.assert_allclose(take.points[:, 0], TRUTH[:, 30], atol=1e-4)
    np.testing.assert_allclose(take.points[:, 1], np.tile([21.0, 1.0, 0.0], (N_FRAMES, 1)))


def test_gltf_errors():
    labelled = {"vertex_indices": FACE.landmarks68.tolist(), "layout": "ibug68"}
    with pytest.raises(RetargetError, match="needs labelled_vertices"):
        read_take(_morph_glb(), filename="f.glb")
    with pytest.raises(RetargetError, match="no \"layout\" to name its points"):
        read_take(_morph_glb(), filename="f.glb", labelled_vertices={"vertex_indices": [1, 2, 3]})
    with pytest.raises(RetargetError, match="is not a vertex of the mesh"):
        read_take(_morph_glb(), filename="f.glb", labelled_vertices={"a": 10 ** 7})
    b = _GlbBuilder()
    b.node(mesh=b.mesh(FACE.vertices, FACE.faces))
    with pytest.raises(RetargetError, match="holds no animation"):
        read_take(b.glb(), filename="still.glb", labelled_vertices=labelled)
    with pytest.raises(RetargetError, match=r"lasts 0.9 s, \d+ frames at 1e\+06 fps; at most 200000"):
        read_take(_morph_glb(), filename="f.glb", labelled_vertices=labelled, fps=1e6)
    with pytest.raises(RetargetError, match="could not read 'x.glb' as glTF"):
        read_take(b"glTF" + b"\0" * 20, filename="x.glb", labelled_vertices=labelled)
    doc = json.dumps({"asset": {"version": "2.0"}, "buffers": [{"uri": "face.bin", "byteLength": 4}]})
    with pytest.raises(RetargetError, match="external file 'face.bin'"):
        read_take(doc.encode(), filename="x.gltf", labelled_vertices=labelled)
    # an accessor that claims more data than its buffer holds
    b = _GlbBuilder()
    node = b.node(mesh=b.mesh(FACE.vertices, FACE.faces, targets=FACE.expressions))
    b.animate([(node, "weights", KEYS, WEIGHTS, "LINEAR")])
    b.doc.accessors[0].count += 10 ** 6
    with pytest.raises(RetargetError, match="accessor 0 reads past the end of its buffer"):
        read_take(b.glb(), filename="x.glb", labelled_vertices=labelled)


def test_gltf_mesh_instanced_by_many_nodes_is_refused_from_the_json_counts():
    import tracemalloc

    b = _GlbBuilder()
    mesh = b.mesh(FACE.vertices, FACE.faces, targets=FACE.expressions)
    nodes = [b.node(mesh=mesh) for _ in range(40)]  # 126,006 vertices counted per node
    b.animate([(nodes[0], "weights", KEYS, WEIGHTS, "LINEAR")])
    data = b.glb()
    labelled = {"vertex_indices": FACE.landmarks68.tolist(), "layout": "ibug68"}
    tracemalloc.start()
    with pytest.raises(RetargetError, match=r"'many.glb': its 40 mesh node\(s\) instance 5040240 vertices "
                                            r"\(each morph target and joint set counting again\); at most 4000000"):
        read_take(data, filename="many.glb", labelled_vertices=labelled)
    assert tracemalloc.get_traced_memory()[1] < 8 * len(data)  # no instance was read
    tracemalloc.stop()


def test_gltf_keyframes_and_sampling_are_budgeted_before_they_are_made():
    labelled = {"vertex_indices": FACE.landmarks68.tolist(), "layout": "ibug68"}
    b = _GlbBuilder()
    node = b.node(mesh=b.mesh(FACE.vertices, FACE.faces, targets=FACE.expressions))
    b.animate([(node, "weights", KEYS, WEIGHTS, "LINEAR")])
    # key times that are 20 million zeros out of nothing (no bufferView)
    b.doc.accessors.append(pygltflib.Accessor(componentType=pygltflib.FLOAT, count=20_000_000, type="SCALAR"))
    b.doc.animations[0].samplers[0].input = len(b.doc.accessors) - 1
    with pytest.raises(RetargetError, match=r"'keys.glb': the animation's channels hold 20000120 key times "
                                            r"and values; at most 16000000 are read"):
        read_take(b.glb(), filename="keys.glb", labelled_vertices=labelled)
    # 198,900 frames (float32 key times) of 1 node and 68 labelled vertices
    with pytest.raises(RetargetError, match=r"'fast.glb': sampling 198900 frames of 1 node\(s\) and 68 labelled "
                                            r"vertices makes 303919200 values; at most 25000000"):
        read_take(_morph_glb(), filename="fast.glb", labelled_vertices=labelled, fps=221_000)


def _obj(vertices, faces) -> bytes:
    out = io.BytesIO()
    trimesh.Trimesh(vertices, faces, process=False).export(out, file_type="obj")
    return out.getvalue()


def _obj_zip(frames, faces, names=None, extra=()) -> bytes:
    out = io.BytesIO()
    order = np.random.default_rng(0).permutation(len(frames))  # stored out of order
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as archive:
        for i in order:
            name = names[i] if names else f"seq/face_{i + 1:04d}.obj"
            archive.writestr(name, _obj(frames[i], faces))
        for name, data in extra:
            archive.writestr(name, data)
    return out.getvalue()


def test_obj_sequence_zip_in_frame_number_order():
    frames = posed_vertices(FACE, WEIGHTS[:6])
    data = _obj_zip(frames, FACE.faces, extra=[("seq/face.mtl", b"newmtl x\n"), ("__MACOSX/._a.obj", b"junk")])
    labelled = {name: int(v) for name, v in zip(IBUG.point_names, FACE.landmarks68)}
    take = read_take(data, filename="seq.zip", labelled_vertices=labelled, layout="dutreve21", fps=24)
    np.testing.assert_allclose(take.points, TRUTH[:6, list(DUTREVE.ibug68)], atol=1e-5)
    assert take.fps == 24 and take.source == "obj" and take.meta["n_vertices"] == len(FACE.vertices)


def test_obj_sequence_errors_name_the_member():
    frames = posed_vertices(FACE, WEIGHTS[:3])
    labelled = {"a": 0}
    bad = _obj_zip([frames[0], frames[1]], FACE.faces)
    one_more = np.vstack([frames[2], [[0.0, 0.0, 0.0]]])  # an extra, unused vertex
    bad = _obj_zip_with(bad, "seq/face_0003.obj", _obj(one_more, FACE.faces))
    with pytest.raises(RetargetError, match=rf"'seq/face_0003.obj' has {len(FACE.vertices) + 1} vertices, 'seq/face_0001.obj' has {len(FACE.vertices)}"):
        read_take(bad, filename="s.zip", labelled_vertices=labelled)
    flipped = _obj_zip_with(_obj_zip(frames[:2], FACE.faces), "seq/face_0003.obj",
                            _obj(frames[2], FACE.faces[:, ::-1]))
    with pytest.raises(RetargetError, match="'seq/face_0003.obj' has other faces than 'seq/face_0001.obj'"):
        read_take(flipped, filename="s.zip", labelled_vertices=labelled)
    with pytest.raises(RetargetError, match="'x.obj' has no frame number"):
        read_take(_obj_zip(frames[:1], FACE.faces, names=["x.obj"]), filename="s.zip", labelled_vertices=labelled)
    with pytest.raises(RetargetError, match="'a/1.obj' and 'b/1.obj' have the same frame number 1"):
        read_take(_obj_zip(frames[:2], FACE.faces, names=["a/1.obj", "b/1.obj"]), filename="s.zip",
                  labelled_vertices=labelled)
    with pytest.raises(RetargetError, match="holds no .obj files"):
        read_take(_obj_zip([], FACE.faces, extra=[("a.txt", b"x")]), filename="s.zip", labelled_vertices=labelled)
    with pytest.raises(RetargetError, match="is not a zip archive"):
        read_take(b"PK junk", filename="s.zip", labelled_vertices=labelled)


def _obj_zip_with(data: bytes, name: str, member: bytes) -> bytes:
    out = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(data)) as src, zipfile.ZipFile(out, "w") as dst:
        for info in src.infolist():
            dst.writestr(info, src.read(info))
        dst.writestr(name, member)
    return out.getvalue()


def _central(data: bytes, name: str, offset: int, raw: bytes) -> bytes:
    """`data` with `raw` written at `offset` into the central directory entry of `name`
    (8 flag bits, 10 method, 16 CRC, 20 packed size, 24 unpacked size)."""
    entry = next(i for i in range(len(data)) if data.startswith(b"PK\x01\x02", i)
                 and data[i + 46:i + 46 + len(name)] == name.encode())
    return data[:entry + offset] + raw + data[entry + offset + len(raw):]


def _stored_zip(frames, faces) -> bytes:
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as archive:
        for i, frame in enumerate(frames):
            archive.writestr(f"f_{i + 1}.obj", _obj(frame, faces))
    return out.getvalue()


def test_obj_sequence_members_that_cannot_be_read_are_refused_by_name():
    frames = posed_vertices(FACE, WEIGHTS[:3])
    labelled = {"a": 0}
    data = _stored_zip(frames, FACE.faces)
    encrypted = _central(data, "f_2.obj", 8, b"\x01")
    with pytest.raises(RetargetError, match="'s.zip': 'f_2.obj' is encrypted; zip the frames without a password"):
        read_take(encrypted, filename="s.zip", labelled_vertices=labelled)
    for method, name in ((99, "AES encryption"), (9, "Deflate64"), (77, "an unknown method")):
        odd = _central(data, "f_3.obj", 10, method.to_bytes(2, "little"))
        with pytest.raises(RetargetError, match=rf"'f_3.obj' is compressed with {name} \(zip method {method}\), "
                                                "which is not read; zip the frames with Deflate"):
            read_take(odd, filename="s.zip", labelled_vertices=labelled)
    at = data.index(b"v ", data.index(b"f_2.obj") + 10) + 2  # a coordinate of frame 2, stored
    digit = b"1" if data[at:at + 1] != b"1" else b"2"
    damaged = data[:at] + digit + data[at + 1:]
    with pytest.raises(RetargetError, match=r"'f_2.obj' could not be unpacked: its data does not match its checksum"):
        read_take(damaged, filename="s.zip", labelled_vertices=labelled)
    # a central directory that understates a member's size: the read stops there
    short = _central(data, "f_2.obj", 24, (100).to_bytes(4, "little"))
    with pytest.raises(RetargetError, match=r"'f_2.obj' could not be unpacked: its data does not match"):
        read_take(short, filename="s.zip", labelled_vertices=labelled)


def test_obj_sequence_zip_bomb_is_refused_from_its_declared_sizes_before_unpacking(monkeypatch):
    import tracemalloc

    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("face_0001.obj", _obj(FACE.vertices, FACE.faces))
        archive.writestr("face_0002.obj", b"v 0 0 0\n" * (1 << 20))
    bomb = out.getvalue()
    assert len(bomb) < 300_000
    tracemalloc.start()
    with pytest.raises(RetargetError, match=r"'face_0002.obj' claims to unpack \d+ bytes to 8388608 "
                                            r"\(\d+:1\); OBJ text packs at most 100:1"):
        read_take(bomb, filename="b.zip", labelled_vertices={"a": 0})
    assert tracemalloc.get_traced_memory()[1] < 4 << 20  # nothing was unpacked
    tracemalloc.stop()
    data = _obj_zip(posed_vertices(FACE, WEIGHTS[:3]), FACE.faces)
    monkeypatch.setattr(files, "MAX_ARCHIVE_BYTES", 1 << 20)
    with pytest.raises(RetargetError, match=r"'s.zip': its 3 .obj files unpack to \d+ bytes; at most 1048576 are read"):
        read_take(data, filename="s.zip", labelled_vertices={"a": 0})
    monkeypatch.setattr(obj_sequence, "MAX_SEQUENCE_VERTICES", 20_000)
    monkeypatch.setattr(files, "MAX_ARCHIVE_BYTES", 256 << 20)
    with pytest.raises(RetargetError, match=r"3 frames of 8430 vertices are 25290 vertices to parse; at most 20000"):
        read_take(data, filename="s.zip", labelled_vertices={"a": 0})
    monkeypatch.setattr(obj_sequence, "MAX_FRAME_BYTES", 1000)
    with pytest.raises(RetargetError, match=r"'seq/face_0001.obj' unpacks to \d+ bytes; a frame may have at most 1000"):
        read_take(data, filename="s.zip", labelled_vertices={"a": 0})


# --- malformed files of every format ----------------------------------------------------

_TETRA = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
_TETRA_FACES = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def _small_take() -> Take:
    points = np.random.default_rng(2).normal(size=(5, 4, 3))
    points[2, 1] = np.nan
    return Take(points, ("a", "b", "c", "d"), 25.0)


def _small_csv() -> bytes:
    out = io.StringIO()
    write_take_csv(_small_take(), out)
    return out.getvalue().encode()


def _small_json() -> bytes:
    take = _small_take()
    frames = [[None if np.isnan(p).any() else p.tolist() for p in frame] for frame in take.points]
    return json.dumps({"fps": 25, "names": list(take.names), "frames": frames,
                       "times": take.frame_times().tolist(), "units": "mm"}).encode()


def _small_npy() -> bytes:
    out = io.BytesIO()
    np.save(out, TRUTH[:3].astype(np.float32))
    return out.getvalue()


def _small_gltf_builder() -> _GlbBuilder:
    b = _GlbBuilder()
    node = b.node(mesh=b.mesh(_TETRA, _TETRA_FACES, targets=[_TETRA * 0.1]))
    keys = np.arange(4) / 10.0
    b.animate([(node, "weights", keys, np.array([[0.0], [0.5], [1.0], [0.2]]), "LINEAR"),
               (node, "translation", keys, np.c_[keys, keys, keys], "STEP")])
    return b


def _small_obj_zip() -> bytes:
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as archive:
        for i in range(3):
            archive.writestr(f"seq/f_{i + 1}.obj", _obj(_TETRA * (1 + 0.1 * i), _TETRA_FACES))
    return out.getvalue()


_MUTATED = [  # (file name, its valid bytes, read_take options, mutants)
    ("m.csv", _small_csv, {}, 80),
    ("m.json", _small_json, {}, 60),
    ("m.npy", _small_npy, {"layout": "ibug68"}, 200),
    ("m.trc", lambda: _trc(["A", "B", "C"], np.ones((3, 3, 3)) * 1.5).encode(), {}, 60),
    ("m.glb", lambda: _small_gltf_builder().glb(), {"labelled_vertices": {"a": 0, "b": 2}}, 120),
    ("m.gltf", lambda: _small_gltf_builder().gltf(), {"labelled_vertices": {"a": 0, "b": 2}}, 40),
    ("m.zip", _small_obj_zip, {"labelled_vertices": {"a": 0, "b": 2}}, 60),
]


@pytest.mark.parametrize("error, words", [
    (IndexError("list index out of range"),
     r"it refers to a part it does not hold \(IndexError: list index out of range\)"),
    (MemoryError(), "it would take more memory than there is"),
    (RecursionError("maximum recursion depth exceeded"), "it is nested too deeply"),
    (UnicodeDecodeError("utf-8", b"\xff", 0, 1, "invalid start byte"), "it holds text that cannot be decoded"),
], ids=["IndexError", "MemoryError", "RecursionError", "UnicodeDecodeError"])
def test_unexpected_errors_of_a_reader_become_retarget_errors_naming_the_file(monkeypatch, error, words):
    def broken(*args):
        raise error

    monkeypatch.setattr(files, "_read_trc", broken)
    with pytest.raises(RetargetError, match=rf"^'x.trc' could not be read as a TRC file: {words}"):
        read_take(b"PathFileType\t4", filename="x.trc")


@pytest.mark.parametrize("filename, make, options, count", _MUTATED, ids=[m[0] for m in _MUTATED])
def test_mutants_of_every_format_read_or_raise_only_retarget_errors(filename, make, options, count):
    data = make()
    assert read_take(data, filename=filename, **options).n_frames >= 3
    outcomes = {"read": 0, "refused": 0}
    for i, mutant in enumerate(_mutants(data, count, seed=1)):
        try:
            read_take(mutant, filename=filename, **options)
            outcomes["read"] += 1
        except RetargetError as exc:
            assert str(exc).startswith(f"'{filename}'") or f"'{filename}'" in str(exc), str(exc)
            outcomes["refused"] += 1
        except Exception as exc:  # noqa: BLE001 - the point of the test
            pytest.fail(f"mutant {i} of {filename} raised {type(exc).__name__}: {exc}")
    assert outcomes["refused"] > 0

