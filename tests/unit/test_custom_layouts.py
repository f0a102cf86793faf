"""Custom layouts (retarget.custom_layouts): a user's markers as a Layout from a JSON spec,
its checks, its registration under ``custom-<hash>``, and the files that carry it."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest

from retarget.custom_layouts import MAX_POINTS, layout_from_spec, load_layout_file, spec_of_names
from retarget.errors import RetargetError
from retarget.landmarks import SurfacePoints, landmarks_from_json
from retarget.layouts import LAYOUTS, from_ibug68, from_mediapipe468, get_layout
from retarget.sources.conditioning import condition_take
from retarget.sources.take import Take


def _point(name, region, side="center", **extra):
    return {"name": name, "region": region, "side": side, **extra}


def markers_spec(**extra_by_name) -> dict:
    """Eight markers: two brows, two mouth corners, a lip pair, and two head anchors."""
    points = [
        _point("m01", "brows", "right", mirror="m02"),
        _point("m02", "brows", "left", mirror="m01"),
        _point("m03", "mouth_corners", "right", mirror="m04"),
        _point("m04", "mouth_corners", "left", mirror="m03"),
        _point("m05", "upper_lip"),
        _point("m06", "lower_lip"),
        _point("h1", "forehead", "right", mirror="h2", anchor=True),
        _point("h2", "forehead", "left", mirror="h1", anchor=True),
        _point("h3", "nose", anchor=True),
    ]
    for p in points:
        p.update(extra_by_name.get(p["name"], {}))
    return {"description": "nine markers", "points": points}


def test_a_spec_makes_a_registered_layout_with_its_regions_pairs_and_anchors():
    layout = layout_from_spec(markers_spec())
    assert layout.is_custom and layout.name.startswith("custom-")
    assert layout.point_names[:3] == ("m01", "m02", "m03")
    assert layout.mirror == (1, 0, 3, 2, 4, 5, 7, 6, 8)
    assert layout.anchors == (6, 7, 8)
    assert layout.region_mask("mouth").tolist() == [False, False, True, True, True, True, False, False, False]
    assert layout.ibug68 == (-1,) * 9 and not layout.has_ibug68 and not layout.has_mediapipe468
    assert get_layout(layout.name) == layout
    mirrored = layout.mirrored(np.arange(27.0).reshape(9, 3))
    assert mirrored[0].tolist() == [-3.0, 4.0, 5.0]


def test_the_name_is_the_spec_s_hash_and_the_spec_round_trips():
    layout = layout_from_spec(markers_spec())
    again = layout_from_spec(json.loads(json.dumps(layout.spec())))
    assert again == layout
    other = layout_from_spec(markers_spec(m05={"region": "nose"}))
    assert other.name != layout.name


def test_a_custom_layout_pickles_as_its_spec_and_registers_where_it_lands():
    from retarget import layouts

    layout = layout_from_spec(markers_spec(m06={"name": "m06b"}))
    data = pickle.dumps(layout)
    del layouts._REGISTERED[layout.name]
    with pytest.raises(RetargetError, match="is not loaded"):
        get_layout(layout.name)
    assert pickle.loads(data) == layout
    assert get_layout(layout.name) == layout


def test_a_built_in_layout_s_spec_makes_a_custom_twin():
    twin = layout_from_spec(LAYOUTS["dutreve22"].spec())
    assert twin.is_custom and twin.point_names == LAYOUTS["dutreve22"].point_names
    assert twin.ibug68 == LAYOUTS["dutreve22"].ibug68
    np.testing.assert_allclose(twin.reference_points(), LAYOUTS["dutreve22"].reference_points())
    assert from_ibug68(np.zeros((68, 3)), twin).shape == (22, 3)


@pytest.mark.parametrize("change, message", [
    (lambda s: s["points"].append(dict(s["points"][0])), "'m01' is repeated"),
    (lambda s: s["points"][0].update(region="ears"), "region 'ears' is not one of"),
    (lambda s: s["points"][0].update(side="up"), "side 'up' is not one of"),
    (lambda s: s["points"][1].update(mirror="m03"), "asymmetric mirror: point 'm01' names 'm02' its partner, but 'm02' names 'm03'"),
    (lambda s: s["points"][0].update(mirror="zz"), "mirror partner 'zz' is no point"),
    (lambda s: (s["points"][4].update(mirror="m06"), s["points"][5].update(mirror="m05")),
     "partners 'm05' \\(center\\) and 'm06' \\(center\\) must be one right and one left"),
    (lambda s: s.update(points=s["points"][:2]), "needs 3 to 1000 points, got 2"),
    (lambda s: s["points"][0].update(name="m 01"), "name 'm 01' is not a safe identifier"),
    (lambda s: s["points"][0].update(name="../x"), "is not a safe identifier"),
    (lambda s: s["points"][0].update(name="a" * 65), "is not a safe identifier"),
    (lambda s: s["points"][0].update(colour="red"), "unknown keys \\['colour'\\]"),
    (lambda s: s["points"][6].update(anchor=False), "head anchors: mark at least 3"),
    (lambda s: s["points"][0].update(anchor="yes"), "anchor must be true or false"),
    (lambda s: s["points"][0].update(ibug68=68), "ibug68 must be an integer in \\[0, 68\\)"),
    (lambda s: s["points"][0].update(reference=[0, 1, 2]), "give every point one or none"),
    (lambda s: s["points"][0].update(reference=[0, 1, float("nan")]), "reference must be"),
    (lambda s: s.update(points=[_point(f"p{i}", "nose") for i in range(MAX_POINTS + 1)]), "got 1001"),
    (lambda s: s.update(format="other/2"), "format 'other/2'"),
    (lambda s: s.update(extra=1), "unknown keys \\['extra'\\]"),
])
def test_a_bad_spec_is_refused_naming_the_point_and_the_fault(change, message):
    spec = markers_spec()
    change(spec)
    with pytest.raises(RetargetError, match=message):
        layout_from_spec(spec)


def test_built_in_only_data_is_refused_clearly_for_markers_that_are_no_face_point():
    layout = layout_from_spec(markers_spec())
    with pytest.raises(RetargetError, match="has no reference positions: 9 of its points"):
        layout.reference_points()
    with pytest.raises(RetargetError, match="none of the 68 iBUG points"):
        from_ibug68(np.zeros((68, 3)), layout)
    with pytest.raises(RetargetError, match="no face-mesh vertex"):
        from_mediapipe468(np.zeros((468, 3)), layout)


def test_reference_positions_given_in_the_spec_are_the_layout_s():
    refs = {f"m0{i}": {"reference": [i, 0, 0]} for i in range(1, 7)}
    refs.update({h: {"reference": [0, k, 0]} for k, h in enumerate(("h1", "h2", "h3"), 1)})
    layout = layout_from_spec(markers_spec(**refs))
    assert layout.reference_points()[:, 0].tolist() == [1, 2, 3, 4, 5, 6, 0, 0, 0]
    assert layout.select("brows").reference_points().shape == (2, 3)


def test_a_layout_file_is_read_and_its_faults_name_the_file(tmp_path):
    path = tmp_path / "L.json"
    path.write_text(json.dumps(markers_spec()))
    assert load_layout_file(path).n_points == 9
    path.write_text("{")
    with pytest.raises(RetargetError, match="could not read layout file"):
        load_layout_file(path)
    path.write_text(json.dumps({"points": []}))
    with pytest.raises(RetargetError, match="L.json.*needs 3 to"):
        load_layout_file(path)


def test_spec_of_names_builds_the_cli_s_spec():
    spec = spec_of_names(["a", "b", "c"], ["brows", "brows", "nose"], ["right", "left", "center"],
                         ["b", "a", None])
    assert layout_from_spec(spec).mirror == (1, 0, 2)
    with pytest.raises(RetargetError, match="regions has 2 entries, names has 3"):
        spec_of_names(["a", "b", "c"], ["brows", "nose"])


def test_landmarks_json_carries_the_spec_and_registers_it_when_read():
    from retarget import layouts

    layout = layout_from_spec(markers_spec(h3={"name": "h3b"}))
    vertices = np.random.default_rng(0).normal(size=(20, 3))
    faces = np.array([[0, 1, 2]])
    points = SurfacePoints(np.repeat(np.arange(9)[:, None], 3, 1), np.tile([1.0, 0, 0], (9, 1)), layout.name)
    stored = json.loads(json.dumps(points.to_json()))
    assert stored["layout"] == layout.name and stored["layout_spec"] == layout.spec()
    del layouts._REGISTERED[layout.name]
    again = landmarks_from_json(stored, vertices, faces)
    assert again.layout == layout.name and get_layout(layout.name) == layout
    data = pickle.dumps(again)
    del layouts._REGISTERED[layout.name]
    assert pickle.loads(data).layout == layout.name  # as a child process receives it
    assert get_layout(layout.name) == layout
    with pytest.raises(RetargetError, match="is not the layout its 'layout_spec' describes"):
        landmarks_from_json({**stored, "layout": "dutreve22"}, vertices, faces)
    with pytest.raises(RetargetError, match="'layout_spec': head anchors"):
        bad = markers_spec()
        bad["points"][6]["anchor"] = False
        landmarks_from_json({**stored, "layout_spec": bad}, vertices, faces)


def test_conditioning_removes_head_motion_on_the_user_s_anchors():
    layout = layout_from_spec(markers_spec())
    rng = np.random.default_rng(1)
    rest = rng.normal(size=(9, 3)) * 3
    frames = np.repeat(rest[None], 10, 0).astype(np.float32)
    frames += np.linspace(0, 2, 10, dtype=np.float32)[:, None, None] * [1, 0, 0]  # the head slides
    frames[:, :6] += np.linspace(0, 1, 10, dtype=np.float32)[:, None, None] * [0, 1, 0]  # the face moves
    take = Take(frames, layout.point_names, 30.0, None, layout.name, "test", {})
    conditioned, _ = condition_take(take, {"head_pose": "remove", "filter": "none",
                                            "neutral": {"mode": "frame", "frame": 0}})
    moved = conditioned.points - conditioned.points[:1]
    np.testing.assert_allclose(moved[:, 6:], 0, atol=1e-4)  # the anchors stay: the head is removed
    np.testing.assert_allclose(moved[:, :6, 0], 0, atol=1e-4)
    np.testing.assert_allclose(moved[-1, :6, 1], 1, atol=1e-4)  # the face's own motion is kept


def test_the_registry_keeps_the_most_recently_used_layouts(monkeypatch):
    from retarget import layouts

    monkeypatch.setattr(layouts, "MAX_REGISTERED", 3)
    made = [layout_from_spec(markers_spec(m01={"name": f"x{k}"}, m02={"mirror": f"x{k}"})) for k in range(3)]
    get_layout(made[0].name)  # used: the oldest is now made[1]
    layout_from_spec(markers_spec(m01={"name": "y"}, m02={"mirror": "y"}))
    assert len(layouts._REGISTERED) == 3
    assert made[1].name not in layouts._REGISTERED
    assert get_layout(made[0].name) == made[0] and get_layout(made[2].name) == made[2]


def _truth_markers(points, truth) -> np.ndarray:
    """(M,) the rendered marker each column of a 2D marker take (y up) follows: the nearest
    in the first frame where the column is seen."""
    height = truth.cameras[0].size[1]
    seen = np.isfinite(points[..., 0])
    first = seen.argmax(axis=0)
    xy = points[first, np.arange(points.shape[1])] * [1, -1] + [0, height]
    return np.linalg.norm(xy[:, None] - truth.points2d[first, 0], axis=2).argmin(axis=1)


def test_a_layout_made_from_one_marker_take_names_the_markers_of_the_next(tmp_path):
    """Made from a take tracked with every marker in view (columns m01.. in the order the
    tracker met them), the layout keeps where each marker sat (`take_reference`); a later
    clip of the same markers, with other head motion, is tracked in that layout and each
    of its points follows the same marker."""
    from retarget.custom_layouts import take_reference
    from retarget.sources.markers import track_marker_video
    from retarget.testing.marker_video import render_marker_video

    clips = []
    for seed, start in ((3, 0.55), (7, 2.0)):
        path = tmp_path / f"clip{seed}.mkv"
        clips.append((path, render_marker_video(path, n_frames=20, seed=seed, start=start)))
    first = track_marker_video(clips[0][0], layout=None)
    reference = take_reference(first)
    assert reference is not None and len(reference) == first.n_points
    spec = {"points": [{"name": name, "region": "cheeks", "side": "center", "reference": xyz}
                       for name, xyz in zip(first.names, reference)]}
    layout = layout_from_spec(spec)
    assert layout.reference_points().shape == (first.n_points, 3)
    later = track_marker_video(clips[1][0], layout=layout.name)
    assert later.names == first.names and later.layout == layout.name
    np.testing.assert_array_equal(_truth_markers(later.points, clips[1][1]),
                                  _truth_markers(first.points, clips[0][1]))
    lost = Take(np.full((3, 4, 2), np.nan), ("a", "b", "c", "d"), 30.0)
    assert take_reference(lost) is None  # a marker never seen: no reference


def test_a_stereo_take_s_reference_is_each_sticker_s_median_place_in_the_layouts_axes():
    """A stereo take's head frame is the left camera's (x right, y down, z away from it):
    its reference has +y up and +z out of the face, each sticker at its median place
    (a frame off does not move it), centred and scaled to the built-in face."""
    from retarget.custom_layouts import take_reference
    # forehead, chin, the subject's left cheek (the camera's right), nose tip: mm, camera frame
    places = np.array([[0.0, -60.0, 1000.0], [0.0, 60.0, 1000.0], [50.0, 0.0, 1010.0], [0.0, 0.0, 975.0]])
    points = np.repeat(places[None], 5, axis=0)
    points[1] += 30.0   # one frame off
    points[2, 3] = np.nan   # the nose lost in one
    reference = np.array(take_reference(Take(points, ("forehead", "chin", "cheek_l", "nose"), 30.0, source="stereo")))
    expected = (places - places.mean(axis=0)) * [1, -1, -1]
    face = get_layout("ibug68").reference_points()
    size = np.sqrt(((face - face.mean(axis=0)) ** 2).sum(axis=1).mean())
    np.testing.assert_allclose(reference, expected * size / np.sqrt((expected ** 2).sum(axis=1).mean()), atol=1e-4)
    assert reference[0, 1] > reference[1, 1] and reference[2, 0] > 0 and reference[3, 2] > 0
    # A 3D take from another source: its axes are unknown, so no reference.
    assert take_reference(Take(points, ("forehead", "chin", "cheek_l", "nose"), 30.0, source="c3d")) is None
