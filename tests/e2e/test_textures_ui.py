"""Textured meshes in the real page: an OBJ picked with its MTL and PNG, a GLB with an
embedded image, files dropped together or zipped. The view draws the texture (read back
from the screen: the image's colour regions where its uv put them), the Texture / Shaded
switch turns it off, the painting heat map still shows over it, and the export keeps
the image; files that cannot make a textured mesh are refused with the reason."""

from __future__ import annotations

import base64
import io
import zipfile

import numpy as np
import pytest
import trimesh
from PIL import Image

from retarget.gltf import read_gltf
from tests.e2e.conftest import open_project
from tests.waits import scaled_ms, wait_job

N = 25  # grid vertices per side


@pytest.fixture(scope="module")
def server(module_server):
    """One server for these tests: each makes a project of its own."""
    return module_server


def _surface() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A face-sized bulging sheet facing +z: vertices (V, 3) cm, faces (F, 3), uv (V, 2)
    with u along x and v along y (OBJ's convention)."""
    s = np.linspace(0.0, 1.0, N)
    u, v = (a.ravel() for a in np.meshgrid(s, s))
    x, y = 16 * u - 8, 20 * v - 10
    vertices = np.column_stack([x, y, 4 - 0.02 * (x**2 + y**2)])
    i = np.arange(N - 1)
    corner = (i[None, :] + N * i[:, None]).ravel()
    faces = np.concatenate([np.column_stack([corner, corner + 1, corner + N + 1]),
                            np.column_stack([corner, corner + N + 1, corner + N])])
    return vertices, faces, np.column_stack([u, v])


def _image() -> Image.Image:
    """64 x 64: left half red, right half blue, the bottom quarter (v < 0.25) green."""
    pixels = np.zeros((64, 64, 3), np.uint8)
    pixels[:, :32] = (255, 0, 0)
    pixels[:, 32:] = (0, 0, 255)
    pixels[48:] = (0, 255, 0)
    return Image.fromarray(pixels)


def _png() -> bytes:
    out = io.BytesIO()
    _image().save(out, "PNG")
    return out.getvalue()


MTL = b"newmtl scan\nKd 1 1 1\nmap_Kd maps/scan-colour.png\n"


def _obj() -> bytes:
    vertices, faces, uv = _surface()
    lines = ["mtllib scan.mtl", *(f"v {x:.5f} {y:.5f} {z:.5f}" for x, y, z in vertices),
             *(f"vt {a:.5f} {b:.5f}" for a, b in uv), "usemtl scan"]
    lines += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in faces + 1]
    return "\n".join(lines).encode()


def _glb() -> bytes:
    vertices, faces, uv = _surface()
    mesh = trimesh.Trimesh(vertices, faces, process=False,
                           visual=trimesh.visual.TextureVisuals(uv=uv, image=_image()))
    return mesh.export(file_type="glb")


def _write(folder, files: dict[str, bytes]) -> list[str]:
    paths = []
    for name, data in files.items():
        (folder / name).write_bytes(data)
        paths.append(str(folder / name))
    return paths


def _classes(page) -> dict[str, np.ndarray]:
    """Screen pixels of the viewport drawn in the texture's saturated red, blue and green:
    {colour: (n, 2) x, y}."""
    shot = np.asarray(Image.open(io.BytesIO(page.locator("#viewport").screenshot())).convert("RGB"), float)
    r, g, b = shot[..., 0], shot[..., 1], shot[..., 2]

    def saturated(main, *others):  # lit, and nothing like the skin tone or viridis
        return (main > 120) & (np.maximum(*others) < 90) & (main > 2.5 * np.maximum(*others))

    found = {"red": saturated(r, g, b), "green": saturated(g, r, b), "blue": saturated(b, r, g)}
    return {name: np.argwhere(mask)[:, ::-1] for name, mask in found.items()}


def _drawn(page, n_vertices: int) -> None:
    """Wait for the uploaded face with its texture, drawn."""
    page.wait_for_function("n => window.app.face && window.app.face.nVertices === n && window.app.face.hasTexture",
                           arg=n_vertices, timeout=scaled_ms(30_000))
    page.evaluate("() => window.app.ready")
    page.wait_for_selector("#surface-switch", state="visible", timeout=scaled_ms(30_000))
    page.evaluate("() => new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)))")


def _assert_texture_drawn(page) -> None:
    """Red on the left, blue on the right, green below them: the image where uv put it."""
    drawn = _classes(page)
    sizes = {name: len(xy) for name, xy in drawn.items()}
    assert min(sizes.values()) > 1500, sizes
    red, blue, green = (drawn[c].mean(0) for c in ("red", "blue", "green"))
    assert red[0] < blue[0] - 100, (red, blue)  # u grows to the right
    assert green[1] > max(red[1], blue[1]) + 80, (green, red, blue)  # v grows upwards


def _assert_plain(page, colours=("red", "green", "blue")) -> None:
    """None of the texture's `colours` on the screen."""
    sizes = {name: len(xy) for name, xy in _classes(page).items()}
    assert max(sizes[c] for c in colours) < 50, sizes


def _new_project(server, page, name: str) -> str:
    pid = server.api("POST", "/api/projects", {"name": name})["id"]
    open_project(page, server, pid)
    return pid


def _rig(server, pid: str) -> None:
    grid = [N * row + col for row in (4, 8, 12, 16, 20) for col in (3, 7, 12, 17, 21)]
    server.api("PUT", f"/api/projects/{pid}/landmarks", {"vertex_indices": grid[:22], "layout": "dutreve22"})
    job = server.api("POST", f"/api/projects/{pid}/rig", {"method": "ellipsoid"})
    assert wait_job(server, job["id"], 120)["state"] == "done"


def test_an_obj_picked_with_its_mtl_and_png_is_drawn_textured_switched_painted_and_exported(
        server, page, tmp_path):
    pid = _new_project(server, page, "scan")
    page.set_input_files("#file-input", _write(tmp_path, {
        "scan.obj": _obj(), "scan.mtl": MTL, "scan-colour.png": _png()}))
    _drawn(page, N * N)
    assert page.inner_text("#error").strip() == ""
    assert server.api("GET", f"/api/projects/{pid}")["mesh"]["format"] == "zip"
    assert page.is_checked("#surface-texture")
    _assert_texture_drawn(page)

    # Shaded: the plain surface, no texture colour left; and back
    page.click("label:has(#surface-shaded)")
    page.evaluate("() => new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)))")
    _assert_plain(page)
    page.keyboard.press("t")
    assert page.is_checked("#surface-texture")
    _assert_texture_drawn(page)

    # rigged: painting shows the heat map over the texture
    _rig(server, pid)
    page.reload()
    page.wait_for_function("() => window.app.face && window.app.face.nJoints === 22 && window.app.face.hasTexture",
                           timeout=scaled_ms(30_000))
    page.click("#paint-toggle")
    page.select_option("#paint-joint", "0")
    page.wait_for_function("() => window.app.face.mesh.material.uniforms.heatJoint.value === 0")
    page.evaluate("() => new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)))")
    _assert_plain(page, ("red", "blue"))  # viridis has greens, no saturated red or blue
    assert page.inner_text("#error").strip() == ""
    page.click("#paint-toggle")

    # the export keeps the image
    with page.expect_download() as download:
        page.click("#export-gltf")
    path = tmp_path / "exported.glb"
    download.value.save_as(path)
    texture = Image.open(io.BytesIO(read_gltf(path).mesh.material.base_color_texture)).convert("RGB")
    np.testing.assert_array_equal(np.asarray(texture), np.asarray(_image()))


def test_a_glb_with_an_embedded_texture_is_drawn_textured(server, page, tmp_path):
    _new_project(server, page, "glb")
    page.set_input_files("#file-input", _write(tmp_path, {"scan.glb": _glb()}))
    _drawn(page, N * N)
    _assert_texture_drawn(page)
    page.click("label:has(#surface-shaded)")
    page.evaluate("() => new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)))")
    _assert_plain(page)


def _drop(page, files: dict[str, bytes]) -> None:
    """Drop `files` on the view together, as a file manager does."""
    page.evaluate("""(files) => {
        const transfer = new DataTransfer();
        for (const [name, data] of Object.entries(files)) {
            const bytes = Uint8Array.from(atob(data), (c) => c.charCodeAt(0));
            transfer.items.add(new File([bytes], name));
        }
        const zone = document.getElementById('drop-zone');
        for (const type of ['dragenter', 'dragover', 'drop'])
            zone.dispatchEvent(new DragEvent(type, {dataTransfer: transfer, bubbles: true, cancelable: true}));
    }""", {name: base64.b64encode(data).decode() for name, data in files.items()})


def _error(page) -> str:
    page.wait_for_function("() => document.getElementById('error-text').textContent !== ''", timeout=scaled_ms(30_000))
    return page.inner_text("#error-text")


@pytest.mark.parametrize("files, reason", [
    # the server reads the MTL and names the image it lacks
    ({"scan.obj": _obj(), "scan.mtl": MTL}, "uses the texture image 'scan-colour.png', which was not given"),
    # the page refuses before sending
    ({"scan.obj": _obj(), "scan.mtl": MTL, "run.exe": b"MZ"}, '"run.exe" is not a mesh this app reads nor a file'),
    ({"scan.obj": _obj(), "other.obj": _obj()}, "2 meshes (scan.obj, other.obj) among the 2 files"),
    ({"scan.mtl": MTL, "scan-colour.png": _png()}, "no mesh among the 2 files"),
])
def test_dropped_files_that_make_no_textured_mesh_are_refused_saying_why(server, page, files, reason):
    pid = _new_project(server, page, "refused")
    _drop(page, files)
    assert reason in _error(page)
    assert server.api("GET", f"/api/projects/{pid}")["mesh"] is None
    assert page.evaluate("() => window.app.face") is None


def test_dropped_files_and_a_zip_of_them_are_drawn_textured(server, page):
    _new_project(server, page, "dropped")
    _drop(page, {"scan.obj": _obj(), "scan.mtl": MTL, "scan-colour.png": _png()})
    _drawn(page, N * N)
    _assert_texture_drawn(page)

    pid = _new_project(server, page, "zipped")
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("scan/scan.obj", _obj())
        archive.writestr("scan/scan.mtl", MTL)
        archive.writestr("scan/maps/scan-colour.png", _png())
    _drop(page, {"scan.zip": out.getvalue()})
    _drawn(page, N * N)
    _assert_texture_drawn(page)
    assert server.api("GET", f"/api/projects/{pid}")["mesh"]["filename"] == "scan.zip"
