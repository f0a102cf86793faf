"""The dense layout in the app (issue 14, section 3): on a project with a face, choosing
mediapipe468 in the layout select is the last click: the page finds all 468 points on the
mesh, rigs 468 joints and plays the demo on them; the markers are one instanced draw
(each instance where its point is), and the Live panel's region toggles and the
conditioning rows carry the layout's regions, cheeks and forehead among them, in colour.
"""

from __future__ import annotations

import numpy as np

from retarget.layouts import REGIONS, get_layout
from tests.e2e.conftest import upload_face, wait_face_moves, write_face_file
from tests.waits import scaled_ms

# the markers' instances in the face's model space: (N, 3) centres, per instance its scale
_INSTANCES = """() => {
    const markers = window.app.picker.markers, points = markers.points;
    const m = new points.matrixWorld.constructor(), out = [];
    for (let i = 0; i < points.count; i ++) {
        points.getMatrixAt(i, m);
        const e = m.elements;
        out.push([e[12], e[13], e[14], Math.hypot(e[0], e[1], e[2])]);
    }
    return {isInstanced: points.isInstancedMesh, count: points.count, instances: out,
            halos: markers.halos.count};
}"""


def test_choosing_the_dense_layout_finds_rigs_and_plays_468_points(server, page, tmp_path):
    project, face = upload_face(server, page, write_face_file(tmp_path, "scan.obj", None), "dense")
    pid = project["id"]
    short = get_layout("dutreve22")  # a new project's layout: found, rigged, played first
    page.wait_for_function("n => window.app.face.nJoints === n && window.app.streaming", arg=short.n_points,
                           timeout=scaled_ms(120_000))

    dense = get_layout("mediapipe468")
    page.select_option("#layout-select", dense.name)
    # no click from here on: found, rigged with 468 joints, the demo moving the face
    page.wait_for_function("n => window.app.face.nJoints === n && window.app.streaming"
                           " && window.app.project.rig", arg=dense.n_points, timeout=scaled_ms(180_000))
    wait_face_moves(page, 0.1)
    assert page.inner_text("#error").strip() == ""
    assert server.api("GET", f"/api/projects/{pid}")["landmarks"] == {"layout": dense.name, "n_points": dense.n_points}
    stored = server.api("GET", f"/api/projects/{pid}/landmarks")
    assert len(stored["triangles"]) == dense.n_points
    assert page.inner_text("#landmark-count") == f"{dense.n_points} / {dense.n_points}"
    assert not page.is_visible("#unsaved")

    # the regions: a toggle and a conditioning row each, cheeks and forehead among them, coloured
    toggles = page.eval_on_selector_all("#regions input[data-region]", "boxes => boxes.map((b) => b.dataset.region)")
    assert toggles == [r for r in REGIONS if r in dense.regions]
    assert {"cheeks", "forehead"} <= set(toggles)
    rows = page.eval_on_selector_all("#gain-table tr[data-region]", "rows => rows.map((r) => r.dataset.region)")
    assert set(rows) == set(toggles)
    colours = page.evaluate("""() => Object.fromEntries(['regions', 'gain-table'].flatMap((id) =>
        [...document.querySelectorAll(`#${id} [data-region]`)].map((el) => {
            const swatch = (el.closest('label') || el).querySelector('.swatch');
            return [`${id}:${el.dataset.region}`, getComputedStyle(swatch).backgroundColor];
        })))""")
    assert colours["regions:cheeks"] == colours["gain-table:cheeks"]
    assert colours["regions:forehead"] == colours["gain-table:forehead"]
    assert len({colours[f"regions:{r}"] for r in toggles}) == len(toggles)  # one colour a region

    # the markers, stopped: one instanced draw of 468 spheres, each on its point
    page.click("#stop")
    page.wait_for_function("() => !window.app.streaming && window.app.picker.markers.group.visible")
    page.wait_for_function("() => window.app.face.deformedPositions().every((v, i) =>"
                           " v === window.app.face.mesh.geometry.attributes.position.array[i])",
                           polling=200, timeout=scaled_ms(10_000))
    shown = page.evaluate(_INSTANCES)
    assert shown["isInstanced"] and shown["count"] == dense.n_points
    triangles, barycentric = np.array(stored["triangles"]), np.array(stored["barycentric"])
    where = np.einsum("nk,nkj->nj", barycentric, face.vertices[triangles])
    instances = np.array(shown["instances"])
    size = np.ptp(face.vertices, axis=0).max()
    assert np.abs(instances[:, :3] - where).max() < 1e-4 * size
    assert (instances[:, 3] > 0).all()
    flagged = np.flatnonzero(np.array(stored["confidence"]) < stored["check_below"])
    assert shown["halos"] == len(flagged)
    calls = page.evaluate("""() => { const v = window.app.viewer; v.render(); return v.renderer.info.render.calls; }""")
    assert calls <= 4  # the face, the spheres, the halos (not one per point)
