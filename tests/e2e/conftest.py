"""End-to-end fixtures: a real `retarget serve` on a free port and Debian's Chromium
driven by Playwright, WebGL2 through SwiftShader.

Screenshots of every e2e test are kept in ``test-artifacts/e2e/`` (the test's name),
and browser console errors or uncaught page exceptions fail the test that caused them.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from playwright.sync_api import sync_playwright

from tests.waits import scaled, scaled_ms

CHROMIUM = "/usr/bin/chromium"
# WebGL without multisampling, as on a GPU that has none: SwiftShader draws on the CPU, where
# 4x MSAA doubled every frame's cost (a test playing a stream kept both cores busy), and
# no test judges edge smoothing
CHROMIUM_ARGS = ["--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--ignore-gpu-blocklist",
                 "--webgl-antialiasing-mode=none"]
ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "e2e"
_STARTUP_S = 60.0


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class Server:
    """One `retarget serve` process on 127.0.0.1; `restart()` keeps the data dir."""

    data_dir: Path
    args: tuple[str, ...] = ()  # extra `retarget serve` flags, e.g. ("--max-upload-mb", "1")
    port: int = field(default_factory=free_port)
    process: subprocess.Popen | None = None
    log: Path | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> "Server":
        self.log = self.data_dir.parent / f"server-{self.port}-{time.monotonic_ns()}.log"
        with open(self.log, "wb") as out:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "server.cli", "serve", "--port", str(self.port),
                 "--data-dir", str(self.data_dir), *self.args],
                stdout=out, stderr=subprocess.STDOUT, cwd=Path(__file__).resolve().parents[2])
        startup_s = scaled(_STARTUP_S)
        deadline = time.monotonic() + startup_s
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"server exited with {self.process.returncode}:\n{self.log.read_text()}")
            try:
                with urllib.request.urlopen(self.url + "/api/projects", timeout=1) as reply:
                    if reply.status == 200:
                        return self
            except urllib.error.HTTPError as refused:
                if refused.code == 401:  # up, and asking for its access token
                    return self
                time.sleep(0.1)
            except OSError:
                time.sleep(0.1)
        raise RuntimeError(f"server did not answer within {startup_s:.0f} s:\n{self.log.read_text()}")

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self.process = None

    def restart(self) -> "Server":
        self.stop()
        return self.start()

    def read(self, path: str) -> bytes:
        """The bytes of GET `path`."""
        with urllib.request.urlopen(self.url + path, timeout=30) as reply:
            return reply.read()

    def api(self, method: str, path: str, body: dict | None = None):
        """A JSON request to the REST API; its JSON answer (None for 204)."""
        data = None if body is None else json.dumps(body).encode()
        request = urllib.request.Request(self.url + path, data=data, method=method,
                                         headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(request, timeout=30) as reply:
            return json.loads(reply.read() or b"null")

    def wait_for_project(self, project_id: str, check, timeout_s: float = 120.0) -> dict:
        """Poll the project's JSON until `check(project)` holds; the project."""
        deadline = time.monotonic() + timeout_s
        while True:
            project = self.api("GET", f"/api/projects/{project_id}")
            if check(project):
                return project
            assert time.monotonic() < deadline, f"project never got there: {project}"
            time.sleep(0.1)


def write_face_file(folder: Path, name: str, identity) -> tuple[Path, object]:
    """An OBJ `name` in `folder` of the built-in face (cm) with `identity`, and the
    `SampleFace` (its vertices and 68 landmark indices are the test's ground truth)."""
    from retarget.mesh import mesh_from_arrays, save_mesh
    from retarget.sample_face import sample_face

    face = sample_face(1, identity=identity)
    path = folder / name
    save_mesh(mesh_from_arrays(face.vertices, face.faces), path)
    return path, face


def upload_face(server: Server, page, face_file, name: str) -> tuple[dict, object]:
    """A new project `name` shown in the page, with `face_file` = (path, SampleFace)
    uploaded through the file picker; the project JSON and the face."""
    path, face = face_file
    project = server.api("POST", "/api/projects", {"name": name})
    open_project(page, server, project["id"])
    page.set_input_files("#file-input", str(path))
    page.wait_for_function("n => window.app.face && window.app.face.mesh.geometry"
                           ".attributes.position.count === n", arg=len(face.vertices), timeout=scaled_ms(30_000))
    page.evaluate("() => window.app.ready")
    assert page.inner_text("#error").strip() == ""
    return project, face


def wait_face_moves(page, cm: float, timeout_ms: float = 30_000) -> None:
    """Wait until the skinning shader's vertices leave the rest pose by more than `cm`
    (mesh units) somewhere: the face on screen moves."""
    page.wait_for_function("""(cm) => {
        const face = window.app.face, rest = face.mesh.geometry.attributes.position.array;
        const now = face.deformedPositions();
        let most = 0;
        for (let i = 0; i < rest.length; i ++) most = Math.max(most, Math.abs(now[i] - rest[i]));
        return most > cm;
    }""", arg=cm, polling=200, timeout=scaled_ms(timeout_ms))


def open_project(page, server: Server, project_id: str) -> None:
    """Load the app on `project_id` and wait until it is shown."""
    page.goto(f"{server.url}/#p={project_id}")
    page.wait_for_function("() => window.app && window.app.projectId")
    page.evaluate("() => window.app.ready")


def sample_copy(sample_data_dir: Path, folder: Path) -> Path:
    """`folder` made a data dir holding the sample project, a copy of the one built once per
    run (a server started on an empty dir builds the same, at a few seconds of CPU)."""
    shutil.copytree(sample_data_dir, folder)
    return folder


@pytest.fixture
def server(tmp_path, copy_sample_data):
    """A real server on a free port with a fresh data dir holding the sample project
    (a copy of the one built once per run: the server would build the same at its start)."""
    srv = Server(copy_sample_data(tmp_path / "data")).start()
    yield srv
    srv.stop()


@pytest.fixture(scope="module")
def module_server(tmp_path_factory, sample_data_dir):
    """One server for a whole test module (a start costs seconds of CPU), for modules whose
    tests make projects of their own or leave the sample project as they found it; such a
    module opts in with a module-scoped ``server`` fixture that returns this one."""
    srv = Server(sample_copy(sample_data_dir, tmp_path_factory.mktemp("module") / "data")).start()
    yield srv
    srv.stop()


@pytest.fixture(scope="module")
def browser():
    """Chromium for one test module: Playwright's sync API keeps an asyncio loop running
    while it is open, which would break later tests that run their own loop."""
    yield from chromium()


def chromium(camera: Path | None = None):
    """Yield a Chromium browser, closed after; with `camera` (a Y4M file, `fake_camera`) its
    only camera plays that file, granted without asking. A module's `browser` fixture
    yields from it."""
    if not os.path.exists(CHROMIUM):
        pytest.fail(f"{CHROMIUM} is missing: the README's test command installs it with apt-get install chromium")
    args = CHROMIUM_ARGS if camera is None else [
        *CHROMIUM_ARGS, "--use-fake-device-for-media-stream", "--use-fake-ui-for-media-stream",
        f"--use-file-for-fake-video-capture={camera}"]
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=args)
        yield b
        b.close()


@pytest.fixture
def page(browser, request):
    """A fresh page (1280 x 800). Console errors and page exceptions fail the test; a
    screenshot is saved under test-artifacts/e2e/ whatever the outcome."""
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    context.set_default_timeout(scaled_ms(30_000))  # Playwright's own default, scaled to the load
    pg = context.new_page()
    errors: list[str] = []
    pg.on("console", lambda msg: errors.append(f"console.{msg.type}: {msg.text}")
          if msg.type == "error" and not _expected_error(msg.text) else None)
    pg.on("pageerror", lambda exc: errors.append(f"page error: {exc}"))
    pg.console_errors = errors
    yield pg
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    name = re.sub(r"[^A-Za-z0-9_.-]+", "_", request.node.name)
    try:
        pg.screenshot(path=str(ARTIFACTS / f"{name}.png"))
    except Exception:  # a crashed page has no screenshot; the test already failed
        pass
    context.close()
    assert not errors, "browser reported errors:\n" + "\n".join(errors)


def _expected_error(text: str) -> bool:
    """Errors Chromium logs for what tests provoke on purpose, whose handling by the UI
    is what the tests check: HTTP errors of bad uploads ('Failed to load resource') and
    the stream's reconnect attempts while a test restarts the server."""
    return "Failed to load resource" in text or (
        text.startswith("WebSocket connection to") and "ERR_CONNECTION_REFUSED" in text)
