"""The smaller rough edges of issue 13 item 5, each as a user meets it in the browser:
Play visible on first open at 1280 x 800, a double click on New makes one project, the
Export panel lists a new take without being hovered, a new project shows none of the old
one's figures or notes, the feature points hide while playing (Show points), the brush
starts a third of the eye-to-eye distance wide, and the heat map has a legend with the
shown feature's weight range."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from retarget.landmarks import landmarks_from_json
from retarget.layouts import get_layout
from retarget.sample_face import demo_performance
from tests.e2e.conftest import open_project
from tests.waits import scaled_ms


@pytest.fixture(scope="module")
def server(module_server):
    """One server for these tests: each opens the sample project or makes projects of its
    own, and none depends on what another left there (the export test deletes the take it
    adds; new projects are named after the existing ones)."""
    return module_server


def _sample(server) -> dict:
    return next(p for p in server.api("GET", "/api/projects") if p["rig"])


def _open_sample(server, page) -> dict:
    sample = _sample(server)
    open_project(page, server, sample["id"])
    page.wait_for_function("() => window.app.face && window.app.face.nJoints === 68", timeout=scaled_ms(30_000))
    return sample


def _play_demo(page) -> None:
    page.wait_for_function("() => window.app.stream && window.app.stream.state === 'open'", timeout=scaled_ms(30_000))
    page.select_option("#source-select", "demo")
    page.click("#play")
    page.wait_for_function("() => window.app.streaming", timeout=scaled_ms(30_000))


def test_play_is_visible_on_first_open_without_scrolling(server, page):
    _open_sample(server, page)
    box = page.locator("#play").bounding_box()
    assert box is not None and 0 <= box["y"] and box["y"] + box["height"] <= 800 and box["x"] + box["width"] <= 1280
    assert page.evaluate("() => document.getElementById('panel').scrollTop") == 0
    assert page.is_visible("#play") and page.is_enabled("#play")


def test_a_double_click_on_new_makes_one_project(server, page):
    _open_sample(server, page)
    before = {p["id"] for p in server.api("GET", "/api/projects")}
    taken = {p["name"] for p in server.api("GET", "/api/projects")}
    expected = next(f"Untitled {n}" for n in range(1, 1000) if f"Untitled {n}" not in taken)
    page.dblclick("#new-project")
    page.wait_for_function("() => window.app.project && window.app.project.name.startsWith('Untitled')", timeout=scaled_ms(30_000))
    page.evaluate("() => window.app.ready")
    page.wait_for_timeout(1500)  # a second request would have landed by now
    projects = server.api("GET", "/api/projects")
    new = [p for p in projects if p["id"] not in before]
    assert [p["name"] for p in new] == [expected]
    assert page.input_value("#project-name") == expected
    names = [p["name"] for p in projects]
    assert len(names) == len(set(names))


def test_the_export_panel_lists_a_new_take_without_being_hovered(server, page, tmp_path):
    _open_sample(server, page)
    page.mouse.move(5, 5)  # over the project bar, far from the Export panel, and it stays there
    assert page.is_visible("#export-none")
    _, frames = demo_performance(30.0)
    path = tmp_path / "smile.npy"
    np.save(path, frames[:45, np.r_[:68]].astype(np.float32))
    page.set_input_files("#take-file", str(path))
    page.wait_for_selector("#take-list li:has-text('smile')", timeout=scaled_ms(60_000))
    page.wait_for_selector("#export-takes label:has-text('smile')", timeout=scaled_ms(5_000))
    assert page.is_hidden("#export-none")
    # deleted in the Performance panel: gone from the Export panel too
    page.click("#take-list li:has-text('smile') .delete")
    page.click("#confirm-ok")
    page.wait_for_function("() => !document.querySelector('#take-list li')", timeout=scaled_ms(30_000))
    page.wait_for_selector("#export-takes label", state="detached", timeout=scaled_ms(5_000))
    assert page.is_visible("#export-none")


def test_a_new_project_shows_none_of_the_old_ones_figures_or_notes(server, page):
    _open_sample(server, page)
    _play_demo(page)
    page.wait_for_function("() => document.getElementById('latency').textContent.endsWith('ms')", timeout=scaled_ms(30_000))
    page.click("#record")
    page.wait_for_function("() => document.getElementById('record').textContent.startsWith('■')", timeout=scaled_ms(10_000))
    page.wait_for_timeout(500)
    page.click("#record")
    page.wait_for_function("() => document.getElementById('source-note').textContent.startsWith('Recorded')",
                           timeout=scaled_ms(30_000))
    page.click("#new-project")
    page.wait_for_function("() => window.app.project && window.app.project.name.startsWith('Untitled')", timeout=scaled_ms(30_000))
    page.evaluate("() => window.app.ready")
    assert page.inner_text("#latency") == "–" and page.inner_text("#fps") == "–"
    assert page.inner_text("#source-note") == ""
    assert page.inner_text("#play") == "▶ Play" and page.is_disabled("#stop")
    assert page.text_content("#status") == "offline"


def _points_shown(page) -> bool:
    return page.evaluate("() => window.app.picker.markers.group.visible")


def test_points_hide_while_playing_unless_the_user_chooses(server, page):
    _open_sample(server, page)
    assert _points_shown(page) and page.is_checked("#show-points")
    _play_demo(page)
    page.wait_for_function("() => !window.app.picker.markers.group.visible", timeout=scaled_ms(10_000))
    assert not page.is_checked("#show-points")
    page.click("#stop")
    page.wait_for_function("() => window.app.picker.markers.group.visible", timeout=scaled_ms(10_000))
    assert page.is_checked("#show-points")
    # the user's choice holds, playing or not
    page.uncheck("#show-points")
    assert not _points_shown(page)
    _play_demo(page)
    page.click("#stop")
    page.wait_for_function("() => !window.app.streaming", timeout=scaled_ms(10_000))
    assert not _points_shown(page) and not page.is_checked("#show-points")
    page.check("#show-points")
    _play_demo(page)
    page.wait_for_timeout(500)
    assert _points_shown(page)
    page.click("#stop")


def _sample_landmarks(server, sample) -> np.ndarray:
    """(68, 3) the sample project's landmarks at rest, mesh units."""
    arrays = server.read(f"/api/projects/{sample['id']}/mesh/arrays")
    v, f = struct.unpack_from("<II", arrays, 8)
    vertices = np.frombuffer(arrays, "<f4", 3 * v, 16).reshape(v, 3).astype(np.float64)
    faces = np.frombuffer(arrays, "<u4", 3 * f, 16 + 12 * v).reshape(f, 3)
    points = landmarks_from_json(server.api("GET", f"/api/projects/{sample['id']}/landmarks"), vertices, faces)
    return points.positions(vertices)


def test_the_brush_starts_a_third_of_the_eye_distance_wide(server, page):
    sample = _open_sample(server, page)
    page.click("#paint-toggle")
    names = np.array(get_layout("ibug68").point_names)
    points = _sample_landmarks(server, sample)
    eyes = np.linalg.norm(points[np.char.startswith(names, "eye_left")].mean(0)
                          - points[np.char.startswith(names, "eye_right")].mean(0))
    radius = page.evaluate("() => window.app.paint.painter.radius")
    assert abs(radius - eyes / 3) < 1e-4 * eyes, (radius, eyes)
    assert 2 < eyes < 10  # cm: a face's (the old default brush was 1.0 units wide whatever the face)
    assert page.inner_text("#paint-radius-out") == f"{radius:.2g} units"


def test_the_heat_map_has_a_legend_with_the_features_weight_range(server, page):
    sample = _open_sample(server, page)
    assert page.is_hidden("#heat-legend")
    data = server.read(f"/api/projects/{sample['id']}/rig/weights")
    v, k, _ = struct.unpack_from("<III", data, 8)
    start = 20 + 2 * v * k + (2 if (v * k) % 2 else 0)
    indices = np.frombuffer(data, "<u2", v * k, 20).reshape(v, k)
    weights = np.frombuffer(data, "<f4", v * k, start).reshape(v, k)
    joint = get_layout("ibug68").point_names.index("lip_upper_center")
    w = np.where(indices == joint, weights, 0).sum(axis=1)  # (V,) 0 where it has no influence
    assert w.min() < 0  # the default (interpolating) rig has negative weights
    page.select_option("#heatmap-select", str(joint))
    page.wait_for_selector("#heat-legend", state="visible", timeout=scaled_ms(5_000))
    assert float(page.inner_text("#heat-min")) == round(float(w.min()), 3)
    assert float(page.inner_text("#heat-max")) == round(float(w.max()), 3)
    assert "negative weight: the skin moves against the feature point" in page.inner_text("#heat-legend").lower()
    bar = page.evaluate("""() => { const c = document.getElementById('heat-bar');
        const d = c.getContext('2d').getImageData(0, 5, c.width, 1).data; return [Array.from(d.slice(0, 3)), Array.from(d.slice(-4, -1))]; }""")
    assert bar[0][0] > 150 and bar[0][1] < 100  # the lowest weight, negative: red
    assert page.locator("#heat-bar").bounding_box()["width"] > 100
    page.select_option("#heatmap-select", "")
    assert page.is_hidden("#heat-legend")
