"""Weight painting in a real browser on the sample project (biharmonic rig, every vertex
weighted by all 68 joints, negative weights included): paint a feature with the mouse,
check the server's rows against the brush and the automatic rig, the drawn deformation
against the stored weights, undo and redo, mirrored painting while the demo plays, a
reload, resetting a feature and the whole rig, a refused save, and painted rows reaching
the GPU on the vertex-attribute path of sparse rigs too."""

from __future__ import annotations

import base64
import struct

import numpy as np

from retarget.layouts import get_layout
from tests.e2e.conftest import open_project
from tests.waits import scaled_ms

STRENGTH = 1.0
RADIUS = 0.6  # cm: the sample face is about 15 cm wide
MIRROR = get_layout("ibug68").mirror


def server_weights(server, pid) -> np.ndarray:
    """(V, N) float64 dense weights the server stores."""
    data = server.read(f"/api/projects/{pid}/rig/weights")
    _, _, v, k, n = struct.unpack_from("<4sIIII", data)
    idx = np.frombuffer(data, "<u2", v * k, 20).reshape(v, k)
    w = np.frombuffer(data, "<f4", v * k, 20 + 2 * v * k + (2 * v * k) % 4).reshape(v, k)
    dense = np.zeros((v, n))
    np.add.at(dense, (np.arange(v)[:, None], idx), w)
    return dense


def page_weights(page) -> np.ndarray:
    """(V, N) float64 dense weights the painter holds (its arrays' bytes, base64)."""
    rig = page.evaluate("""() => {
        const r = window.app.paint.painter.rig;
        const b64 = (a) => { const u = new Uint8Array(a.buffer, a.byteOffset, a.byteLength); let s = '';
            for (let i = 0; i < u.length; i += 0x8000) s += String.fromCharCode.apply(null, u.subarray(i, i + 0x8000));
            return btoa(s); };
        return {k: r.nInfluences, n: r.nJoints, idx: b64(r.indices), w: b64(r.weights)}; }""")
    idx = np.frombuffer(base64.b64decode(rig["idx"]), "<u2").reshape(-1, rig["k"])
    w = np.frombuffer(base64.b64decode(rig["w"]), "<f4").reshape(idx.shape)
    dense = np.zeros((len(idx), rig["n"]))
    np.add.at(dense, (np.arange(len(idx))[:, None], idx), w)
    return dense


def drawn_column(page, joint: int, rest: np.ndarray) -> np.ndarray:
    """(V,) how far each vertex moves, as drawn, when only `joint` moves 1 unit along z:
    its weight as the GPU skins it."""
    z = page.evaluate("""j => { const face = window.app.face, d = new Float32Array(3 * face.nJoints);
        d[3 * j + 2] = 1; face.setDisplacements(d);
        const p = face.deformedPositions(); face.setDisplacements(null);
        return Array.from(p.filter((_, i) => i % 3 === 2)); }""", joint)
    return np.array(z) - rest[:, 2]


def screen(page, point) -> tuple[float, float]:
    xy = page.evaluate("p => window.app.viewer.project(p)", [float(c) for c in point])
    return xy["x"], xy["y"]


def stroke(page, points) -> None:
    """A mouse drag over the surface points (rest pose, world = mesh frame at rest)."""
    xy = [screen(page, p) for p in points]
    page.mouse.move(*xy[0])
    page.mouse.down()
    for (x0, y0), (x1, y1) in zip(xy, xy[1:]):
        for t in np.linspace(0.25, 1.0, 4):
            page.mouse.move(x0 + t * (x1 - x0), y0 + t * (y1 - y0))
    page.mouse.up()


def wait_saved(page, version: int) -> None:
    page.wait_for_function("v => window.app.paint.painter.saveState === 'saved' && "
                           "window.app.paint.painter.rig.version === v", arg=version, timeout=scaled_ms(20_000))
    assert page.get_attribute("#paint-note", "data-state") == "saved"


def set_range(page, selector: str, value: float) -> None:
    page.eval_on_selector(selector, "(e, v) => { e.value = String(v); e.dispatchEvent(new Event('input')); }", value)


def distance_to_segment(points, a, b) -> np.ndarray:
    t = np.clip((points - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
    return np.linalg.norm(points - (a + t[:, None] * (b - a)), axis=1)


def test_paint_undo_mirror_reload_reset_and_a_refused_save(server, page):
    sample = next(p for p in server.api("GET", "/api/projects") if p["rig"])
    pid = sample["id"]
    arrays = server.read(f"/api/projects/{pid}/mesh/arrays")
    n_vertices = struct.unpack_from("<I", arrays, 8)[0]
    rest = np.frombuffer(arrays, "<f4", 3 * n_vertices, 16).reshape(-1, 3).astype(np.float64)
    landmarks = rest[server.api("GET", f"/api/projects/{pid}/landmarks")["vertex_indices"]]
    automatic = server_weights(server, pid)
    version = server.api("GET", f"/api/projects/{pid}/rig")["version"]

    open_project(page, server, pid)
    page.wait_for_function("() => window.app.face && window.app.face.nJoints === 68", timeout=scaled_ms(30_000))
    assert page.is_hidden("#paint-panel")
    page.click("#paint-toggle")
    page.select_option("#paint-joint", "30")  # nose tip
    assert page.is_visible("#paint-panel") and page.input_value("#heatmap-select") == "30"
    set_range(page, "#paint-strength", STRENGTH)
    # the radius slider is logarithmic from 0.005 to 0.5 bounding-sphere radii
    bounds = page.evaluate("() => window.app.face.mesh.geometry.boundingSphere.radius")
    set_range(page, "#paint-radius", round(1000 * np.log(RADIUS / (0.005 * bounds)) / np.log(100)))
    radius = page.evaluate("() => window.app.paint.painter.radius")
    assert abs(radius - RADIUS) < 0.01 and page.inner_text("#paint-radius-out") == "0.60 units"

    # one add stroke down the nose: the server's rows change under the brush only
    tip, base = landmarks[30], landmarks[33]
    stroke(page, [tip, (tip + base) / 2, base])
    wait_saved(page, version + 1)
    painted = server_weights(server, pid)
    near = distance_to_segment(rest, tip, base)
    changed = np.abs(painted - automatic).max(1) > 1e-6
    assert changed.sum() > 20 and not changed[near > radius + 0.05].any()
    core = np.linalg.norm(rest - tip, axis=1) < 0.5 * radius
    gain = STRENGTH * (1 - 0.25) ** 2  # the falloff half way out
    assert np.all(painted[core, 30] >= np.minimum(1, automatic[core, 30] + gain) - 1e-3)
    rows = changed
    assert np.all(painted[rows] >= np.minimum(automatic[rows].min(1, keepdims=True), 0) - 1e-5)
    assert np.all(painted[rows].sum(1) <= np.maximum(automatic[rows].sum(1), 1) + 1e-4)
    np.testing.assert_allclose(page_weights(page), painted, atol=1e-7)
    assert "differ from the automatic rig" in page.inner_text("#paint-note")
    # the face is drawn with the painted weights: moving the joint moves the skin by them
    drawn = drawn_column(page, 30, rest)
    np.testing.assert_allclose(drawn, painted[:, 30], atol=1e-4)
    assert np.abs(drawn - automatic[:, 30]).max() > 0.2

    # undo and redo, each saved
    page.keyboard.press("Control+z")
    wait_saved(page, version + 2)
    np.testing.assert_array_equal(server_weights(server, pid), automatic)
    page.keyboard.press("Control+Shift+z")
    wait_saved(page, version + 3)
    np.testing.assert_allclose(server_weights(server, pid), painted, atol=1e-7)

    # mirrored subtract on the right eye's inner corner while the demo plays
    page.click("#play")
    page.wait_for_function("() => window.app.stream.stats.frames > 5", timeout=scaled_ms(30_000))
    corner = landmarks[39]
    page.keyboard.down("Control")  # Ctrl+click picks the feature point nearest the click
    page.mouse.click(*screen(page, corner + [0.05, 0.0, 0.0]))
    page.keyboard.up("Control")
    assert page.input_value("#paint-joint") == "39" and page.input_value("#heatmap-select") == "39"
    page.check("input[name='paint-brush'][value='subtract']")
    page.check("#paint-mirror")
    stroke(page, [corner, corner + [0.0, 0.05, 0.0]])
    wait_saved(page, version + 4)
    frames = page.evaluate("() => window.app.stream.stats.frames")
    page.wait_for_function("n => window.app.stream.stats.frames > n + 5", arg=frames, timeout=scaled_ms(20_000))
    mirrored = server_weights(server, pid)
    for joint, point in ((39, corner), (MIRROR[39], landmarks[MIRROR[39]])):
        close = np.linalg.norm(rest - point, axis=1) < 0.3 * radius
        assert close.any() and np.all(mirrored[close, joint] <= automatic[close, joint] - 0.3), joint
    page.click("#stop")

    # a reload shows the painted rig
    page.reload()
    page.wait_for_function("() => window.app.face && window.app.face.nJoints === 68", timeout=scaled_ms(30_000))
    page.evaluate("() => window.app.ready")
    assert "painted" in page.inner_text("#paint-state")
    np.testing.assert_allclose(drawn_column(page, 39, rest), mirrored[:, 39], atol=1e-4)

    # reset the nose tip: its stroke is undone exactly; the eyes stay painted
    page.click("#paint-toggle")
    assert page.inner_text("#paint-strength-out") == "1.00" and page.is_checked("#paint-mirror")  # brush kept
    page.uncheck("#paint-mirror")
    page.select_option("#paint-joint", "30")
    page.click("#paint-reset-joint")
    wait_saved(page, version + 5)
    reset = server_weights(server, pid)
    np.testing.assert_allclose(reset[:, 30], automatic[:, 30], atol=1e-6)
    eyes = np.abs(mirrored - painted).max(1) > 1e-6
    np.testing.assert_allclose(reset[~eyes], automatic[~eyes], atol=1e-6)
    assert np.abs(reset[eyes] - automatic[eyes]).max() > 0.3
    page.click("#paint-reset-all")
    wait_saved(page, version + 6)
    np.testing.assert_array_equal(server_weights(server, pid), automatic)
    assert page.inner_text("#paint-note") == "Saved · the automatic rig." and page.inner_text("#paint-state") == ""

    # set the chin to a quarter; smooth the nose tip's peak
    page.select_option("#paint-joint", "8")
    page.check("input[name='paint-brush'][value='set']")
    set_range(page, "#paint-value", 0.25)
    chin = landmarks[8]
    stroke(page, [chin, chin + [0.02, 0.0, 0.0]])
    wait_saved(page, version + 7)
    page.select_option("#paint-joint", "30")
    page.check("input[name='paint-brush'][value='smooth']")
    stroke(page, [tip, tip + [0.0, -0.05, 0.0], tip])
    wait_saved(page, version + 8)
    brushed = server_weights(server, pid)
    chin_vertex, tip_vertex = np.argmin(np.linalg.norm(rest - chin, axis=1)), np.argmin(np.linalg.norm(rest - tip, axis=1))
    assert abs(brushed[chin_vertex, 8] - 0.25) < 0.02 and automatic[chin_vertex, 8] > 0.9
    assert brushed[tip_vertex, 30] < automatic[tip_vertex, 30] - 0.05  # a peak smoothed down

    # a save the server refuses (the rig changed behind the page's back) says why and keeps the stroke
    server.api("POST", f"/api/projects/{pid}/rig/reset", {"joints": None})
    page.check("input[name='paint-brush'][value='add']")
    stroke(page, [tip, base])
    page.wait_for_function("() => window.app.paint.painter.saveState === 'failed'", timeout=scaled_ms(20_000))
    note = page.inner_text("#paint-note")
    assert f"the rig changed (now version {version + 9}) since version {version + 8}" in note
    assert page.is_visible("#paint-retry")
    assert np.abs(page_weights(page) - automatic).max() > 0.2  # the local stroke is kept
    np.testing.assert_array_equal(server_weights(server, pid), automatic)

    # partial uploads on both paths: vertex attributes (k <= 8) and the weight texture
    # (k = 12), where vertex 240's 17 texels straddle the texture's first row end (4096):
    # joint 66 is in its last texel, on the second row
    for k in (4, 12):
        moved = page.evaluate("""k => {
            const face = window.app.face, v = face.nVertices;
            const indices = new Uint16Array(v * k), weights = new Float32Array(v * k);
            for (let i = 0; i < v; i ++) {
                indices[i * k] = i % 68; weights[i * k] = 0.5;
                indices[i * k + 1] = (i + 1) % 68; weights[i * k + 1] = 0.25;
            }
            face.setRig({nJoints: 68, nInfluences: k, indices, weights});
            window.app.viewer.render();  // uploaded whole; the update below goes as ranges
            const rows = [240, 5000, 5001, 8429];
            for (const r of rows) {
                indices.fill(0, r * k, r * k + k); weights.fill(0, r * k, r * k + k);
                indices[r * k + 2] = 66; weights[r * k + 2] = 1;
            }
            face.updateWeights(rows, indices, weights);
            const d = new Float32Array(3 * 68); d[3 * 66 + 2] = 1; face.setDisplacements(d);
            return Array.from(face.deformedPositions().filter((_, i) => i % 3 === 2)); }""", k)
        vertex = np.arange(n_vertices)
        expected = 0.5 * (vertex % 68 == 66) + 0.25 * ((vertex + 1) % 68 == 66)
        expected[[240, 5000, 5001, 8429]] = 1.0
        np.testing.assert_allclose(np.array(moved) - rest[:, 2], expected, atol=1e-5, err_msg=f"k = {k}")
