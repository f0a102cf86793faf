"""Rough edges of the Performance panel: a file that is not a video says so in words the
user can act on (the server's, which opened it), a take tracked from a video is labelled
with that video, and the Conditioning table has a row for exactly the regions of the
saved layout that have points (no jaw row for dutreve21)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from retarget.layouts import get_layout
from tests.e2e.conftest import open_project, upload_face, write_face_file
from tests.e2e.fake_camera import video_frames
from tests.e2e.test_video_take import write_webm
from tests.waits import scaled_ms

SHARED = Path(__file__).resolve().parents[3] / "shared"
VIDEO = SHARED / "data" / "video" / "face_expressions_480.mp4"
NOT_A_VIDEO = ("is not a video OpenCV can open (unknown format, or a damaged or cut-off file: an "
               "MP4 whose index was never written cannot be read)")


@pytest.fixture(scope="module")
def server(module_server):
    """One server for these tests: the first only fails an upload, the second adds a take to
    the sample project, the third makes a project of its own; none reads what another left."""
    return module_server


def _sample(server) -> str:
    return next(p for p in server.api("GET", "/api/projects") if p["rig"])["id"]


def test_a_text_file_named_mp4_is_not_a_video(server, page, tmp_path):
    path = tmp_path / "notes.mp4"
    path.write_text("not a video at all\n" * 50)
    pid = _sample(server)
    before = server.api("GET", f"/api/projects/{pid}/takes")
    open_project(page, server, pid)
    page.select_option("#video-method", "markerless")
    page.set_input_files("#video-file", str(path))
    page.wait_for_function("() => !document.getElementById('error').hidden", timeout=scaled_ms(60_000))
    shown = page.inner_text("#error-text")
    assert f"'notes.mp4' {NOT_A_VIDEO}" in shown, shown
    assert "scratch" not in shown  # the server's own file name for the upload means nothing here
    page.wait_for_selector("#source-progress", state="hidden", timeout=scaled_ms(30_000))
    assert server.api("GET", f"/api/projects/{pid}/takes") == before


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared (its face video) is absent")
def test_a_take_tracked_from_a_video_is_labelled_with_the_video(server, page, tmp_path):
    path = write_webm(tmp_path / "performer.webm", video_frames(VIDEO, 8, 240), 24)
    pid = _sample(server)
    open_project(page, server, pid)
    page.select_option("#video-method", "markerless")
    page.set_input_files("#video-file", str(path))
    item = page.locator("#take-list li:has-text('performer')")
    item.wait_for(timeout=scaled_ms(120_000))
    assert item.locator(".take-meta").inner_text().startswith("video: performer.webm · ")
    [take] = [t for t in server.api("GET", f"/api/projects/{pid}/takes") if t["name"] == "performer"]
    assert take["source"] == "video: performer.webm"
    page.reload()  # as stored, not only as the page last wrote it
    item.wait_for(timeout=scaled_ms(30_000))
    assert item.locator(".take-meta").inner_text().startswith("video: performer.webm · ")


@pytest.fixture(scope="module")
def face_file(tmp_path_factory):
    return write_face_file(tmp_path_factory.mktemp("meshes"), "regions_face.obj",
                           np.array([0.2, 0.3, -0.5, 0.1, 0.4]))


def _rows(page) -> list[str]:
    return page.eval_on_selector_all("#gain-table tr[data-region]", "rows => rows.map((r) => r.dataset.region)")


def test_the_conditioning_rows_are_the_saved_layouts_regions(server, page, face_file):
    project, face = upload_face(server, page, face_file, "regions")
    page.select_option("#layout-select", "dutreve21")
    layout = get_layout("dutreve21")
    for point in face.vertices[face.landmarks68[list(layout.ibug68)]]:
        xy = page.evaluate("p => window.app.viewer.project(p)", [float(c) for c in point])
        page.mouse.click(xy["x"], xy["y"])
    page.click("#save-landmarks")
    server.wait_for_project(project["id"], lambda p: p["landmarks"] is not None)
    regions = list(dict.fromkeys(layout.regions))  # in point order, each once
    assert "jaw" not in regions
    page.wait_for_function("n => document.querySelectorAll('#gain-table tr[data-region]').length === n",
                           arg=len(regions), timeout=scaled_ms(30_000))
    assert _rows(page) == regions

    # as opened again: the same rows
    open_project(page, server, project["id"])
    page.reload()
    page.wait_for_function("() => window.app.projectId && window.app.face", timeout=scaled_ms(30_000))
    page.evaluate("() => window.app.ready")
    assert _rows(page) == regions
