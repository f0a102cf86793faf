"""The cost of drawing the landmark markers in the web app: frame time with 68 and 468 points.

    python bench/landmark_markers.py [--frames 40] [--gpu]

The sample face is uploaded through the page's file chooser of a new project whose layout
is ibug68, then of one whose layout is mediapipe468 (headless Chromium, SwiftShader
unless --gpu, a real `retarget serve`); the page finds the points with no click, rigs the
face and plays the demo, which is stopped. Then the viewer renders `--frames` frames back
to back, each waited for (a one-pixel readPixels), with the markers shown and hidden:

    shown    ms per frame, the face and its markers (and red halos of points to check)
    hidden   ms per frame, the face alone
    markers  shown - hidden: what the markers cost
    calls    WebGL draw calls of one frame with the markers shown
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.stream import http_json, machine  # noqa: E402
from bench.zero_click import TIMEOUT_MS, server_and_chromium  # noqa: E402
from retarget.mesh import mesh_from_arrays, save_mesh  # noqa: E402
from retarget.sample_face import sample_face  # noqa: E402

_FRAME_MS = """([frames, shown]) => {
    const app = window.app, viewer = app.viewer, gl = viewer.renderer.getContext();
    app.picker.markers.setShown(shown);
    const pixel = new Uint8Array(4);
    const frame = () => { viewer.render(); gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel); };
    for (let i = 0; i < 3; i ++) frame();
    const t0 = performance.now();
    for (let i = 0; i < frames; i ++) frame();
    const ms = (performance.now() - t0) / frames;
    return {ms, calls: viewer.renderer.info.render.calls};
}"""


def one_layout(browser, url: str, obj: Path, layout: str, frames: int) -> dict:
    project = http_json(f"{url}/api/projects", "POST", {"name": f"markers {layout}"})
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    try:
        page.goto(f"{url}/#p={project['id']}")
        page.wait_for_function("() => window.app && window.app.projectId")
        page.evaluate("() => window.app.ready")
        page.select_option("#layout-select", layout)
        page.set_input_files("#file-input", str(obj))
        page.wait_for_function("n => window.app.face && window.app.face.nJoints === n && window.app.streaming",
                               arg=http_json(f"{url}/api/layouts/{layout}")["n_points"], timeout=TIMEOUT_MS)
        page.click("#stop")
        page.wait_for_function("() => !window.app.streaming && window.app.picker.markers.group.visible")
        shown = page.evaluate(_FRAME_MS, [frames, True])
        hidden = page.evaluate(_FRAME_MS, [frames, False])
        flagged = page.evaluate("() => window.app.landmarks.flagged.filter(Boolean).length")
    finally:
        page.close()
    return {"shown": shown["ms"], "hidden": hidden["ms"], "calls": shown["calls"], "flagged": flagged}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--frames", type=int, default=40)
    p.add_argument("--gpu", action="store_true", help="let Chromium use the machine's GPU")
    args = p.parse_args(argv)

    print(machine())
    with server_and_chromium(args.gpu) as (tmp, server, browser):
        face = sample_face(1)
        obj = tmp / "sample_face.obj"
        save_mesh(mesh_from_arrays(face.vertices, face.faces), obj)
        print(f"sample face, 1280 x 800 page, {'GPU' if args.gpu else 'SwiftShader'}, {args.frames} frames:")
        for layout in ("ibug68", "mediapipe468"):
            r = one_layout(browser, server.url, obj, layout, args.frames)
            print(f"  {layout:13s} shown {r['shown']:6.1f} ms  hidden {r['hidden']:6.1f} ms  "
                  f"markers {r['shown'] - r['hidden']:6.1f} ms  calls {r['calls']}  ({r['flagged']} to check)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
