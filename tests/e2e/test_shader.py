"""The skinning shader against its CPU twin, in a real Chromium (WebGL2 via SwiftShader).

`SkinnedFace.deformedPositions()` runs web/shaders/skinning.glsl, the function the display
shader draws with, over every vertex and reads the result back; it must match
`retarget.skin.skin_displacements` on the rig the server stored, for the dense
weight-texture path (the sample's biharmonic rig, k = N = 68; also as the app downloads it,
RTSW version 2, quantised), the vertex-attribute path
(an ellipsoid rig, k = 4) and truncations of the dense rig (k = 8 with negative weights;
k = 12 with arbitrary joint order, scattered into the texture). The normals drawn with
(`deformedNormals()`) are the deformed mesh's area-weighted vertex normals. The drawn
pixels follow the pose, the heat map and the wireframe switch.
"""

from __future__ import annotations

import base64
import re

import httpx
import numpy as np
import pytest

from retarget.mesh import mesh_from_arrays, save_mesh
from retarget.sample_face import sample_face
from retarget.skin import SkinWeights, skin_displacements
from retarget.testing.seams import seam_split
from tests.e2e.conftest import ARTIFACTS, _expected_error
from tests.waits import scaled_ms, wait_job

TOLERANCE = 1e-4  # of the mesh's bounding-box diagonal

# A page of the server's origin with the client's import map; the modules under test are
# imported from /static/js like the app does.
PAGE = """<!doctype html><meta charset="utf-8"><title>skin check</title>
<script type="importmap">{"imports": {"three": "/vendor/three/build/three.module.js",
  "three/addons/": "/vendor/three/examples/jsm/"}}</script>
<style>body { margin: 0 } #viewport { width: 640px; height: 480px }</style>
<div id="viewport"></div>
<script type="module">
import { Viewer } from '/static/js/scene/Viewer.js';
import { SkinnedFace } from '/static/js/scene/SkinnedFace.js';
import { api } from '/static/js/net/api.js';

const bytes = ( base64 ) => Uint8Array.from( atob( base64 ), ( c ) => c.charCodeAt( 0 ) ).buffer;

// base64 of a typed array's bytes, by the browser's own encoder (a string built a byte at a
// time took most of a second for the canvas's pixels on a loaded machine)
function base64Of( array ) {
	return new Promise( ( resolve, reject ) => {
		const reader = new FileReader();
		reader.onload = () => resolve( reader.result.slice( reader.result.indexOf( ',' ) + 1 ) );
		reader.onerror = () => reject( reader.error );
		reader.readAsDataURL( new Blob( [ array ] ) );
	} );
}

async function fetchBinary( url ) {
	const response = await fetch( url );
	if ( ! response.ok ) throw new Error( `${ url }: HTTP ${ response.status }` );
	return response.arrayBuffer();
}

// GET /api/projects/{id}/rig/weights (format: server/routers/rigs.py)
function parseRig( buffer ) {
	const view = new DataView( buffer );
	const [ v, k, n ] = [ view.getUint32( 8, true ), view.getUint32( 12, true ), view.getUint32( 16, true ) ];
	const weightsAt = 20 + 2 * v * k + ( ( 2 * v * k ) % 4 );
	return {
		nJoints: n, nInfluences: k,
		indices: new Uint16Array( buffer.slice( 20, 20 + 2 * v * k ) ),
		weights: new Float32Array( buffer, weightsAt, v * k ),
	};
}

window.check = {
	async load( projectId, scale = 1 ) {
		const buffer = await fetchBinary( `/api/projects/${ projectId }/mesh/arrays` );
		const view = new DataView( buffer );
		const [ v, f ] = [ view.getUint32( 8, true ), view.getUint32( 12, true ) ];
		const face = await SkinnedFace.create( {
			positions: new Float32Array( buffer, 16, 3 * v ).map( ( x ) => x * scale ),
			faces: new Uint32Array( buffer, 16 + 12 * v, 3 * f ),
		} );
		this.viewer ??= new Viewer( document.getElementById( 'viewport' ) );
		this.face?.dispose();
		this.face = face;
		this.viewer.setObject( face.mesh );
		return v;
	},
	async setServerRig( projectId ) {
		this.face.setRig( parseRig( await fetchBinary( `/api/projects/${ projectId }/rig/weights` ) ) );
		return this.face.nInfluences;
	},
	// the rig as the app reads it: api.rigWeights, RTSW version 2 (quantised, gzip-encoded)
	async setPageRig( projectId ) {
		this.face.setRig( await api.rigWeights( projectId ) );
		return this.face.nInfluences;
	},
	setRig( nJoints, nInfluences, indices, weights ) {
		this.face.setRig( { nJoints, nInfluences, indices: new Uint16Array( bytes( indices ) ), weights: new Float32Array( bytes( weights ) ) } );
	},
	// the canvas as drawn: RGBA8, rows bottom-up (read before the frame is composited)
	pixels() {
		this.viewer.render();
		const gl = this.viewer.renderer.getContext();
		const out = new Uint8Array( 4 * gl.drawingBufferWidth * gl.drawingBufferHeight );
		gl.readPixels( 0, 0, gl.drawingBufferWidth, gl.drawingBufferHeight, gl.RGBA, gl.UNSIGNED_BYTE, out );
		return base64Of( out );
	},
	deformed( displacements ) {
		this.face.setDisplacements( displacements === null ? null : new Float32Array( bytes( displacements ) ) );
		this.viewer.render();
		const positions = this.face.deformedPositions();
		return base64Of( positions );
	},
	normals() {
		return base64Of( this.face.deformedNormals() );
	},
};
window.ready = true;
</script>
"""


def _b64(array: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(array).tobytes()).decode()




def _mesh_arrays(server, project_id: str) -> tuple[np.ndarray, np.ndarray]:
    data = server.read(f"/api/projects/{project_id}/mesh/arrays")
    v, f = np.frombuffer(data, "<u4", 2, 8)
    return (np.frombuffer(data, "<f4", 3 * v, 16).reshape(v, 3),
            np.frombuffer(data, "<u4", 3 * f, 16 + 12 * v).reshape(f, 3))


def _stored_rig(server, project_id: str) -> SkinWeights:
    """The rig as the store wrote it (`SkinWeights.save`), read without the server."""
    files = sorted((server.data_dir / "projects" / project_id).glob("rig-*.npz"))
    assert len(files) == 1, files
    return SkinWeights.load(files[0])


def _wait_for_rig(server, project_id: str, method: str) -> None:
    job = server.api("POST", f"/api/projects/{project_id}/rig", {"method": method})
    job = wait_job(server, job["id"], timeout_s=120, poll_s=0.2)
    assert job["state"] == "done", job


@pytest.fixture(scope="module")
def server(module_server):
    """One server for the module (the sample project's rig is read, and replaced only by
    the last test)."""
    return module_server


@pytest.fixture(scope="module")
def check_page(browser, server):
    """The check page, loaded once for the module (a load parses three.js and the app's
    modules, seconds on a loaded machine); `sample` shows the face afresh for each test.
    Console errors collect in `page.console_errors` and fail the test during which they
    appeared, as the conftest `page` fixture's do."""
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    context.set_default_timeout(scaled_ms(30_000))
    page = context.new_page()
    page.console_errors = []
    page.on("console", lambda msg: page.console_errors.append(f"console.{msg.type}: {msg.text}")
            if msg.type == "error" and not _expected_error(msg.text) else None)
    page.on("pageerror", lambda exc: page.console_errors.append(f"page error: {exc}"))
    page.route(server.url + "/skin-check", lambda route: route.fulfill(body=PAGE, content_type="text/html"))
    page.goto(server.url + "/skin-check")
    page.wait_for_function("window.ready === true")
    yield page
    context.close()


@pytest.fixture
def page(check_page, request):
    """The module's check page; a screenshot under test-artifacts/e2e/ after each test."""
    yield check_page
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    check_page.screenshot(path=str(ARTIFACTS / f"{re.sub(r'[^A-Za-z0-9_.-]+', '_', request.node.name)}.png"))
    errors, check_page.console_errors[:] = list(check_page.console_errors), []
    assert not errors, "browser reported errors:\n" + "\n".join(errors)


@pytest.fixture
def sample(server, page):
    """The sample project shown in the check page: (page, project id, rest positions)."""
    project_id = next(p["id"] for p in server.api("GET", "/api/projects") if p["settings"].get("sample"))
    # the viewer outlives the face: undo what an earlier test set on it (a narrower view, wireframe)
    page.evaluate("document.getElementById('viewport').style.width = ''; check.viewer?.setWireframe(false)")
    positions, _ = _mesh_arrays(server, project_id)
    assert page.evaluate("(id) => check.load(id)", project_id) == len(positions)
    return page, project_id, positions


def _displacements(n_joints: int, size: float, seed: int) -> np.ndarray:
    """(N, 3) float32 feature displacements of a few percent of the face's size."""
    return (np.random.default_rng(seed).normal(size=(n_joints, 3)) * 0.03 * size).astype(np.float32)


def _vertex_normals(positions: np.ndarray, faces: np.ndarray, rest: np.ndarray | None = None) -> np.ndarray:
    """(V, 3) unit area-weighted vertex normals (three.js's computeVertexNormals), over
    every triangle at the vertex's `rest` position (default `positions`): the copies of a
    vertex along a UV seam share their triangles."""
    p = positions.astype(np.float64)
    at = np.unique(p if rest is None else rest, axis=0, return_inverse=True)[1].ravel()
    face_normals = np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])
    normals = np.zeros_like(p)
    for corner in range(3):
        np.add.at(normals, at[faces[:, corner]], face_normals)
    normals = normals[at]
    return normals / np.linalg.norm(normals, axis=1, keepdims=True)


def _shader_error(page, server, project_id, rig: SkinWeights, seed: int,
                  normal_tolerance: float = 1e-3) -> float:
    """Max |GPU - CPU| over the vertex positions, relative to the bounding-box diagonal.
    The deformed normals are checked on the way (max |GPU - CPU| of unit vectors below
    `normal_tolerance`)."""
    positions, faces = _mesh_arrays(server, project_id)
    size = float(np.linalg.norm(positions.max(0) - positions.min(0)))
    d = _displacements(rig.n_joints, size, seed)
    gpu = np.frombuffer(base64.b64decode(page.evaluate("(d) => check.deformed(d)", _b64(d))), np.float32)
    cpu = positions + skin_displacements(rig, d)
    moved = float(np.abs(cpu - positions).max())
    assert moved > 0.01 * size, "the test displacements barely move the face"
    error = float(np.abs(gpu.reshape(-1, 3) - cpu).max()) / size

    used = np.unique(faces)  # a vertex in no triangle has no normal to compare
    gpu_normals = np.frombuffer(base64.b64decode(page.evaluate("check.normals()")), np.float32).reshape(-1, 3)
    cpu_normals = _vertex_normals(cpu, faces, rest=positions)
    normal_error = float(np.abs(gpu_normals[used] - cpu_normals[used]).max())
    turned = float(np.abs(cpu_normals[used] - _vertex_normals(positions, faces)[used]).max())
    print(f"{rig.method} k={rig.n_influences}: max |GPU - CPU| = {error:.2e} x mesh size (moved up to "
          f"{moved / size:.3f}); normals {normal_error:.1e} (turned up to {turned:.2f})")
    assert turned > 0.1 and normal_error < normal_tolerance
    return error


def test_dense_rig_matches_cpu(sample, server):
    page, project_id, positions = sample
    rig = _stored_rig(server, project_id)
    assert rig.n_influences == rig.n_joints > 8  # the weight-texture path
    assert page.evaluate("(id) => check.setServerRig(id)", project_id) == rig.n_influences
    assert (rig.weights < 0).any(), "the biharmonic rig should have negative weights, which must not be clamped"
    assert _shader_error(page, server, project_id, rig, seed=1, normal_tolerance=2e-3) < TOLERANCE
    rest = np.frombuffer(base64.b64decode(page.evaluate("check.deformed(null)")), np.float32)
    assert np.array_equal(rest.reshape(-1, 3), positions)


def test_dense_rig_as_the_app_downloads_it_matches_cpu(sample, server):
    """The page's download (RTSW version 2: 20-bit weights over a power-of-two step, gzip)
    is the stored rig exactly (the store keeps rigs on that grid), and the GPU skins it as
    the library does."""
    from server.wire import weights_from_binary

    page, project_id, _ = sample
    rig = _stored_rig(server, project_id)
    assert page.evaluate("(id) => check.setPageRig(id)", project_id) == rig.n_influences
    downloaded = weights_from_binary(server.read(f"/api/projects/{project_id}/rig/weights?version=2"))
    assert np.array_equal(downloaded.weights, rig.weights) and np.array_equal(downloaded.indices, rig.indices)
    assert _shader_error(page, server, project_id, rig, seed=1) < TOLERANCE


@pytest.mark.parametrize("k", [8, 12])
def test_truncated_rig_matches_cpu(sample, server, k):
    """k = 8: attributes, both halves used, negative weights; k = 12: texture from an
    arbitrary joint order."""
    page, project_id, _ = sample
    rig = _stored_rig(server, project_id).top_k(k)
    page.evaluate("([n, k, i, w]) => check.setRig(n, k, i, w)",
                  [rig.n_joints, k, _b64(rig.indices.astype("<u2")), _b64(rig.weights.astype("<f4"))])
    assert _shader_error(page, server, project_id, rig, seed=3) < TOLERANCE


def test_a_uv_seam_moves_as_one_and_shows_no_crease(server, page, tmp_path):
    """A textured scan's glTF splits each vertex along its UV seams into copies at one
    position. The rig moves the copies as one (retarget/welding.py) and the normal pass sums
    every triangle at a position, so the seam shows no crease: before, each copy was lit by
    its own side's triangles only."""
    face = sample_face(1)
    vertices, faces, seam, copies = seam_split(face.vertices, face.faces, x=0.3)   # through the lips
    path = tmp_path / "seam.obj"
    save_mesh(mesh_from_arrays(vertices, faces), path)
    pid = server.api("POST", "/api/projects", {"name": "seam"})["id"]
    reply = httpx.put(f"{server.url}/api/projects/{pid}/mesh", files={"file": ("seam.obj", path.read_bytes())},
                      timeout=60)
    assert reply.status_code == 200, reply.text
    server.api("PUT", f"/api/projects/{pid}/landmarks",
               {"vertex_indices": face.landmarks68.tolist(), "layout": "ibug68"})
    _wait_for_rig(server, pid, "biharmonic")
    assert page.evaluate("(id) => check.load(id)", pid) == len(vertices)
    rig = _stored_rig(server, pid)
    assert page.evaluate("(id) => check.setServerRig(id)", pid) == rig.n_influences
    assert _shader_error(page, server, pid, rig, seed=4) < TOLERANCE
    deformed = np.frombuffer(base64.b64decode(page.evaluate("check.deformed(null)")), np.float32).reshape(-1, 3)
    normals = np.frombuffer(base64.b64decode(page.evaluate("check.normals()")), np.float32).reshape(-1, 3)
    np.testing.assert_array_equal(deformed[copies], deformed[seam])
    assert np.abs(normals[copies] - normals[seam]).max() < 1e-5


def _pixels(page) -> np.ndarray:
    return np.frombuffer(base64.b64decode(page.evaluate("check.pixels()")), np.uint8).reshape(-1, 4)[:, :3].astype(int)


def _changed(a: np.ndarray, b: np.ndarray) -> float:
    """Fraction of pixels that differ by more than a rounding step."""
    return float((np.abs(a - b).max(1) > 2).mean())


def _red(pixels: np.ndarray) -> np.ndarray:
    """Bright, saturated red pixels: the heat map's negative weights, never skin."""
    r, g, b = pixels.T
    return (r > 100) & (r > 2 * g) & (r > 2 * b)


def test_pose_heatmap_and_wireframe_change_the_pixels(sample, server):
    page, project_id, positions = sample
    rig = _stored_rig(server, project_id)
    page.evaluate("(id) => check.setServerRig(id)", project_id)
    rest = _pixels(page)
    face = (np.abs(rest - rest[0]).max(1) > 2).mean()  # the corner pixel is background
    assert 0.1 < face < 0.9, f"the face covers {face:.0%} of the view"

    # a pose moves the drawn surface, and neutral puts it back exactly
    size = float(np.linalg.norm(positions.max(0) - positions.min(0)))
    page.evaluate("(d) => check.deformed(d)", _b64(_displacements(rig.n_joints, size, seed=4)))
    assert _changed(_pixels(page), rest) > 0.02
    page.evaluate("check.deformed(null)")
    assert _changed(_pixels(page), rest) == 0

    # the heat map of the joint with the most negative weight shows weights, negative ones in red
    joint = int(rig.indices.ravel()[np.argmin(rig.weights)])
    page.evaluate("(j) => check.face.setHeatmap(j)", joint)
    heat = _pixels(page)
    assert _changed(heat, rest) > 0.5 * face
    assert _red(heat).sum() > 50 and not _red(rest).any()
    page.evaluate("(j) => check.face.setHeatmap(j)", (joint + 1) % rig.n_joints)
    assert _changed(_pixels(page), heat) > 0.01
    page.evaluate("check.face.setHeatmap(null)")
    assert _changed(_pixels(page), rest) == 0

    page.evaluate("check.viewer.setWireframe(true)")
    assert _changed(_pixels(page), rest) > 0.1 * face
    page.evaluate("check.viewer.setWireframe(false)")
    assert _changed(_pixels(page), rest) == 0


def test_viewer_frames_any_units_projects_and_resizes(sample):
    """Framing depends on the bounding sphere only: the face in metres, centimetres or
    millimetres looks the same; project() gives page pixels; the view follows its container."""
    page, project_id, positions = sample
    coverage, clipping = {}, {}
    for scale in (0.01, 1, 10):
        page.evaluate("([id, s]) => check.load(id, s)", [project_id, scale])
        coverage[scale] = _pixels(page)
        clipping[scale] = np.array(page.evaluate("[check.viewer.camera.near, check.viewer.camera.far]")) / scale
    for scale in (0.01, 10):
        assert _changed(coverage[scale], coverage[1]) < 0.002
        assert clipping[scale] == pytest.approx(clipping[1])

    centre = page.evaluate("check.face.mesh.geometry.boundingSphere.center.toArray()")
    assert page.evaluate("(p) => check.viewer.project(p)", centre) == pytest.approx({"x": 320, "y": 240}, abs=0.5)
    page.evaluate("document.getElementById('viewport').style.width = '320px'")
    page.wait_for_function("check.viewer.renderer.domElement.width === 320 * devicePixelRatio")
    assert page.evaluate("check.viewer.camera.aspect") == pytest.approx(320 / 480)
    assert page.evaluate("(p) => check.viewer.project(p)", centre) == pytest.approx({"x": 160, "y": 240}, abs=0.5)


# last: it replaces the module's shared rig with an ellipsoid one, and the tests above
# need the default (dense, signed) rig
def test_sparse_rig_matches_cpu(sample, server):
    page, project_id, _ = sample
    _wait_for_rig(server, project_id, "ellipsoid")
    rig = _stored_rig(server, project_id)
    assert rig.n_influences <= 8  # the vertex-attribute path
    assert page.evaluate("(id) => check.setServerRig(id)", project_id) == rig.n_influences
    assert _shader_error(page, server, project_id, rig, seed=2) < TOLERANCE
