"""Weight painting: what a stroke costs in the page and on the server, on the sample project
(8,430 vertices, dense 68-joint biharmonic rig: every row has 68 influences).

    python bench/painting.py [--repeats 20] [--radius 0.6 1.5]

Runs `retarget serve` (subprocess, temp data dir, free port) and Debian's Chromium through
Playwright (headless, WebGL2 through SwiftShader), opens the app in painting mode and, for
each brush radius (cm):

    dab        one pointermove of a stroke, in the page: the surface pick, the brush over
               the vertices it reaches (add; with mirroring: two dabs), the rows written
               to the face's weight texture (timed around the synchronous event dispatch)
    draw       the next `viewer.render()`: the changed texture rows uploaded, the skinning,
               normal and display passes (SwiftShader: a CPU rasteriser, so this is the
               software renderer's cost, not a GPU's)
    save       PATCH .../rig/weights with one stroke's rows (binary), client wall clock:
               validation against the automatic rig (kept in memory), merge, the painted
               rows written atomically (compressed .npz), the index updated
    reset      POST .../rig/reset for the painted feature, and for the whole rig

Prints medians over --repeats (dab: over every move of every stroke) and the rows a stroke
touched.
"""

from __future__ import annotations

import argparse
import json
import struct
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.stream import ServerProcess, machine, sample_project  # noqa: E402

CHROMIUM = "/usr/bin/chromium"
SWIFTSHADER = ["--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--ignore-gpu-blocklist"]
JOINT = 48  # right mouth corner: a stroke across the cheek

_STROKE = """async ([x0, y0, x1, y1, moves]) => {
    const canvas = window.app.viewer.renderer.domElement;
    const at = (type, t) => new PointerEvent(type, {bubbles: true, button: 0, buttons: 1, pointerId: 1,
        pointerType: 'mouse', clientX: x0 + t * (x1 - x0), clientY: y0 + t * (y1 - y0)});
    const dabs = [], draws = [], pixel = new Uint8Array(4);
    const painter = window.app.paint.painter, rig = painter.rig;
    let rows = 0;  // the rows of the stroke's undo step, as the painter records it
    const record = rig.record;
    rig.record = (step) => { rows = step.vertices.length; return record.call(rig, step); };
    canvas.dispatchEvent(at('pointerdown', 0));
    for (let i = 1; i <= moves; i ++) {
        let t = performance.now();
        canvas.dispatchEvent(at('pointermove', i / moves));
        dabs.push(performance.now() - t);
        t = performance.now();
        window.app.viewer.render();
        const gl = window.app.viewer.renderer.getContext();
        gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel);  // waits for the draw
        draws.push(performance.now() - t);
    }
    canvas.dispatchEvent(at('pointerup', 1));
    rig.record = record;
    await painter.flush();
    return {dabs, draws, rows};
}"""


def post(url: str, body: bytes, content_type: str, method: str = "POST") -> dict:
    request = urllib.request.Request(url, data=body, method=method, headers={"Content-Type": content_type})
    with urllib.request.urlopen(request, timeout=120) as reply:
        return json.loads(reply.read())


def stroke_body(server, pid: str, version: int, rows: list[int]) -> bytes:
    """A weight edit raising JOINT to 0.9 at `rows` of the stored rig (the painting rule)."""
    from retarget.skin import SkinWeights
    from retarget.weights.painting import automatic_rows, with_weight

    data = urllib.request.urlopen(f"{server.url}/api/projects/{pid}/rig/weights").read()
    _, _, v, k, n = struct.unpack_from("<4sIIII", data)
    idx = np.frombuffer(data, "<u2", v * k, 20).reshape(v, k)
    w = np.frombuffer(data, "<f4", v * k, 20 + 2 * v * k + (2 * v * k) % 4).reshape(v, k)
    painted = with_weight(automatic_rows(SkinWeights(idx, w, n), rows), JOINT, 0.9)
    index_bytes = np.broadcast_to(np.arange(n, dtype="<u2"), painted.shape).tobytes()
    return (struct.pack("<4sIIIII", b"RTSE", 1, len(rows), n, n, version)
            + np.asarray(rows, "<u4").tobytes() + index_bytes + b"\0" * (len(index_bytes) % 4)
            + painted.astype("<f4").tobytes())


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=20, help="strokes per radius")
    p.add_argument("--radius", type=float, nargs="+", default=[0.6, 1.5], help="brush radii, cm")
    args = p.parse_args(argv)

    from playwright.sync_api import sync_playwright

    print(machine())
    with ServerProcess() as server, sync_playwright() as pw:
        pid = sample_project(server.url)
        landmarks = json.loads(urllib.request.urlopen(f"{server.url}/api/projects/{pid}/landmarks").read())
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=SWIFTSHADER)
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        page.goto(f"{server.url}/#p={pid}")
        page.wait_for_function("() => window.app && window.app.face && window.app.face.nJoints === 68", timeout=60_000)
        page.evaluate("() => window.app.ready")
        page.click("#paint-toggle")
        page.select_option("#paint-joint", str(JOINT))
        start = page.evaluate("i => window.app.viewer.project(window.app.picker.worldPosition(i))", JOINT)
        x0, y0 = start["x"], start["y"]
        try:
            for radius in args.radius:
                for mirror in (False, True):
                    page.evaluate(f"() => window.app.paint.painter.configure({{radius: {radius}, strength: 0.2, mirror: {str(mirror).lower()}}})")
                    dabs, draws, rows = [], [], []
                    for r in range(args.repeats):
                        print(f"  radius {radius} cm, mirror {mirror}: stroke {r + 1}/{args.repeats}", file=sys.stderr, flush=True)
                        result = page.evaluate(_STROKE, [x0, y0, x0 + 60, y0 - 40, 12])
                        dabs += result["dabs"][1:]  # the first move after pointerdown may be below the spacing
                        draws += result["draws"]
                        rows.append(result["rows"])
                    print(f"\nradius {radius} cm{' mirrored' if mirror else ''}: a stroke touches "
                          f"{int(np.median(rows))} rows (median)")
                    print(f"  dab (pick + brush + rows to the texture): median {np.median(dabs):.2f} ms, "
                          f"p90 {np.percentile(dabs, 90):.2f} ms over {len(dabs)} moves")
                    print(f"  draw after a dab (SwiftShader): median {np.median(draws):.1f} ms")

            info = json.loads(urllib.request.urlopen(f"{server.url}/api/projects/{pid}/rig").read())
            url = f"{server.url}/api/projects/{pid}"
            vertex = np.array(landmarks["vertex_indices"][JOINT])
            arrays = urllib.request.urlopen(f"{url}/mesh/arrays").read()
            n = struct.unpack_from("<I", arrays, 8)[0]
            rest = np.frombuffer(arrays, "<f4", 3 * n, 16).reshape(-1, 3)
            for radius in args.radius:
                rows = np.flatnonzero(np.linalg.norm(rest - rest[vertex], axis=1) < radius).tolist()
                saves, resets, reset_alls = [], [], []
                for _ in range(args.repeats):
                    for times, joints in ((resets, [JOINT]), (reset_alls, None)):
                        body = stroke_body(server, pid, info["version"], rows)
                        t = time.perf_counter()
                        info = post(f"{url}/rig/weights", body, "application/octet-stream", "PATCH")
                        saves.append(time.perf_counter() - t)
                        t = time.perf_counter()
                        info = post(f"{url}/rig/reset", json.dumps({"joints": joints}).encode(), "application/json")
                        times.append(time.perf_counter() - t)
                print(f"\nstroke of {len(rows)} rows (radius {radius} cm) on the server:")
                print(f"  save: median {1e3 * np.median(saves):.1f} ms; reset the feature: "
                      f"{1e3 * np.median(resets):.1f} ms; reset the whole rig: {1e3 * np.median(reset_alls):.1f} ms")
        finally:
            browser.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
