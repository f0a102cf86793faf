"""Tests for retarget.sources.take: validation, neutral, trimming, layout selection and the
.npz round trip of `Take`."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.layouts import get_layout
from retarget.sources import take as take_module
from retarget.sources.take import Take

IBUG = get_layout("ibug68")


def _take(frames=20, fps=30.0, dims=3, seed=0, **kw) -> Take:
    rng = np.random.default_rng(seed)
    return Take(rng.normal(size=(frames, 68, dims)), IBUG.point_names, fps, layout="ibug68", **kw)


def test_fields_are_coerced_and_described():
    take = _take(frames=7, fps=25)
    assert take.points.dtype == np.float32
    assert (take.n_frames, take.n_points, take.dims) == (7, 68, 3)
    np.testing.assert_allclose(take.frame_times(), np.arange(7) / 25)
    times = np.array([0.0, 0.1, 0.1, 0.35])
    timed = Take(np.zeros((4, 2, 2)), ("a", "b"), 10, times=times)
    np.testing.assert_array_equal(timed.frame_times(), times)


def test_a_partly_nan_row_becomes_a_lost_point():
    points = np.ones((3, 2, 3))
    points[1, 0, 2] = np.nan
    take = Take(points, ("a", "b"), 30)
    assert np.isnan(take.points[1, 0]).all()
    assert np.isfinite(take.points[1, 1]).all()


@pytest.mark.parametrize("kwargs, message", [
    ({"points": np.zeros((3, 2))}, r"shape \(F, N, 2\|3\)"),
    ({"points": np.zeros((3, 2, 4))}, r"shape \(F, N, 2\|3\)"),
    ({"points": np.zeros((0, 2, 3))}, r"F, N >= 1"),
    ({"names": ("a",)}, "2 points but 1 names"),
    ({"names": ("a", "a")}, "repeat 'a'"),
    ({"fps": 0}, "fps must be a positive number"),
    ({"fps": "fast"}, "fps must be a positive number"),
    ({"times": [0.0, 0.2, 0.1]}, "backwards at frame 2"),
    ({"times": [0.0, 0.1]}, r"shape \(3,\)"),
    ({"layout": "ibug68"}, "not the points of layout 'ibug68'"),
    ({"layout": "nope"}, "unknown layout 'nope'"),
    ({"meta": {"camera": object()}}, "JSON-able"),
])
def test_bad_fields_are_refused_by_name(kwargs, message):
    fields = {"points": np.zeros((3, 2, 3)), "names": ("a", "b"), "fps": 30.0, **kwargs}
    with pytest.raises(RetargetError, match=message):
        Take(**fields)


def test_infinite_coordinates_are_refused_with_frame_and_point():
    points = np.zeros((3, 2, 3))
    points[2, 1, 0] = np.inf
    with pytest.raises(RetargetError, match="frame 2, point 1 is infinite"):
        Take(points, ("a", "b"), 30)


def test_neutral_is_the_median_of_the_first_seconds_ignoring_lost_frames():
    take = _take(frames=30, fps=10)
    take.points[2, 5] = np.nan
    # 0.5 s at 10 fps: frames 0..5 (t <= 0.5)
    expected = np.nanmedian(take.points[:6], axis=0)
    np.testing.assert_allclose(take.neutral(seconds=0.5), expected)
    np.testing.assert_array_equal(take.neutral(frame=4), take.points[4])
    np.testing.assert_array_equal(take.neutral(seconds=0), take.points[0])


def test_neutral_names_points_lost_throughout_the_span():
    take = _take(frames=30, fps=10)
    take.points[:6, IBUG.index("nose_tip")] = np.nan
    with pytest.raises(RetargetError, match="lost throughout the first 0.5 s.*nose_tip"):
        take.neutral(seconds=0.5)
    take.neutral(seconds=0.7)  # frame 6 sees it
    with pytest.raises(RetargetError, match="neutral frame 3.*nose_tip"):
        take.neutral(frame=3)
    with pytest.raises(RetargetError, match=r"in \[0, 30\)"):
        take.neutral(frame=30)


def test_trimmed_keeps_the_half_open_span_and_rebases_times():
    take = _take(frames=30, fps=10)
    part = take.trimmed(0.5, 1.2)
    np.testing.assert_array_equal(part.points, take.points[5:12])
    np.testing.assert_allclose(part.frame_times(), np.arange(7) / 10)
    timed = Take(take.points, take.names, 10, times=np.arange(30) ** 1.5 / 100, layout="ibug68")
    part = timed.trimmed(0.5)
    first = int(np.argmax(timed.times >= 0.5))
    np.testing.assert_allclose(part.times, timed.times[first:] - timed.times[first])
    with pytest.raises(RetargetError, match="leaves no frame"):
        take.trimmed(5.0)


def test_to_layout_selects_by_name_and_through_a_mapping():
    take = _take()
    sub = take.to_layout("dutreve21")
    dutreve = get_layout("dutreve21")
    assert sub.layout == "dutreve21" and sub.names == dutreve.point_names
    np.testing.assert_array_equal(sub.points, take.points[:, list(dutreve.ibug68)])

    rng = np.random.default_rng(1)
    labels = ("LBROW", "nose_tip", "junk")
    markers = Take(rng.normal(size=(4, 3, 3)), labels, 30)
    lay = get_layout("ibug68").select(["brow_left_middle", "nose_tip"], name="x")
    with pytest.raises(RetargetError, match="unknown layout 'x'"):
        markers.to_layout(lay.name)
    with pytest.raises(RetargetError, match="lacks 20 of the 21 points.*brow_right_outer"):
        markers.to_layout("dutreve21")
    with pytest.raises(RetargetError, match="label 'RBROW'"):
        markers.to_layout("dutreve21", {"RBROW": "brow_right_outer"})
    with pytest.raises(RetargetError, match="no point named 'brow_left_mid'"):
        markers.to_layout("dutreve21", {"LBROW": "brow_left_mid"})


def test_to_layout_error_suggests_close_labels():
    names = tuple(n.upper() if n == "nose_tip" else n for n in get_layout("dutreve21").point_names)
    take = Take(np.zeros((2, 21, 3)), names, 30)
    with pytest.raises(RetargetError, match="lacks 1 of the 21.*nose_tip.*close labels: nose_tip ~ NOSE_TIP"):
        take.to_layout("dutreve21")
    mapped = take.to_layout("dutreve21", {"NOSE_TIP": "nose_tip"})
    assert mapped.names == get_layout("dutreve21").point_names


def test_save_load_round_trip_keeps_everything(tmp_path):
    take = _take(frames=5, dims=2, times=[0, 0.03, 0.07, 0.1, 0.2], source="markers",
                 meta={"video": {"size": [640, 480]}, "units": "px"})
    take.points[1, 3] = np.nan
    path = tmp_path / "take.npz"
    take.save(path)
    back = Take.load(path)
    np.testing.assert_array_equal(back.points, take.points)
    np.testing.assert_array_equal(back.times, take.times)
    assert (back.names, back.fps, back.layout, back.source, back.meta) == \
        (take.names, take.fps, take.layout, take.source, take.meta)
    buffer = io.BytesIO()
    take.save(buffer)
    assert Take.load(buffer.getvalue()).n_frames == 5


def test_load_refuses_other_files(tmp_path):
    path = tmp_path / "other.npz"
    np.savez(path, points=np.zeros((2, 2, 3)))
    with pytest.raises(RetargetError, match="not a take file: it lacks times, names, info"):
        Take.load(path)
    with pytest.raises(RetargetError, match="could not read the take data"):
        Take.load(b"not a zip")
    take = _take(frames=2)
    buffer = io.BytesIO()
    np.savez(buffer, points=take.points, times=take.frame_times(),
             names=np.array(take.names), info=np.array('{"format": "other"}'))
    with pytest.raises(RetargetError, match="not a take file"):
        Take.load(buffer.getvalue())
    buffer = io.BytesIO()
    np.savez(buffer, points=take.points[:, :3], times=take.frame_times(),
             names=np.array(take.names), info=np.array('{"format": "retarget-take-1", "fps": 30}'))
    with pytest.raises(RetargetError, match="3 points but 68 names"):
        Take.load(buffer.getvalue())


def _npz(take: Take, **replace) -> bytes:
    """A take file whose members are `take`'s, those named in `replace` swapped for bytes."""
    buffer = io.BytesIO()
    take.save(buffer)
    out = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(buffer.getvalue())) as src, zipfile.ZipFile(out, "w") as dst:
        for info in src.infolist():
            key = info.filename[:-4]
            dst.writestr(info.filename, replace.get(key, src.read(info)))
    return out.getvalue()


def test_load_checks_member_headers_before_unpacking():
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<f4", "fortran_order": False, "shape": (10 ** 8, 678, 3)})
    data = _npz(_take(frames=2), points=header.getvalue() + b"\0" * 16)
    with pytest.raises(RetargetError, match=r"^the take data: member 'points.npy': its header declares a "
                                            r"100000000x678x3 float32 array, 813600000000 bytes, but 16"):
        Take.load(data)
    with pytest.raises(RetargetError, match=r"^'t.npz': member 'points.npy': its header declares"):
        Take.load(data, label="'t.npz'")
    objects = io.BytesIO()
    np.save(objects, np.array(["a", 1], dtype=object), allow_pickle=True)
    with pytest.raises(RetargetError, match=r"member 'names.npy' holds Python objects"):
        Take.load(_npz(_take(frames=2), names=objects.getvalue()))


def test_load_refuses_encrypted_damaged_and_oversized_members(monkeypatch):
    data = _npz(_take(frames=2))
    # the central directory entry of points.npy: its flag bits at offset 8
    entry = next(i for i in range(len(data)) if data.startswith(b"PK\x01\x02", i)
                 and data[i + 46:i + 56] == b"points.npy")
    encrypted = data[:entry + 8] + bytes([data[entry + 8] | 1]) + data[entry + 9:]
    with pytest.raises(RetargetError, match="member 'points.npy' is encrypted"):
        Take.load(encrypted)
    at = data.index(b"points.npy") + 10 + 200  # a byte of the stored points data
    damaged = data[:at] + bytes([data[at] ^ 0xFF]) + data[at + 1:]
    with pytest.raises(RetargetError, match=r"member 'points.npy' is damaged: Bad CRC-32"):
        Take.load(damaged)
    monkeypatch.setattr(take_module, "_MAX_NPZ_BYTES", 1000)
    with pytest.raises(RetargetError, match=r"its arrays unpack to \d+ bytes \(points.npy \d+, .*\); at most 1000"):
        Take.load(data)
