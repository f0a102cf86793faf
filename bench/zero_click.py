"""Zero clicks from upload to a rigged, moving face, in the web app (issue 14).

    python bench/zero_click.py [--repeats 3] [--gpu]

A face mesh is picked in the page's file chooser of a new, empty project (headless
Chromium through Playwright, SwiftShader unless --gpu, against a real `retarget serve` on
a temp data dir), and nothing else is done: the page finds the points (the server's job,
`POST .../landmarks/find`), rigs the face (the default deformer) and plays the built-in
demo on it. The page itself notes, from the moment the file is handed to the chooser:

    mesh      the uploaded mesh drawn (upload, server checks, download, GPU set-up)
    points    the found landmarks shown on it
    rigged    the rig on the face: a rigged face with landmarks (the figure; target < 15 s)
    moving    the first demo frame applied to it

Meshes: the project's sample face (8,430 vertices) and, when ../shared exists, the ICT
face model's neutral (11,248 vertices, ``ict_face.npz`` keys ``neutral``, ``faces``), each
saved as OBJ (not timed). Prints each repeat and the median per mesh.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from bench.ict import DATA  # noqa: E402
from bench.stream import ServerProcess, http_json, machine  # noqa: E402
from retarget.mesh import mesh_from_arrays, save_mesh  # noqa: E402
from retarget.sample_face import sample_face  # noqa: E402

CHROMIUM = "/usr/bin/chromium"
SWIFTSHADER = ["--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--ignore-gpu-blocklist",
               "--webgl-antialiasing-mode=none"]
STAGES = ("mesh", "points", "rigged", "moving")
TIMEOUT_MS = 300_000

# what the page shows, polled every 10 ms from the moment the file is handed over
_WATCH = """() => {
    const app = window.app, seen = {};
    window.benchSeen = seen;
    window.benchT0 = performance.now();
    const check = () => {
        const t = (performance.now() - window.benchT0) / 1000;
        const face = app.face;
        if (!seen.mesh && face && app.project && app.project.mesh) seen.mesh = t;
        if (!seen.points && face && app.picker.placedCount > 0 && !app.marks.finding
            && app.landmarks.placedCount === app.landmarks.points.length && app.project.landmarks) seen.points = t;
        if (!seen.rigged && face && face.nJoints > 0 && app.project.rig) seen.rigged = t;
        if (!seen.moving && app.streaming && app.stream && app.stream.stats.frames > 0) seen.moving = t;
        if (!seen.moving) setTimeout(check, 10);
    };
    check();
}"""


def one_run(browser, url: str, obj: Path, run: int) -> dict:
    project = http_json(f"{url}/api/projects", "POST", {"name": f"zero click {run}"})
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    try:
        page.goto(f"{url}/#p={project['id']}")
        page.wait_for_function("() => window.app && window.app.projectId")
        page.evaluate("() => window.app.ready")
        page.evaluate(_WATCH)
        page.set_input_files("#file-input", str(obj))
        page.wait_for_function("() => window.benchSeen.moving !== undefined"
                               " || document.getElementById('error-text').textContent !== ''",
                               timeout=TIMEOUT_MS)
        error = page.inner_text("#error-text")
        if error:
            raise RuntimeError(f"the page says: {error}")
        seen = page.evaluate("() => window.benchSeen")
        seen["check"] = page.inner_text("#find-note")
    finally:
        page.close()
    return seen


def meshes(folder: Path) -> list[tuple[str, Path]]:
    """(name, OBJ path) of each benchmarked face."""
    out = []
    face = sample_face(1)
    path = folder / "sample_face.obj"
    save_mesh(mesh_from_arrays(face.vertices, face.faces), path)
    out.append((f"sample face ({len(face.vertices):,} vertices)", path))
    if DATA.exists():
        data = np.load(DATA)
        path = folder / "ict_neutral.obj"
        save_mesh(mesh_from_arrays(data["neutral"], data["faces"]), path)
        out.append((f"ICT neutral ({len(data['neutral']):,} vertices)", path))
    else:
        print(f"({DATA} is absent: the ICT neutral is skipped)")
    return out


@contextmanager
def server_and_chromium(gpu: bool):
    """(scratch folder, a real `retarget serve`, Chromium: SwiftShader unless `gpu`), all
    closed on leaving."""
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as tmp, ServerProcess() as server, sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=[] if gpu else SWIFTSHADER)
        try:
            yield Path(tmp), server, browser
        finally:
            browser.close()


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--gpu", action="store_true", help="let Chromium use the machine's GPU")
    args = p.parse_args(argv)

    print(machine())
    with server_and_chromium(args.gpu) as (tmp, server, browser):
        faces = meshes(tmp)
        for name, obj in faces:
            runs = []
            for r in range(args.repeats):
                print(f"  {name}: repeat {r + 1}/{args.repeats}", file=sys.stderr, flush=True)
                start = time.perf_counter()
                runs.append(one_run(browser, server.url, obj, r))
                print(f"    {time.perf_counter() - start:.1f} s in all", file=sys.stderr, flush=True)
            print(f"\n{name}, upload through the file chooser -> (s), {'GPU' if args.gpu else 'SwiftShader'}:")
            for i, run in enumerate(runs):
                print(f"  repeat {i + 1}: " + ", ".join(f"{s} {run[s]:.2f}" for s in STAGES))
            print("  median:   " + ", ".join(f"{s} {statistics.median(run[s] for run in runs):.2f}"
                                            for s in STAGES))
            print(f"  upload -> rigged face with landmarks: {statistics.median(run['rigged'] for run in runs):.1f} s"
                  f" (median of {len(runs)}); the panel: {runs[-1]['check']!r}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
