"""Tests for retarget.layouts: structure of every layout, the API, and geometry checks
against the ICT face model (skipped when its data file is absent) and against vertices
of MediaPipe's canonical face model embedded below."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.layouts import (
    GROUPS,
    IBUG68_TO_MEDIAPIPE468,
    LAYOUTS,
    REGIONS,
    SIDES,
    Layout,
    from_ibug68,
    from_mediapipe468,
    get_layout,
)

ICT_NPZ = Path(__file__).resolve().parents[3] / "shared" / "data" / "ict_face" / "ict_face.npz"

# Vertices of MediaPipe's canonical face model (google/mediapipe,
# mediapipe/modules/face_geometry/data/canonical_face_model.obj, Apache License 2.0),
# only those the iBUG table uses: {vertex index: (x, y, z)}, cm-like units, +x toward the
# subject's left, +y up, +z out of the face.
MP_CANONICAL = {
    127: (-7.743095, 2.364999, -2.005167),  # iBUG 0
    234: (-7.664182, 0.673132, -2.435867),  # iBUG 1
    93: (-7.542244, -1.049282, -2.431321),  # iBUG 2
    132: (-7.270895, -2.890917, -2.252455),  # iBUG 3
    58: (-6.719682, -4.788645, -1.745401),  # iBUG 4
    136: (-5.085276, -7.178590, 0.714711),  # iBUG 5
    149: (-3.210651, -8.533278, 2.802001),  # iBUG 6
    176: (-2.308977, -8.974196, 3.609070),  # iBUG 7
    152: (0.000000, -9.403378, 4.264492),  # iBUG 8
    400: (2.308977, -8.974196, 3.609070),  # iBUG 9
    378: (3.210651, -8.533278, 2.802001),  # iBUG 10
    365: (5.085276, -7.178590, 0.714711),  # iBUG 11
    288: (6.719682, -4.788645, -1.745401),  # iBUG 12
    361: (7.270895, -2.890917, -2.252455),  # iBUG 13
    323: (7.542244, -1.049282, -2.431321),  # iBUG 14
    454: (7.664182, 0.673132, -2.435867),  # iBUG 15
    356: (7.743095, 2.364999, -2.005167),  # iBUG 16
    70: (-5.720968, 4.254584, 2.830852),  # iBUG 17
    63: (-4.985894, 4.802461, 3.751977),  # iBUG 18
    105: (-3.986562, 5.109487, 4.466315),  # iBUG 19
    66: (-2.760292, 5.100971, 5.015990),  # iBUG 20
    107: (-1.395634, 5.011963, 5.316032),  # iBUG 21
    336: (1.395634, 5.011963, 5.316032),  # iBUG 22
    296: (2.760292, 5.100971, 5.015990),  # iBUG 23
    334: (3.986562, 5.109487, 4.466315),  # iBUG 24
    293: (4.985894, 4.802461, 3.751977),  # iBUG 25
    300: (5.720968, 4.254584, 2.830852),  # iBUG 26
    168: (0.000000, 3.271027, 5.236015),  # iBUG 27
    197: (0.000000, 1.728369, 6.316750),  # iBUG 28
    195: (0.000000, 1.059413, 6.774605),  # iBUG 29
    4: (0.000000, -0.463170, 7.586580),  # iBUG 30
    98: (-1.405627, -1.714196, 5.241087),  # iBUG 31
    97: (-0.597442, -2.013686, 5.866456),  # iBUG 32
    2: (0.000000, -2.089024, 6.058267),  # iBUG 33
    326: (0.597442, -2.013686, 5.866456),  # iBUG 34
    327: (1.405627, -1.714196, 5.241087),  # iBUG 35
    33: (-4.445859, 2.663991, 3.173422),  # iBUG 36
    160: (-3.670075, 2.927714, 3.724325),  # iBUG 37
    158: (-2.724032, 2.961810, 3.871767),  # iBUG 38
    133: (-1.856432, 2.585245, 3.757904),  # iBUG 39
    153: (-2.724032, 2.315802, 3.777151),  # iBUG 40
    144: (-3.670075, 2.360153, 3.635230),  # iBUG 41
    362: (1.856432, 2.585245, 3.757904),  # iBUG 42
    385: (2.724032, 2.961810, 3.871767),  # iBUG 43
    387: (3.670075, 2.927714, 3.724325),  # iBUG 44
    263: (4.445859, 2.663991, 3.173422),  # iBUG 45
    373: (3.670075, 2.360153, 3.635230),  # iBUG 46
    380: (2.724032, 2.315802, 3.777151),  # iBUG 47
    61: (-2.456206, -4.342621, 4.283884),  # iBUG 48
    39: (-1.431615, -3.500953, 5.496189),  # iBUG 49
    37: (-0.711452, -3.329355, 5.877044),  # iBUG 50
    0: (0.000000, -3.406404, 5.979507),  # iBUG 51
    267: (0.711452, -3.329355, 5.877044),  # iBUG 52
    269: (1.431615, -3.500953, 5.496189),  # iBUG 53
    291: (2.456206, -4.342621, 4.283884),  # iBUG 54
    321: (1.838624, -4.828746, 4.823737),  # iBUG 55
    314: (0.699606, -5.291850, 5.448304),  # iBUG 56
    17: (0.000000, -5.365123, 5.535441),  # iBUG 57
    84: (-0.699606, -5.291850, 5.448304),  # iBUG 58
    91: (-1.838624, -4.828746, 4.823737),  # iBUG 59
    78: (-2.153084, -4.276322, 4.038093),  # iBUG 60
    81: (-1.024340, -3.989851, 4.926693),  # iBUG 61
    13: (0.000000, -3.994436, 5.219482),  # iBUG 62
    311: (1.024340, -3.989851, 4.926693),  # iBUG 63
    308: (2.153084, -4.276322, 4.038093),  # iBUG 64
    402: (1.098819, -4.458788, 5.120727),  # iBUG 65
    14: (0.000000, -4.542400, 5.404754),  # iBUG 66
    178: (-1.098819, -4.458788, 5.120727),  # iBUG 67
}

# The iBUG 68 mirror pairs, written out by hand (independent of the module's derivation).
IBUG68_PAIRS = (
    [(i, 16 - i) for i in range(8)]  # jaw contour
    + [(17, 26), (18, 25), (19, 24), (20, 23), (21, 22)]  # brows
    + [(31, 35), (32, 34)]  # nose base
    + [(36, 45), (37, 44), (38, 43), (39, 42), (40, 47), (41, 46)]  # eyes
    + [(48, 54), (49, 53), (50, 52), (55, 59), (56, 58)]  # outer lip
    + [(60, 64), (61, 63), (65, 67)]  # inner lip
)
IBUG68_MIDLINE = (8, 27, 28, 29, 30, 33, 51, 57, 62, 66)

SNAKE = re.compile(r"^[a-z][a-z0-9]*(_[a-z0-9]+)*$")


@pytest.fixture(params=sorted(LAYOUTS))
def layout(request) -> Layout:
    return LAYOUTS[request.param]


@pytest.fixture(params=sorted(name for name, lay in LAYOUTS.items() if lay.has_ibug68))
def ibug_layout(request) -> Layout:
    """The layouts made of iBUG points (all but the dense mediapipe468)."""
    return LAYOUTS[request.param]


@pytest.fixture(scope="module")
def ict_landmarks() -> np.ndarray:
    """(68, 3) float64, cm: the ICT generic neutral face at its 68 landmark vertices."""
    if not ICT_NPZ.exists():
        pytest.skip(f"ICT face data not found at {ICT_NPZ}")
    with np.load(ICT_NPZ) as d:
        return d["neutral"].astype(np.float64)[d["landmarks_68"]]


def _similarity_fit(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(K, 3) `a` moved by the least-squares similarity transform onto (K, 3) `b`."""
    ma, mb = a.mean(0), b.mean(0)
    u, s, vt = np.linalg.svd((a - ma).T @ (b - mb))
    d = np.ones(3)
    d[2] = np.sign(np.linalg.det(u @ vt))
    r = (u * d) @ vt
    scale = (s * d).sum() / ((a - ma) ** 2).sum()
    return (a - ma) @ r * scale + mb


# ---------------------------------------------------------------- every layout


def test_builtin_layouts_and_counts():
    expected = {"dutreve21": 21, "ibug68": 68, "ibug51": 51, "mediapipe68": 68}
    for name, n in expected.items():
        assert LAYOUTS[name].n_points == n
        assert LAYOUTS[name].name == name
        assert get_layout(name) is LAYOUTS[name]


def test_structure(layout):
    n = layout.n_points
    for field in ("point_names", "regions", "sides", "mirror", "ibug68", "mediapipe468"):
        assert len(getattr(layout, field)) == n, field
    assert len(set(layout.point_names)) == n
    assert all(SNAKE.match(p) for p in layout.point_names)
    assert set(layout.regions) <= set(REGIONS)
    assert set(layout.sides) <= set(SIDES)
    assert layout.description


def test_mirror_is_an_involution_between_opposite_sides(layout):
    mirror = np.asarray(layout.mirror)
    assert np.array_equal(mirror[mirror], np.arange(layout.n_points))
    flip = {"right": "left", "left": "right", "center": "center"}
    for i, j in enumerate(layout.mirror):
        assert layout.sides[j] == flip[layout.sides[i]], layout.point_names[i]
        assert layout.regions[j] == layout.regions[i], layout.point_names[i]
        assert (i == j) == (layout.sides[i] == "center"), layout.point_names[i]
        tokens = layout.point_names[i].split("_")
        swapped = "_".join({"right": "left", "left": "right"}.get(t, t) for t in tokens)
        assert layout.point_names[j] == swapped


def test_source_indices_in_range_and_distinct(ibug_layout):
    layout = ibug_layout
    ibug = np.asarray(layout.ibug68)
    mp = np.asarray(layout.mediapipe468)
    assert ibug.min() >= 0 and ibug.max() < 68
    assert mp.min() >= 0 and mp.max() < 468
    assert len(set(ibug.tolist())) == layout.n_points
    assert len(set(mp.tolist())) == layout.n_points
    # one source of truth: the MediaPipe column is the table read at the iBUG indices
    assert layout.mediapipe468 == tuple(IBUG68_TO_MEDIAPIPE468[i] for i in layout.ibug68)


def test_points_agree_with_ibug68(ibug_layout):
    layout = ibug_layout
    ibug68 = LAYOUTS["ibug68"]
    for i, k in enumerate(layout.ibug68):
        assert layout.point_names[i] == ibug68.point_names[k]
        assert layout.regions[i] == ibug68.regions[k]
        assert layout.sides[i] == ibug68.sides[k]
        assert layout.ibug68[layout.mirror[i]] == ibug68.mirror[k]


def test_no_name_is_both_a_region_group_and_point(layout):
    assert not set(REGIONS) & set(GROUPS)
    assert not (set(REGIONS) | set(GROUPS)) & set(layout.point_names)
    for group, regions in GROUPS.items():
        assert set(regions) <= set(REGIONS), group


# ---------------------------------------------------------------- layout contents


def test_ibug68_regions():
    lay = LAYOUTS["ibug68"]
    expected = (
        ["jaw"] * 17
        + ["brows"] * 10
        + ["nose"] * 9
        + ["eyes"] * 12
        + ["mouth_corners"] + ["upper_lip"] * 5 + ["mouth_corners"] + ["lower_lip"] * 5
        + ["mouth_corners"] + ["upper_lip"] * 3 + ["mouth_corners"] + ["lower_lip"] * 3
    )
    assert list(lay.regions) == expected
    assert lay.ibug68 == tuple(range(68))


def test_ibug68_sides():
    lay = LAYOUTS["ibug68"]
    right = set(range(0, 8)) | set(range(17, 22)) | {31, 32} | set(range(36, 42))
    right |= {48, 49, 50, 58, 59, 60, 61, 67}
    for i in range(68):
        side = "center" if i in IBUG68_MIDLINE else "right" if i in right else "left"
        assert lay.sides[i] == side, (i, lay.point_names[i])


def test_ibug68_mirror_pairs():
    mirror = LAYOUTS["ibug68"].mirror
    assert len(IBUG68_PAIRS) * 2 + len(IBUG68_MIDLINE) == 68
    for a, b in IBUG68_PAIRS:
        assert mirror[a] == b and mirror[b] == a, (a, b)
    for m in IBUG68_MIDLINE:
        assert mirror[m] == m


def test_ibug51_is_ibug68_without_jaw():
    lay51, lay68 = LAYOUTS["ibug51"], LAYOUTS["ibug68"]
    assert lay51.ibug68 == tuple(range(17, 68))
    assert "jaw" not in lay51.regions
    assert lay51.point_names == lay68.point_names[17:]
    assert lay51.mirror == tuple(m - 17 for m in lay68.mirror[17:])


def test_mediapipe68_matches_ibug68_order():
    mp68 = LAYOUTS["mediapipe68"]
    assert mp68.ibug68 == tuple(range(68))
    assert mp68.mediapipe468 == IBUG68_TO_MEDIAPIPE468
    assert mp68.point_names == LAYOUTS["ibug68"].point_names


def test_dutreve21_composition():
    lay = LAYOUTS["dutreve21"]
    counts = {r: lay.regions.count(r) for r in REGIONS}
    assert counts["brows"] == 6 and counts["eyes"] == 4 and counts["nose"] == 3
    assert counts["upper_lip"] == 3 and counts["lower_lip"] == 3 and counts["mouth_corners"] == 2
    assert counts["jaw"] == 0
    for region, per_side in (("brows", 3), ("eyes", 2)):
        sides = [s for s, r in zip(lay.sides, lay.regions) if r == region]
        assert sides.count("right") == sides.count("left") == per_side
    nose = [s for s, r in zip(lay.sides, lay.regions) if r == "nose"]
    assert sorted(nose) == ["center", "left", "right"]
    assert lay.point_names[lay.index("nose_tip")] == "nose_tip"
    assert lay.ibug68[lay.index("nose_tip")] == 30
    brow = ("brow_right_outer", "brow_right_middle", "brow_right_inner")
    assert [lay.ibug68[lay.index(p)] for p in brow] == [17, 19, 21]
    # eye points: one upper-lid and one lower-lid point per eye
    eye_ibug = {lay.ibug68[i] for i, r in enumerate(lay.regions) if r == "eyes"}
    assert eye_ibug == {38, 40, 43, 47}


def test_mediapipe_table_anchors():
    t = IBUG68_TO_MEDIAPIPE468
    assert len(t) == 68 and len(set(t)) == 68 and all(0 <= v < 468 for v in t)
    assert (t[36], t[45]) == (33, 263)  # outer eye corners, subject's right first
    assert (t[39], t[42]) == (133, 362)  # inner eye corners
    assert (t[48], t[54]) == (61, 291)  # mouth corners
    assert (t[62], t[66]) == (13, 14)  # inner-lip centres
    assert t[8] == 152  # chin
    assert t[30] in (1, 4)  # nose tip (4 chosen; see the module docstring)


def test_mediapipe_table_left_right_on_canonical_model():
    lay = LAYOUTS["ibug68"]
    assert set(IBUG68_TO_MEDIAPIPE468) == set(MP_CANONICAL)
    xyz = np.array([MP_CANONICAL[v] for v in IBUG68_TO_MEDIAPIPE468])  # (68, 3)
    # a mirror pair of iBUG points maps to a mirror pair of canonical vertices
    assert np.allclose(lay.mirrored(xyz), xyz, atol=1e-5)
    sign = np.sign(np.round(xyz[:, 0], 5))
    assert np.array_equal(sign, [{"right": -1, "center": 0, "left": 1}[s] for s in lay.sides])
    # brows above eyes above nose base above mouth above chin
    y = xyz[:, 1]
    assert y[17:27].min() > y[36:48].max()
    assert y[36:48].min() > y[31:36].max()
    assert y[31:36].min() > y[48:68].max()
    assert y[48:68].min() > y[8]
    assert y[list(range(49, 54)) + [61, 62, 63]].min() > y[list(range(55, 60)) + [65, 66, 67]].max()


# ---------------------------------------------------------------- methods


def test_index():
    lay = LAYOUTS["ibug68"]
    assert lay.index("chin") == 8
    assert lay.index("mouth_corner_left") == 54
    with pytest.raises(RetargetError, match="brow_right_outr") as info:
        lay.index("brow_right_outr")
    assert "brow_right_outer" in str(info.value)  # close matches are listed


def test_region_mask():
    lay = LAYOUTS["ibug68"]
    mask = lay.region_mask("brows")
    assert mask.shape == (68,) and mask.dtype == bool
    assert np.array_equal(np.flatnonzero(mask), np.arange(17, 27))
    mouth = lay.region_mask("mouth")
    assert np.array_equal(np.flatnonzero(mouth), np.arange(48, 68))
    assert np.array_equal(
        mouth, lay.region_mask(["upper_lip", "lower_lip", "mouth_corners"])
    )
    upper = lay.region_mask(["upper_face"])
    assert np.array_equal(np.flatnonzero(upper), np.r_[17:27, 36:48])
    mixed = lay.region_mask(["nose", "chin", "eye_left_outer"])
    assert np.array_equal(np.flatnonzero(mixed), np.r_[8, 27:36, 45])
    assert lay.region_mask([]).sum() == 0
    assert LAYOUTS["dutreve21"].region_mask("jaw").sum() == 0
    assert LAYOUTS["dutreve21"].region_mask("all").all()
    with pytest.raises(RetargetError, match="cheek'"):
        lay.region_mask(["brows", "cheek"])
    with pytest.raises(RetargetError, match="'eye'"):
        lay.region_mask("eye")


def test_mirrored():
    lay = LAYOUTS["dutreve21"]
    rng = np.random.default_rng(0)
    p = rng.standard_normal((lay.n_points, 3))
    m = lay.mirrored(p)
    assert m.shape == p.shape
    assert np.allclose(lay.mirrored(m), p)
    i, j = lay.index("brow_right_outer"), lay.index("brow_left_outer")
    assert np.allclose(m[i], p[j] * [-1, 1, 1])
    k = lay.index("nose_tip")
    assert np.allclose(m[k], p[k] * [-1, 1, 1])
    # 2D and batched input; the input is not modified
    p2 = rng.standard_normal((4, 2, lay.n_points, 2))
    before = p2.copy()
    m2 = lay.mirrored(p2)
    assert m2.shape == p2.shape and np.array_equal(p2, before)
    assert np.allclose(m2[..., i, 0], -p2[..., j, 0]) and np.allclose(m2[..., i, 1], p2[..., j, 1])
    assert lay.mirrored(np.zeros((lay.n_points, 3), dtype=int)).dtype == np.float64
    with pytest.raises(RetargetError, match=r"\(20, 3\)"):
        lay.mirrored(np.zeros((20, 3)))
    with pytest.raises(RetargetError):
        lay.mirrored(np.zeros(21))


def test_select_keeps_order_and_remaps_mirror():
    lay = LAYOUTS["ibug68"]
    picked = ["eye_left_outer", "brow_right_outer", "eye_right_outer", "brow_left_outer"]
    sub = lay.select(picked, name="four")
    assert sub.name == "four"
    assert sub.point_names == (
        "brow_right_outer",
        "brow_left_outer",
        "eye_right_outer",
        "eye_left_outer",
    )
    assert sub.mirror == (1, 0, 3, 2)
    assert sub.ibug68 == (17, 26, 36, 45)
    assert sub.mediapipe468 == (70, 300, 33, 263)
    # a partner outside the selection maps to itself
    lone = lay.select(["brow_right_outer", "nose_tip", "mouth_corner_left"])
    assert lone.mirror == (0, 1, 2)
    assert lone.name == "ibug68_subset"
    # regions, groups and indices, repeats harmless
    mouth = lay.select(["mouth", 48, 54])
    assert mouth.ibug68 == tuple(range(48, 68))
    assert mouth.mirror[mouth.index("mouth_corner_right")] == mouth.index("mouth_corner_left")
    assert lay.select(30).point_names == ("nose_tip",)
    assert lay.select(np.array([36, 45])).mirror == (1, 0)
    assert LAYOUTS["dutreve21"].select("upper_face").n_points == 10
    by_mask = lay.select(lay.region_mask("eyes"))
    assert by_mask.ibug68 == tuple(range(36, 48))
    assert by_mask.mirror == tuple(m - 36 for m in lay.mirror[36:48])


def test_select_errors():
    lay = LAYOUTS["dutreve21"]
    with pytest.raises(RetargetError, match="jaw"):
        lay.select("jaw")  # a known region with no points here: empty selection
    with pytest.raises(RetargetError, match="21"):
        lay.select([0, 21])
    with pytest.raises(RetargetError, match="nose_top"):
        lay.select(["nose_top"])
    with pytest.raises(RetargetError, match=r"\(68,\)"):
        lay.select(np.ones(68, dtype=bool))


def test_layout_validation():
    good = dict(
        name="t",
        description="test",
        point_names=("a_right", "a_left", "b"),
        regions=("brows", "brows", "nose"),
        sides=("right", "left", "center"),
        mirror=(1, 0, 2),
        ibug68=(17, 26, 30),
        mediapipe468=(70, 300, 4),
    )
    assert Layout(**good).n_points == 3
    for field, bad, match in (
        ("mirror", (1, 2, 0), "involution"),
        ("mirror", (1, 0, 3), "mirror"),
        ("regions", ("brows", "brows", "cheek"), "cheek"),
        ("sides", ("right", "left", "middle"), "middle"),
        ("ibug68", (17, 26, 68), "68"),
        ("mediapipe468", (70, 300, 468), "468"),
        ("point_names", ("a", "a", "b"), "repeated"),
        ("regions", ("brows", "brows"), "regions"),
    ):
        with pytest.raises(RetargetError, match=match):
            Layout(**{**good, field: bad})


def test_get_layout_unknown():
    with pytest.raises(RetargetError, match="dlib68") as info:
        get_layout("dlib68")
    for name in LAYOUTS:
        assert name in str(info.value)


# ---------------------------------------------------------------- converters


def test_from_ibug68():
    rng = np.random.default_rng(1)
    p68 = rng.standard_normal((68, 3))
    for name, lay in LAYOUTS.items():
        if not lay.has_ibug68:
            with pytest.raises(RetargetError, match="from_mediapipe468"):
                from_ibug68(p68, lay)
            continue
        out = from_ibug68(p68, lay)
        assert out.shape == (lay.n_points, 3)
        assert np.array_equal(out, p68[list(lay.ibug68)])
        assert np.array_equal(from_ibug68(p68, name), out)
    batch = rng.standard_normal((5, 7, 68, 2))
    out = from_ibug68(batch, "dutreve21")
    assert out.shape == (5, 7, 21, 2)
    assert np.array_equal(out[..., 11, :], batch[..., 30, :])  # nose tip
    out[...] = 0
    assert batch.any()  # a copy, not a view
    assert from_ibug68(np.ones((68, 2), dtype=np.int32), "ibug51").dtype == np.float64
    with pytest.raises(RetargetError, match=r"\(51, 3\)"):
        from_ibug68(np.zeros((51, 3)), "ibug51")
    with pytest.raises(RetargetError, match="points68"):
        from_ibug68(np.zeros(68), "ibug68")
    with pytest.raises(RetargetError, match="dtype"):
        from_ibug68(np.full((68, 3), "x"), "ibug68")
    with pytest.raises(RetargetError, match="nope"):
        from_ibug68(p68, "nope")


def test_from_mediapipe468():
    rng = np.random.default_rng(2)
    for n in (468, 478):
        mesh = rng.standard_normal((3, n, 3))
        out = from_mediapipe468(mesh, LAYOUTS["mediapipe68"])
        assert out.shape == (3, 68, 3)
        assert np.array_equal(out[:, 36], mesh[:, 33]) and np.array_equal(out[:, 45], mesh[:, 263])
        d21 = from_mediapipe468(mesh, "dutreve21")
        assert d21.shape == (3, 21, 3)
        # both routes agree: MediaPipe -> 68 -> 21 equals MediaPipe -> 21
        assert np.array_equal(from_ibug68(out, "dutreve21"), d21)
    with pytest.raises(RetargetError, match=r"\(467, 3\)"):
        from_mediapipe468(np.zeros((467, 3)), "ibug68")


# ---------------------------------------------------------------- ICT geometry


def test_mediapipe_table_fits_ict_landmarks(ict_landmarks):
    canon = np.array([MP_CANONICAL[v] for v in IBUG68_TO_MEDIAPIPE468])  # (68, 3)
    inner = np.arange(17, 68)
    fitted = _similarity_fit(canon[inner], ict_landmarks[inner])
    err = np.linalg.norm(fitted - ict_landmarks[inner], axis=1)  # cm
    assert err.max() < 0.6, (inner[err.argmax()], err.max())
    assert np.sqrt((err**2).mean()) < 0.35
    # with two iBUG points swapped in the table the fit is clearly worse
    swapped = canon.copy()
    swapped[[37, 38]] = swapped[[38, 37]]
    refit = _similarity_fit(swapped[inner], ict_landmarks[inner])
    bad = np.linalg.norm(refit - ict_landmarks[inner], axis=1)
    assert bad.max() > 0.6


def test_mirrored_ict_landmarks_land_on_partners(ict_landmarks):
    lay = LAYOUTS["ibug68"]
    err = np.linalg.norm(lay.mirrored(ict_landmarks) - ict_landmarks, axis=1)
    assert err[17:].max() < 0.5  # non-contour points, cm
    assert err[:17].max() < 0.5  # the ICT jaw contour is symmetric too
    for name in ("dutreve21", "ibug51"):
        sub = LAYOUTS[name]
        p = from_ibug68(ict_landmarks, sub)
        assert np.linalg.norm(sub.mirrored(p) - p, axis=1).max() < 0.5


def test_ict_sides_agree_with_x(ict_landmarks, ibug_layout):
    layout = ibug_layout
    x = from_ibug68(ict_landmarks, layout)[:, 0]
    sides = np.asarray(layout.sides)
    assert (x[sides == "right"] < -0.3).all()
    assert (x[sides == "left"] > 0.3).all()
    assert (np.abs(x[sides == "center"]) < 0.05).all()


def test_ict_vertical_order(ict_landmarks, ibug_layout):
    layout = ibug_layout
    y = from_ibug68(ict_landmarks, layout)[:, 1]
    regions = np.asarray(layout.regions)
    assert y[regions == "upper_lip"].min() > y[regions == "lower_lip"].max()
    if "brows" in regions and "eyes" in regions:
        assert y[regions == "brows"].min() > y[regions == "eyes"].max()
    if "nose" in regions and "upper_lip" in regions:
        assert y[regions == "nose"].min() > y[regions == "upper_lip"].max()
    # each upper-lip point lies above the lower-lip point nearest it in x
    x = from_ibug68(ict_landmarks, layout)[:, 0]
    for i in np.flatnonzero(regions == "upper_lip"):
        lower = np.flatnonzero(regions == "lower_lip")
        j = lower[np.argmin(np.abs(x[lower] - x[i]))]
        assert y[i] > y[j], (layout.point_names[i], layout.point_names[j])


# ---------------------------------------------------------------- the dense layout


def test_dense_layout_is_every_face_mesh_point_with_its_symmetry():
    from retarget.facemesh.canonical import canonical_face

    lay = LAYOUTS["mediapipe468"]
    canonical = canonical_face().vertices
    assert lay.n_points == 468 and lay.mediapipe468 == tuple(range(468))
    assert not lay.has_ibug68 and all(LAYOUTS[n].has_ibug68 for n in LAYOUTS if n != "mediapipe468")
    # the iBUG vertices carry their iBUG names, regions and indices
    ibug68 = LAYOUTS["ibug68"]
    for k, vertex in enumerate(IBUG68_TO_MEDIAPIPE468):
        assert lay.point_names[vertex] == ibug68.point_names[k]
        assert lay.regions[vertex] == ibug68.regions[k] and lay.ibug68[vertex] == k
    assert sum(i >= 0 for i in lay.ibug68) == 68
    # partners are mirror images on the canonical face; sides follow x
    mirror = np.asarray(lay.mirror)
    assert np.allclose(canonical[mirror], canonical * [-1, 1, 1], atol=1e-5)
    x, sides = canonical[:, 0], np.asarray(lay.sides)
    assert (x[sides == "right"] < 0).all() and (x[sides == "left"] > 0).all()
    assert np.allclose(x[sides == "center"], 0, atol=1e-5)
    # every region holds points, the cheeks and forehead only here
    counts = {r: lay.regions.count(r) for r in REGIONS}
    assert min(counts.values()) >= 10, counts
    assert all(r not in LAYOUTS[n].regions for n in LAYOUTS if n != "mediapipe468" for r in ("cheeks", "forehead"))
    assert np.array_equal(from_mediapipe468(canonical, lay), canonical)


def test_dense_regions_lie_where_their_names_say():
    from retarget.facemesh.canonical import canonical_face

    lay = LAYOUTS["mediapipe468"]
    x, y = canonical_face().vertices[:, :2].T
    r = np.asarray(lay.regions)
    eye_corners = y[[IBUG68_TO_MEDIAPIPE468[i] for i in (36, 39, 42, 45)]].mean()
    assert y[r == "forehead"].max() == y.max() and y[r == "forehead"].min() > eye_corners
    assert y[r == "brows"].mean() > y[r == "eyes"].mean() > y[r == "upper_lip"].mean()
    assert y[r == "jaw"].mean() < y[r == "lower_lip"].mean()
    # each upper-lip point lies above the lower-lip point nearest it in x
    lower = np.flatnonzero(r == "lower_lip")
    for i in np.flatnonzero(r == "upper_lip"):
        assert y[i] > y[lower[np.argmin(np.abs(x[lower] - x[i]))]], lay.point_names[i]
    # cheeks are off the midline, beside the nose and mouth
    assert np.abs(x[r == "cheeks"]).min() > 1.0


def test_dense_reference_points_lie_on_the_sample_face():
    from scipy.spatial import cKDTree

    from retarget.sample_face import sample_face

    face = sample_face(1)
    lay = LAYOUTS["mediapipe468"]
    ref = lay.reference_points()
    assert ref.shape == (468, 3) and not ref.flags.writeable
    rows = [i for i, k in enumerate(lay.ibug68) if k >= 0]
    assert np.allclose(ref[rows], face.vertices[face.landmarks68[[lay.ibug68[i] for i in rows]]])
    # the others: the canonical face carried onto the sample face, near its surface
    others = [i for i, k in enumerate(lay.ibug68) if k < 0]
    distance = cKDTree(face.vertices).query(ref[others])[0]
    assert np.median(distance) < 0.5, np.median(distance)
