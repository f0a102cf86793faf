"""The landmark guide of the short layouts reads as a face: an outline, eyes and lips are
drawn behind the dots (canvas pixels where the sketch's paths run, away from any dot),
the next point is named beside its spot, on the side the caption explains: the face's
right is drawn on your left."""

from __future__ import annotations

import numpy as np
import pytest

from tests.e2e.conftest import upload_face, write_face_file
from tests.waits import scaled_ms

_IDENTITY = np.array([-0.3, 0.5, 0.1, 0.4, -0.6])


@pytest.fixture(scope="module")
def server(module_server):
    """One server for these tests: each uploads a face of its own and reads only that."""
    return module_server


@pytest.fixture(scope="module")
def face_file(tmp_path_factory):
    return write_face_file(tmp_path_factory.mktemp("meshes"), "guide_face.obj", _IDENTITY)


def _guide(page) -> dict:
    """The guide as drawn: its sketch paths and point positions (CSS px), the canvas's
    size, and the canvas pixels (RGBA, device px)."""
    return page.evaluate("""() => {
        const guide = window.app.marks.guide, canvas = guide.canvas;
        const data = canvas.getContext('2d').getImageData(0, 0, canvas.width, canvas.height).data;
        return {sketch: guide.sketch, points: guide._screen, width: canvas.clientWidth,
                dpr: canvas.width / canvas.clientWidth, height: canvas.height, rgba: Array.from(data)};
    }""")


def _pixels(guide) -> np.ndarray:
    return np.array(guide["rgba"], np.uint8).reshape(guide["height"], -1, 4)


def _drawn_along(guide, path) -> float:
    """The share of places along the closed `path` away from every dot (over 4.5 CSS px)
    where the canvas is painted."""
    pixels, dpr = _pixels(guide), guide["dpr"]
    points = np.array(guide["points"])
    path = np.array(path)
    t = np.linspace(0, 1, 6, endpoint=False)[:, None, None]
    along = (path + t * (np.roll(path, -1, axis=0) - path)).reshape(-1, 2)
    hits = []
    for x, y in along:
        if np.min(np.hypot(*(points - [x, y]).T)) < 4.5:
            continue
        xi, yi = int(round(x * dpr)), int(round(y * dpr))
        window = pixels[max(yi - 1, 0):yi + 2, max(xi - 1, 0):xi + 2, 3]
        hits.append(window.max() > 0)
    assert len(hits) >= 3, "the sketch runs only through the dots"
    return float(np.mean(hits))


@pytest.mark.parametrize("layout, shapes", [
    ("dutreve22", {"face", "eye_right", "eye_left", "lips"}),
    ("dutreve21", {"face", "eye_right", "eye_left", "lips"}),
    ("ibug51", {"face", "lips"}),  # its eyes have rings of six points already
])
def test_short_layouts_are_drawn_over_a_sketched_face(server, page, face_file, layout, shapes):
    upload_face(server, page, face_file, f"guide {layout}")
    page.select_option("#layout-select", layout)
    page.wait_for_function("l => window.app.landmarks.state.layout === l", arg=layout, timeout=scaled_ms(30_000))
    guide = _guide(page)
    assert {s["name"] for s in guide["sketch"]} == shapes
    for shape in guide["sketch"]:
        assert _drawn_along(guide, shape["path"]) > 0.9, shape["name"]
    # the outline surrounds the points (down to the chin where the layout has one)
    face = np.array(next(s["path"] for s in guide["sketch"] if s["name"] == "face"))
    points = np.array(guide["points"])
    assert face[:, 0].min() < points[:, 0].min() and face[:, 0].max() > points[:, 0].max()
    assert face[:, 1].min() < points[:, 1].min() and face[:, 1].max() >= points[:, 1].max() - 0.5
    assert "The face's right is drawn on your left" in page.inner_text("#guide-caption")


def test_the_next_point_is_named_at_its_spot_on_the_side_the_caption_says(server, page, face_file):
    upload_face(server, page, face_file, "guide names")
    page.select_option("#layout-select", "dutreve22")
    page.wait_for_function("() => window.app.landmarks.state.layout === 'dutreve22'", timeout=scaled_ms(30_000))
    assert page.inner_text("#next-point") == "brow_right_outer"
    assert page.inner_text("#next-side") == "· on your left"
    guide = _guide(page)
    x, y = guide["points"][0]
    assert x < guide["width"] / 2  # the face's right, on the viewer's left
    # its name in the guide's yellow, above the spot
    pixels, dpr = _pixels(guide), guide["dpr"]
    box = pixels[int((y - 20) * dpr):int((y - 8) * dpr), int(max(x - 40, 0) * dpr):int((x + 60) * dpr)]
    yellow = (box[..., 0] > 180) & (box[..., 1] > 150) & (box[..., 2] < 120) & (box[..., 3] > 200)
    assert yellow.sum() > 20

    # the face's left: its partner, after clicking it in the guide
    partner = page.evaluate("() => window.app.landmarks.layout.points.findIndex((p) => p.name === 'brow_left_outer')")
    px, py = guide["points"][partner]
    box_of = page.locator("#guide").bounding_box()
    page.mouse.click(box_of["x"] + px, box_of["y"] + py)
    page.wait_for_function("() => document.getElementById('next-point').textContent === 'brow_left_outer'",
                           timeout=scaled_ms(30_000))
    assert page.inner_text("#next-side") == "· on your right"
    assert px > guide["width"] / 2
