"""End-to-end latency on loopback: a frame leaving the source to its displacements applied
in the page, in the real app in a real browser.

    python bench/latency.py [--seconds 20] [--fps 60] [--repeats 3]

Runs `retarget serve` (subprocess, temp data dir, free port) and Debian's Chromium
through Playwright (headless; WebGL2 through SwiftShader unless --gpu), opens the app
on the built-in sample project (8,430 vertices, dense 68-joint biharmonic rig), presses
*Play* (the built-in demo source) and records, for every frame the page receives, in the page:

    applied  = when the app's frame handler has put the displacements in the skinning
               texture (what the app's own latency readout shows)
    painted  = the next animation frame after that, when the skinned face is drawn

each minus the frame's publish timestamp (the server's wall clock when the source
encoded it, header bytes 24..32); both clocks are this machine's. Also prints the
frames received per second and the page's own frame rate.

Headless Chromium draws with SwiftShader, a CPU rasteriser: every draw of the face costs
the page's main thread tens of milliseconds, which delays the handling of the next
frames. The `painted` figure and the p99 of `applied` therefore measure the software
renderer as much as the stream; a second series with the viewport hidden (nothing to
draw) shows the stream's own part.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.stream import ServerProcess, fmt, machine, sample_project, stats  # noqa: E402

CHROMIUM = "/usr/bin/chromium"
SWIFTSHADER = ["--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--ignore-gpu-blocklist"]

_RECORDER = """() => {
    window.benchLatency = { applied: [], painted: [], rafs: 0 };
    const clock = () => performance.timeOrigin + performance.now();
    // registered after the app's own handler, so it runs once the frame is applied
    window.app.stream.addEventListener('frame', (event) => {
        const sent = event.detail.sendTime * 1000;
        window.benchLatency.applied.push(clock() - sent);
        requestAnimationFrame(() => window.benchLatency.painted.push(clock() - sent));
    });
    const tick = () => { window.benchLatency.rafs++; requestAnimationFrame(tick); };
    requestAnimationFrame(tick);
}"""


def one_run(browser, url: str, project_id: str, seconds: float, fps: float, draw: bool) -> dict:
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    try:
        page.goto(f"{url}/#p={project_id}")
        page.wait_for_function("() => window.app && window.app.projectId")
        page.evaluate("() => window.app.ready")
        page.wait_for_function("() => window.app.face && window.app.face.nJoints > 0", timeout=60_000)
        if not draw:
            page.evaluate("() => { document.querySelector('#viewport').style.display = 'none'; }")
        page.wait_for_function("() => window.app.stream && window.app.stream.state === 'open'",
                               timeout=30_000)
        page.evaluate(f"() => window.app.stream.send({{type: 'start', source: 'demo', fps: {fps}}})")
        page.wait_for_function("() => window.app.stream.stats.frames > 10", timeout=30_000)
        page.evaluate(_RECORDER)
        t0 = time.perf_counter()
        time.sleep(seconds)
        result = page.evaluate("() => window.benchLatency")
        elapsed = time.perf_counter() - t0
        page.evaluate("() => window.app.stream.send({type: 'stop'})")
    finally:
        page.close()
    return {"applied": result["applied"], "painted": result["painted"],
            "received_fps": len(result["applied"]) / elapsed, "page_fps": result["rafs"] / elapsed}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=20.0, help="recorded seconds per repeat")
    p.add_argument("--fps", type=float, default=60.0, help="the demo source's frame rate")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--gpu", action="store_true", help="let Chromium use the machine's GPU")
    args = p.parse_args(argv)

    from playwright.sync_api import sync_playwright

    print(machine())
    with ServerProcess() as server, sync_playwright() as pw:
        project_id = sample_project(server.url)
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=[] if args.gpu else SWIFTSHADER)
        try:
            for draw in (True, False):
                runs = []
                for r in range(args.repeats):
                    print(f"  {'drawing' if draw else 'viewport hidden'}: repeat {r + 1}/{args.repeats}",
                          file=sys.stderr, flush=True)
                    runs.append(one_run(browser, server.url, project_id, args.seconds, args.fps, draw))
                applied = [x for run in runs for x in run["applied"]]
                painted = [x for run in runs for x in run["painted"]]
                print(f"\n{'the app drawing the face' if draw else 'viewport hidden'}"
                      f" ({'GPU' if args.gpu else 'SwiftShader'}), {args.repeats} x {args.seconds:g} s"
                      f" at {args.fps:g} fps:")
                print(f"  publish -> applied in the page: {fmt(stats(applied))}")
                print("  per repeat medians: " + ", ".join(
                    f"{stats(run['applied'])['median']:.2f}" for run in runs) + " ms")
                if draw:
                    print(f"  publish -> next animation frame: {fmt(stats(painted))}")
                print("  frames received per s: " + ", ".join(f"{run['received_fps']:.1f}" for run in runs)
                      + "; page animation frames per s: " + ", ".join(f"{run['page_fps']:.1f}" for run in runs))
        finally:
            browser.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
