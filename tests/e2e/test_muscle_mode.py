"""Muscle mode in the page (issue 15): *Drive by: muscles* while the demo plays, the face
drawn from the played muscles in the shader exactly as `played_displacements` of the
contractions received, the live expression readout, a Muscles panel slider posing the
face with no server round trip, a muscle's insertion dragged on the view, saved and
played anew, and the export following the drive."""

from __future__ import annotations

import json
import struct

import numpy as np

from retarget.muscles import MuscleFace
from retarget.muscles.expressions import EXPRESSIONS
from retarget.muscles.morphs import muscle_morphs, played_displacements
from tests.e2e.conftest import open_project
from tests.waits import scaled_ms

TOLERANCE = 1e-4  # of the mesh's bounding-box diagonal: float32 on the GPU against float64

# the contractions on the face and its vertices as drawn, read together once it has moved
# more than `cm` somewhere (the demo passes through rest)
_MOVED_POSE = """(cm) => {
    const face = window.app.face, rest = face.mesh.geometry.attributes.position.array;
    const c = window.app.live.lastContractions, v = face.deformedPositions();
    let most = 0;
    for (let i = 0; i < rest.length; i ++) most = Math.max(most, Math.abs(v[i] - rest[i]));
    return c !== null && most > cm ? {c: Array.from(c), v: Array.from(v)} : null;
}"""
_SLIDERS = """() => ({c: Array.from(document.querySelectorAll('#muscle-sliders input'), (e) => Number(e.value)),
                     v: Array.from(window.app.face.deformedPositions())})"""


def test_drive_by_muscles_plays_the_contractions_and_reads_the_expression(server, page):
    sample = next(p for p in server.api("GET", "/api/projects") if p["rig"])
    open_project(page, server, sample["id"])
    page.wait_for_function("() => window.app.face && window.app.face.nJoints === 68", timeout=scaled_ms(30_000))
    page.click("#play")
    page.wait_for_function("() => window.app.stream.stats.frames > 5", timeout=scaled_ms(30_000))

    page.check("#drive-muscles")
    pose = page.wait_for_function(_MOVED_POSE, arg=0.05, polling=200, timeout=scaled_ms(30_000)).json_value()

    arrays = server.read(f"/api/projects/{sample['id']}/mesh/arrays")
    n = int(np.frombuffer(arrays, "<u4", 1, 8)[0])
    rest = np.frombuffer(arrays, "<f4", 3 * n, 16).reshape(n, 3).astype(np.float64)
    model = MuscleFace.from_json(server.api("GET", f"/api/projects/{sample['id']}/muscles"), rest)
    morphs = muscle_morphs(model)
    diagonal = float(np.linalg.norm(rest.max(0) - rest.min(0)))

    c = np.array(pose["c"])
    assert c.shape == (22,) and np.abs(c).max() > 1e-3
    drawn = np.array(pose["v"]).reshape(n, 3) - rest
    expected = played_displacements(morphs, rest, c)
    assert np.abs(expected).max() > 0.05
    assert np.abs(drawn - expected).max() < TOLERANCE * diagonal

    page.wait_for_function("names => names.includes(document.getElementById('expression-label').textContent)",
                           arg=list(EXPRESSIONS), timeout=scaled_ms(10_000))
    assert page.is_visible("#expression-chart")
    assert page.inner_text("#expression-confidence").endswith("%")

    # stopped, the face rests; a slider then poses it in the shader alone
    page.click("#stop")
    page.wait_for_function("""(n) => { const v = window.app.face.deformedPositions(),
        r = window.app.face.mesh.geometry.attributes.position.array;
        for (let i = 0; i < 3 * n; i ++) if (Math.abs(v[i] - r[i]) > 1e-6) return false; return true; }""",
                           arg=n, polling=200, timeout=scaled_ms(10_000))
    page.click("#muscle-dofs summary")
    page.wait_for_selector("#muscle-sliders input[data-dof='jaw']")
    page.click("#muscles-reset")  # the sliders followed the last frame played
    page.evaluate("""() => { const s = document.querySelector("#muscle-sliders input[data-dof='jaw']");
        s.value = 0.3; s.dispatchEvent(new Event('input')); }""")
    pose = page.evaluate(_SLIDERS)
    opened = np.array(pose["c"])
    assert opened[-1] > 0.29 and not opened[:-1].any()
    drawn = np.array(pose["v"]).reshape(n, 3) - rest
    expected = played_displacements(morphs, rest, opened)
    assert np.abs(expected).max() > 0.3
    assert np.abs(drawn - expected).max() < TOLERANCE * diagonal

    # dragging the zygomatic's insertion saves the muscles as the user's and plays them anew
    page.select_option("#muscle-edit", "zygomatic_major_left")
    page.wait_for_function("() => window.app.muscles.editor.handles !== null", timeout=scaled_ms(10_000))
    at = page.evaluate("""() => { const h = window.app.muscles.editor.handles.handles.get('insertion');
        window.playedBefore = window.app.face.muscles;
        return window.app.viewer.project(h.getWorldPosition(h.position.clone()).toArray()); }""")
    page.mouse.move(at["x"], at["y"])
    page.mouse.down()
    page.mouse.move(at["x"] + 30, at["y"] + 20, steps=4)
    page.mouse.up()
    page.wait_for_function("() => window.app.face.muscles !== window.playedBefore", timeout=scaled_ms(15_000))
    saved = server.api("GET", f"/api/projects/{sample['id']}/muscles")
    moved = next(m for m in saved["muscles"] if m["name"] == "zygomatic_major_left")
    placed = next(m for m in model.to_json()["muscles"] if m["name"] == "zygomatic_major_left")
    assert saved["edited"] is True and np.linalg.norm(np.subtract(moved["insertion"], placed["insertion"])) > 0.1
    assert moved["origin"] == placed["origin"]
    pose = page.evaluate(_SLIDERS)
    edited = muscle_morphs(MuscleFace.from_json(saved, rest))
    drawn = np.array(pose["v"]).reshape(n, 3) - rest
    assert np.abs(drawn - played_displacements(edited, rest, np.array(pose["c"]))).max() < TOLERANCE * diagonal

    # the export follows the drive: a morph target per muscle (and corrective), named after it
    with page.expect_download() as download:
        page.click("#export-gltf")
    glb = open(download.value.path(), "rb").read()
    length, = struct.unpack_from("<I", glb, 12)
    names = json.loads(glb[20:20 + length])["meshes"][0]["extras"]["targetNames"]
    assert names[:21] == list(model.names[:-1]) and "orbicularis_oris*jaw" in names
