"""The glTF export in the browser: stock three.js plays it as our app draws it, and the
Export panel downloads and imports it.

three.js proof: the server's export of the sample project (biharmonic rig: morph targets)
and of the same face with an ellipsoid rig (a true glTF skin) is loaded with three.js's
own GLTFLoader, its AnimationMixer is set to a key time and to a time between keys, and
the posed vertices are read the stock way (`Mesh.getVertexPosition`: morph targets, and
for a SkinnedMesh `applyBoneTransform` on top). They must equal, within 1e-4 of the mesh
size, both the library's linear blend skinning (`retarget.skin.skin_displacements`) and
our app's skinning shader (`SkinnedFace.deformedPositions()`) on the project's rig with
the clip's feature displacements at that time. three.js reads one JOINTS_0/WEIGHTS_0 set
(four influences), so the skin must need no second set. The muscle export
(``drive=muscles``: a morph target per muscle and corrective, a jaw joint) must play in
three.js as glTF defines it (`retarget.gltf.animation`, which
tests/unit/test_export_muscles.py ties to the muscles' played form). The ARKit export (52
morph targets named after ARKit, in sparse accessors) must play in three.js as
`ArkitShapes.posed` of the interpolated weights, within the targets' tolerance.
"""

from __future__ import annotations

import base64
import io
import json
import struct
import urllib.parse

import httpx
import numpy as np
import pytest

from retarget.arkit.clip import ArkitClip
from retarget.arkit.reference import ARKIT_NAMES
from retarget.arkit.shapes import arkit_shapes
from retarget.gltf import export_arkit_gltf, read_gltf
from retarget.gltf.arkit import arkit_tolerance
from retarget.gltf.animation import (animated_weights, animation_channels, drawn_vertices, mesh_instances,
                                       node_transforms, posed_vertices)
from retarget.gltf.document import GltfDocument
from retarget.landmarks import from_vertex_indices
from retarget.layouts import get_layout
from retarget.mesh import mesh_from_arrays
from retarget.sample_face import demo_weights, sample_face
from retarget.skin import SkinWeights, skin_displacements
from retarget.weights import compute_weights
from tests.e2e.conftest import Server, open_project, sample_copy
from tests.waits import wait_job
from tests.waits import scaled_ms

TOLERANCE = 1e-4  # of the mesh's bounding-box diagonal
FPS = 30.0

PAGE = """<!doctype html><meta charset="utf-8"><title>three.js export check</title>
<script type="importmap">{"imports": {"three": "/vendor/three/build/three.module.js",
  "three/addons/": "/vendor/three/examples/jsm/"}}</script>
<script type="module">
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { SkinnedFace } from '/static/js/scene/SkinnedFace.js';

const encoded = ( array ) => btoa( String.fromCharCode( ...new Uint8Array( array.buffer ) ) );
const decoded = ( text ) => Uint8Array.from( atob( text ), ( c ) => c.charCodeAt( 0 ) ).buffer;

async function fetchBinary( url ) {
	const response = await fetch( url );
	if ( ! response.ok ) throw new Error( `${ url }: HTTP ${ response.status }` );
	return response.arrayBuffer();
}

window.check = {
	// three.js: the stock loader, mixer and CPU vertex evaluation
	async load( url ) {
		this.gltf = await new GLTFLoader().loadAsync( url );
		this.mixer = new THREE.AnimationMixer( this.gltf.scene );
		this.mesh = null;
		this.gltf.scene.traverse( ( object ) => { if ( object.isMesh ) this.mesh = object; } );
		const geometry = this.mesh.geometry;
		return {
			skinned: this.mesh.isSkinnedMesh === true,
			morphs: geometry.morphAttributes.position?.length ?? 0,
			skinAttributes: Object.keys( geometry.attributes ).filter( ( name ) => name.startsWith( 'skin' ) ).sort(),
			vertices: geometry.attributes.position.count,
			morphNames: Object.keys( this.mesh.morphTargetDictionary ?? {} ),
			animations: this.gltf.animations.map( ( clip ) => [ clip.name, clip.duration ] ),
		};
	},
	posed( t ) {
		this.mixer.stopAllAction();
		const action = this.mixer.clipAction( this.gltf.animations[ 0 ] );
		action.setLoop( THREE.LoopOnce );
		action.clampWhenFinished = true;
		action.play();
		this.mixer.setTime( t );
		this.gltf.scene.updateMatrixWorld( true );
		const out = new Float32Array( 3 * this.mesh.geometry.attributes.position.count );
		const v = new THREE.Vector3();
		for ( let i = 0; i < out.length / 3; i ++ ) {
			this.mesh.getVertexPosition( i, v );
			v.applyMatrix4( this.mesh.matrixWorld );
			out.set( [ v.x, v.y, v.z ], 3 * i );
		}
		return encoded( out );
	},
	// our app's shader (web/shaders/skinning.glsl) on the project's mesh and rig
	async loadFace( projectId ) {
		const mesh = await fetchBinary( `/api/projects/${ projectId }/mesh/arrays` );
		const view = new DataView( mesh );
		const [ v, f ] = [ view.getUint32( 8, true ), view.getUint32( 12, true ) ];
		this.face?.dispose();
		this.face = await SkinnedFace.create( {
			positions: new Float32Array( mesh, 16, 3 * v ), faces: new Uint32Array( mesh, 16 + 12 * v, 3 * f ) } );
		const rig = await fetchBinary( `/api/projects/${ projectId }/rig/weights` );
		const r = new DataView( rig );
		const [ rv, k, n ] = [ r.getUint32( 8, true ), r.getUint32( 12, true ), r.getUint32( 16, true ) ];
		const weightsAt = 20 + 2 * rv * k + ( ( 2 * rv * k ) % 4 );
		this.face.setRig( { nJoints: n, nInfluences: k, indices: new Uint16Array( rig.slice( 20, 20 + 2 * rv * k ) ),
			weights: new Float32Array( rig, weightsAt, rv * k ) } );
	},
	shaded( displacements ) {
		this.face.setDisplacements( new Float32Array( decoded( displacements ) ) );
		return encoded( this.face.deformedPositions() );
	},
	// our app's viewer turning the head: the shader's positions through the face mesh's matrix
	turned( displacements, q ) {
		this.face.setDisplacements( new Float32Array( decoded( displacements ) ) );
		this.face.setHeadRotation( q );
		this.face.mesh.updateMatrixWorld( true );
		const out = this.face.deformedPositions(), v = new THREE.Vector3();
		for ( let i = 0; i < out.length; i += 3 ) {
			v.fromArray( out, i ).applyMatrix4( this.face.mesh.matrixWorld ).toArray( out, i );
		}
		this.face.setHeadRotation( null );
		return encoded( out );
	},
};
window.ready = true;
</script>
"""


@pytest.fixture(scope="module")
def server(tmp_path_factory, sample_data_dir):
    """One server for the module, on a fresh data dir with the sample project."""
    srv = Server(sample_copy(sample_data_dir, tmp_path_factory.mktemp("export") / "data")).start()
    yield srv
    srv.stop()


@pytest.fixture(scope="module")
def sample(server):
    """The sample project with a take of another identity performing the demo: (project
    id, take info)."""
    pid = next(p["id"] for p in server.api("GET", "/api/projects") if p["settings"].get("sample"))
    face = sample_face(identity=np.array([0.8, 0.5, -0.6, 1.0, 0.3]))
    lm = np.asarray(face.landmarks68)
    frames = face.vertices[lm] + np.tensordot(demo_weights(45, FPS), face.expressions[:, lm], axes=1)
    buffer = io.BytesIO()
    np.save(buffer, frames.astype(np.float32))
    r = httpx.post(f"{server.url}/api/projects/{pid}/takes", timeout=30,
                   files={"file": ("talk.npy", buffer.getvalue())}, data={"layout": "ibug68", "fps": str(FPS)})
    assert r.status_code == 201, r.text
    return pid, r.json()


def _decoded(text: str) -> np.ndarray:
    return np.frombuffer(base64.b64decode(text), np.float32).reshape(-1, 3).astype(np.float64)


def _server_rig(server, pid) -> SkinWeights:
    """The project's rig from GET rig/weights (the RTSW format of server/routers/rigs.py)."""
    data = server.read(f"/api/projects/{pid}/rig/weights")
    v, k, n = struct.unpack_from("<III", data, 8)
    at = 20 + 2 * v * k + (2 * v * k) % 4
    return SkinWeights(np.frombuffer(data, "<u2", v * k, 20).reshape(v, k).astype(np.int32),
                       np.frombuffer(data, "<f4", v * k, at).reshape(v, k), n)


def _rest(server, pid) -> np.ndarray:
    data = server.read(f"/api/projects/{pid}/mesh/arrays")
    v = struct.unpack_from("<I", data, 8)[0]
    return np.frombuffer(data, "<f4", 3 * v, 16).reshape(v, 3).astype(np.float64)


def _rig(server, pid, method: str) -> None:
    job = server.api("POST", f"/api/projects/{pid}/rig", {"method": method})
    job = wait_job(server, job["id"], timeout_s=120, poll_s=0.1)
    assert job["state"] == "done", job


def _file_scale(data: bytes) -> float:
    """What the export multiplied every length by (0.01: the centimetre sample in metres)."""
    return GltfDocument(data, "export", None).doc.scenes[0].extras["retarget"]["scale"]


def _three_matches_ours(page, server, pid, take) -> dict:
    """Load the project's export with its take in three.js and compare its posed vertices
    (in metres, over the file's scale) with our LBS and our shader at a key time and between
    keys; what three.js loaded."""
    url = f"/api/projects/{pid}/export.glb?takes={take['id']}"
    data = server.read(url)
    clip, scale = read_gltf(data).clips[0], _file_scale(data)
    loaded = page.evaluate("(url) => check.load(url)", url)
    assert loaded["animations"] == [[take["name"], pytest.approx(clip.duration, abs=1e-6)]]
    page.evaluate("(id) => check.loadFace(id)", pid)
    rest, rig = _rest(server, pid), _server_rig(server, pid)
    size = float(np.linalg.norm(rest.max(0) - rest.min(0)))
    key = min(int(np.abs(clip.displacements).max(axis=(1, 2)).argmax()), clip.n_frames - 2)  # the widest pose
    for t in (clip.times[key], 0.5 * (clip.times[key] + clip.times[key + 1])):
        d = np.stack([np.interp(t, clip.times, clip.displacements[:, i, a])
                      for i in range(clip.displacements.shape[1]) for a in range(3)]).reshape(-1, 3)
        lbs = rest + skin_displacements(rig, d)
        three = _decoded(page.evaluate("(t) => check.posed(t)", float(t))) / scale
        shaded = _decoded(page.evaluate("(d) => check.shaded(d)",
                                        base64.b64encode(d.astype("<f4").tobytes()).decode()))
        moved = float(np.abs(lbs - rest).max()) / size
        three_lbs = float(np.abs(three - lbs).max()) / size
        three_shader = float(np.abs(three - shaded).max()) / size
        print(f"{rig.n_influences} influences, t = {t:.4f} s: |three.js - LBS| = {three_lbs:.1e}, "
              f"|three.js - shader| = {three_shader:.1e} of the mesh size (moved up to {moved:.3f})")
        assert moved > 0.01, "the frame barely moves the face"
        assert three_lbs < TOLERANCE and three_shader < TOLERANCE
    return loaded


def test_three_js_plays_the_export_as_our_app_draws_it(server, page, sample):
    pid, take = sample
    page.route(server.url + "/three-check", lambda route: route.fulfill(body=PAGE, content_type="text/html"))
    page.goto(server.url + "/three-check")
    page.wait_for_function("window.ready === true")

    # the sample's biharmonic rig has negative weights: morph targets, 3 per feature
    loaded = _three_matches_ours(page, server, pid, take)
    assert not loaded["skinned"] and loaded["morphs"] == 3 * 68 and loaded["vertices"] == 8430

    # an ellipsoid rig is a true skin; three.js reads its one set of four influences
    _rig(server, pid, "ellipsoid")
    glb = server.read(f"/api/projects/{pid}/export.glb")
    attributes = vars(GltfDocument(glb, "export", None).doc.meshes[0].primitives[0].attributes)
    assert attributes["JOINTS_0"] is not None and "JOINTS_1" not in attributes
    loaded = _three_matches_ours(page, server, pid, take)
    assert loaded["skinned"] and loaded["morphs"] == 0
    assert loaded["skinAttributes"] == ["skinIndex", "skinWeight"]

    # the muscles: morph targets then the jaw joint's skin, as glTF defines them
    url = f"/api/projects/{pid}/export.glb?takes={take['id']}&drive=muscles"
    gltf = GltfDocument(server.read(url), "muscles", None)
    loaded = page.evaluate("(url) => check.load(url)", url)
    assert loaded["skinned"] and loaded["morphs"] == len(gltf.doc.meshes[0].extras["targetNames"]) > 21
    (instance,) = mesh_instances(gltf)
    channels = animation_channels(gltf, gltf.doc.animations[0])
    (keys, weights), = [(c[2], c[3]) for c in channels if c[1] == "weights"]
    key = min(int(np.abs(weights).sum(1).argmax()), len(keys) - 2)   # the widest pose
    rest = instance["positions"].astype(np.float64)
    size = float(np.linalg.norm(rest.max(0) - rest.min(0)))
    for t in (keys[key], 0.5 * (keys[key] + keys[key + 1])):
        at = np.array([t], dtype=np.float64)
        expected = posed_vertices(gltf, instance, np.arange(len(rest)),
                                  node_transforms(gltf, gltf.doc.nodes, channels, at),
                                  animated_weights(gltf, channels, at), at)[0]
        three = _decoded(page.evaluate("(t) => check.posed(t)", float(t)))
        print(f"muscles, t = {t:.4f} s: |three.js - glTF| = {np.abs(three - expected).max() / size:.1e} "
              f"of the mesh size (moved up to {np.abs(expected - rest).max() / size:.3f})")
        assert np.abs(expected - rest).max() / size > 0.01
        assert np.abs(three - expected).max() / size < TOLERANCE


def test_three_js_plays_the_arkit_export(server, page):
    """The library's ARKit export of the sample face (served as a file): three.js names its 52
    morph targets after ARKit, reads the sparse accessors, and draws the shapes posed by the
    weights at a key and between keys."""
    f = sample_face()
    points = from_vertex_indices(f.landmarks68, len(f.vertices), "ibug68")
    rig = compute_weights("ellipsoid", f.vertices, f.faces, points, get_layout("ibug68"))
    shapes = arkit_shapes(f.vertices, f.faces, points, "ibug68", rig)
    weights = np.zeros((3, 52))
    weights[1, [ARKIT_NAMES.index(n) for n in ("jawOpen", "mouthSmileLeft", "eyeBlinkRight")]] = [0.8, 0.6, 1.0]
    weights[2, ARKIT_NAMES.index("browInnerUp")] = 0.7
    data = export_arkit_gltf(mesh_from_arrays(f.vertices, f.faces), shapes,
                             [ArkitClip.at_rate("arkit", weights, FPS)], units="keep")
    page.route(server.url + "/three-check", lambda route: route.fulfill(body=PAGE, content_type="text/html"))
    page.route(server.url + "/arkit.glb", lambda route: route.fulfill(body=data, content_type="model/gltf-binary"))
    page.goto(server.url + "/three-check")
    page.wait_for_function("window.ready === true")
    loaded = page.evaluate("(url) => check.load(url)", "/arkit.glb")
    assert not loaded["skinned"] and loaded["morphs"] == 52 and loaded["morphNames"] == list(ARKIT_NAMES)
    size = float(np.linalg.norm(np.ptp(f.vertices, axis=0)))
    for frame in (1.0, 1.5):
        w = np.array([np.interp(frame, np.arange(3), weights[:, k]) for k in range(52)])
        expected = shapes.posed(f.vertices, w)
        three = _decoded(page.evaluate("(t) => check.posed(t)", frame / FPS))
        bound = arkit_tolerance(f.vertices) * w.sum() + 1e-5 * size
        print(f"ARKit, frame {frame}: |three.js - posed| = {np.abs(three - expected).max() / size:.1e} of the "
              f"mesh size (bound {bound / size:.1e}, moved up to {np.abs(expected - f.vertices).max() / size:.3f})")
        assert np.abs(three - expected).max() < bound
        assert np.abs(expected - f.vertices).max() > 0.03 * size


def test_three_js_turns_the_head_as_our_app_does(server, page, sample):
    """'Turn the head' (issue 19): the server's export of a take whose performer turns the
    head, with apply_rotation, played by three.js at its keys, against our app's viewer (the
    shader's positions through the face mesh's matrix that `SkinnedFace.setHeadRotation`
    sets) on the project's rig with the take's displacements and streamed quaternion."""
    from tests.unit.test_export_head import turning_take

    pid, _ = sample
    take, _ = turning_take(20)
    buffer = io.BytesIO()
    np.save(buffer, take.points)
    r = httpx.post(f"{server.url}/api/projects/{pid}/takes", timeout=30,
                   files={"file": ("turn.npy", buffer.getvalue())}, data={"layout": "ibug68", "fps": str(FPS)})
    assert r.status_code == 201, r.text
    settings = '{"neutral": {"mode": "frame", "frame": 0}, "apply_rotation": true}'
    url = f"/api/projects/{pid}/export.glb?takes={r.json()['id']}&settings={urllib.parse.quote(settings)}"
    data = server.read(url)
    clip, scale = read_gltf(data).clips[0], _file_scale(data)
    page.route(server.url + "/three-check", lambda route: route.fulfill(body=PAGE, content_type="text/html"))
    page.route(server.url + "/turn.glb", lambda route: route.fulfill(body=data, content_type="model/gltf-binary"))
    page.goto(server.url + "/three-check")
    page.wait_for_function("window.ready === true")
    page.evaluate("(url) => check.load(url)", "/turn.glb")
    page.evaluate("(id) => check.loadFace(id)", pid)
    rest = _rest(server, pid)
    size = float(np.linalg.norm(rest.max(0) - rest.min(0)))
    for k in (5, 12, 19):
        d = base64.b64encode(clip.displacements[k].astype("<f4").tobytes()).decode()
        three = _decoded(page.evaluate("(t) => check.posed(t)", float(clip.times[k]))) / scale
        app = _decoded(page.evaluate("([d, q]) => check.turned(d, q)", [d, clip.head_rotations[k].tolist()]))
        still = _decoded(page.evaluate("(d) => check.shaded(d)", d))
        error, turned = np.abs(three - app).max() / size, np.abs(app - still).max() / size
        print(f"head motion, frame {k}: |three.js - app| = {error:.1e} of the mesh size (turned up to {turned:.3f})")
        assert error < TOLERANCE and turned > 0.02


def test_the_mesh_unit_is_shown_changed_and_exported_in(server, page, sample, tmp_path):
    """The header shows the mesh's unit (the sample: cm) with a select; a change is saved to
    the project's settings, and the Export panel's *Units* downloads metres from it or the
    mesh's own numbers."""
    pid, _ = sample
    open_project(page, server, pid)
    assert page.is_visible("#mesh-units") and page.input_value("#mesh-units") == "cm"
    page.select_option("#mesh-units", "mm")
    page.wait_for_function("(id) => window.app.project.settings.mesh_units === 'mm'", arg=pid)
    assert server.api("GET", f"/api/projects/{pid}")["settings"]["mesh_units"] == "mm"
    top = sample_face(1).vertices.max(0)
    for units, scale in (("m", 0.001), ("keep", 1.0)):
        page.select_option("#export-units", units)
        with page.expect_download() as download:
            page.click("#export-gltf")
        download.value.save_as(tmp_path / f"{units}.glb")
        gltf = GltfDocument((tmp_path / f"{units}.glb").read_bytes(), units, None)
        position = gltf.doc.accessors[gltf.doc.meshes[0].primitives[0].attributes.POSITION]
        np.testing.assert_allclose(position.max, scale * top, rtol=1e-6)
    page.select_option("#mesh-units", "cm")
    page.select_option("#export-units", "m")
    page.wait_for_function("() => window.app.project.settings.mesh_units === 'cm'")


def test_export_panel_downloads_and_imports(server, page, sample, tmp_path):
    """Export glTF with a ticked take downloads what the server exports for the panel's
    conditioning; Import .glb makes and opens a project with the same mesh, landmarks and
    rig; refusals show the server's reason."""
    pid, take = sample
    open_project(page, server, pid)
    page.wait_for_function("() => window.app.face && window.app.face.nJoints === 68", timeout=scaled_ms(30_000))
    box = page.locator(f"#export-takes input[data-take='{take['id']}']")
    box.check()
    with page.expect_download() as download:
        page.click("#export-gltf")
    assert download.value.suggested_filename == "Sample-face.glb"
    path = tmp_path / "exported.glb"
    download.value.save_as(path)
    page.wait_for_function("() => document.getElementById('export-note').textContent.startsWith('Saved')")
    assert "Sample-face.glb" in page.inner_text("#export-note") and "1 animation" in page.inner_text("#export-note")
    settings = page.evaluate("() => JSON.stringify(window.app.sources.settings())")
    expected = httpx.get(f"{server.url}/api/projects/{pid}/export.glb", timeout=60,
                         params={"takes": take["id"], "settings": settings}).content
    assert path.read_bytes() == expected
    (clip,) = read_gltf(path).clips
    assert clip.name == take["name"] and np.abs(clip.displacements).max() > 0.1
    # the whole take at its own times, the neutral window's frames included (issue 13 item 3)
    assert clip.n_frames == take["n_frames"] == 45
    np.testing.assert_allclose(clip.times, np.arange(45) / FPS, atol=1e-6)

    # import: a new project, opened, with the exported mesh, landmarks and rig
    before = {p["id"] for p in server.api("GET", "/api/projects")}
    page.set_input_files("#import-file", str(path))
    page.wait_for_function("(id) => window.app.projectId && window.app.projectId !== id "
                           "&& window.app.face && window.app.face.nJoints === 68", arg=pid, timeout=scaled_ms(30_000))
    page.evaluate("() => window.app.ready")
    new = page.evaluate("() => window.app.projectId")
    assert new not in before and page.input_value("#project-name") == "exported"
    assert "Its 1 animation was not imported" in page.inner_text("#export-note")
    np.testing.assert_allclose(_rest(server, new), _rest(server, pid), rtol=2.4e-7)  # through metres
    assert server.api("GET", f"/api/projects/{new}/landmarks") == server.api("GET", f"/api/projects/{pid}/landmarks")
    np.testing.assert_allclose(_server_rig(server, new).dense(), _server_rig(server, pid).dense(), atol=1e-6)

    # refusals: the server's reason in the panel and the banner, no project made
    page.set_input_files("#import-file", files=[{"name": "bad.glb", "mimeType": "model/gltf-binary",
                                                 "buffer": b"solid not a glb"}])
    reason = "'bad.glb' cannot be imported (only a .glb exported by this app can): the file is not a GLB file"
    page.wait_for_function("(r) => document.getElementById('export-note').textContent.includes(r)", arg=reason)
    assert reason in page.inner_text("#error")
    page.evaluate("() => window.app.errors.clear()")
    empty = server.api("POST", "/api/projects", {"name": "empty"})["id"]
    assert {p["id"] for p in server.api("GET", "/api/projects")} == before | {new, empty}
    open_project(page, server, empty)
    page.click("#export-gltf")
    page.wait_for_function("() => document.getElementById('export-note').textContent.includes('has no mesh yet')")
    assert "has no mesh yet" in page.inner_text("#error")


def test_the_four_joint_skin_export_from_the_panel_plays_in_three_js(server, page, sample, tmp_path):
    """Rig as four-joint skin, keys at 24 fps reduced to 0.05 mm: the panel downloads what the
    server exports with those options and says the fit's error; stock three.js plays the file
    (one skinIndex/skinWeight set) as glTF defines it, at a key and between keys."""
    pid, take = sample
    open_project(page, server, pid)
    page.wait_for_function("() => window.app.face && window.app.face.nJoints === 68", timeout=scaled_ms(30_000))
    page.locator(f"#export-takes input[data-take='{take['id']}']").check()
    page.select_option("#export-form", "skin")
    page.select_option("#export-rate", "24")
    page.fill("#export-key-tolerance", "0.05")
    with page.expect_download() as download:
        page.click("#export-gltf")
    path = tmp_path / "skin.glb"
    download.value.save_as(path)
    page.wait_for_function("() => document.getElementById('export-note').textContent.startsWith('Saved')")
    settings = page.evaluate("() => JSON.stringify(window.app.sources.settings())")
    params = {"takes": take["id"], "settings": settings, "form": "skin", "rate": "24", "key_tolerance": "0.05"}
    r = httpx.get(f"{server.url}/api/projects/{pid}/export.glb", timeout=60, params=params)
    assert path.read_bytes() == r.content
    fit = json.loads(r.headers["x-retarget-fit"])
    assert (f"four-joint skin: {100 * fit['rms_relative']:.1f} % RMS error ({fit['rms_mm']:.2f} mm), "
            f"worst vertex {fit['worst_vertex_mm']:.2f} mm") in page.inner_text("#export-note")

    page.route(server.url + "/three-check", lambda route: route.fulfill(body=PAGE, content_type="text/html"))
    page.goto(server.url + "/three-check")
    page.wait_for_function("window.ready === true")
    url = f"/api/projects/{pid}/export.glb?{urllib.parse.urlencode(params)}"
    loaded = page.evaluate("(url) => check.load(url)", url)
    assert loaded["skinned"] and loaded["morphs"] == 0 and loaded["skinAttributes"] == ["skinIndex", "skinWeight"]
    gltf = GltfDocument(r.content, "skin", None)
    rest = mesh_instances(gltf)[0]["positions"].astype(np.float64)
    size = float(np.linalg.norm(rest.max(0) - rest.min(0)))
    clip = read_gltf(r.content).clips[0]
    key = min(int(np.abs(clip.displacements).max(axis=(1, 2)).argmax()), clip.n_frames - 2)
    for t in (clip.times[key], 0.5 * (clip.times[key] + clip.times[key + 1])):
        expected = drawn_vertices(gltf, [t])[0]
        three = _decoded(page.evaluate("(t) => check.posed(t)", float(t)))
        assert np.abs(expected - rest).max() / size > 0.01
        assert np.abs(three - expected).max() / size < TOLERANCE
