import { ArkitShapesDecoder, MeshArraysDecoder, MuscleMorphsDecoder, RigWeightsDecoder, WeightEditEncoder } from './wire.js';

/**
 * The server's REST API (server/routers/*.py), as promise-returning functions; binary
 * bodies go through wire.js.
 *
 * Every failure rejects with an `ApiError` carrying the HTTP status and the server's
 * human `detail`, so the page can show exactly what the server said.
 */

const JOB_POLL_MS = 150;

export class ApiError extends Error {

	/**
	 * @param {number} status - HTTP status; 0 when no answer came (network, aborted).
	 * @param {string} detail - the server's `detail`, or what went wrong on the way.
	 */
	constructor( status, detail ) {

		super( status ? `${ detail } (HTTP ${ status })` : detail );
		this.name = 'ApiError';
		this.status = status;
		this.detail = detail;

	}

}

/**
 * The `detail` of an error answer: FastAPI gives a string, or for request validation a
 * list of {loc, msg}; anything else is shown as text.
 * @param {*} body
 * @param {string} fallback
 * @returns {string}
 */
function detailOf( body, fallback ) {

	const detail = body && body.detail;
	if ( typeof detail === 'string' ) return detail;
	if ( Array.isArray( detail ) ) {

		return detail.map( ( d ) => ( d.loc ? d.loc.filter( ( l ) => l !== 'body' ).join( '.' ) + ': ' : '' ) + d.msg ).join( '; ' );

	}

	return fallback;

}

/**
 * One request; its JSON answer (binary: its bytes; raw: the Response; 204: null).
 * @param {{json?: *, body?: ArrayBuffer, contentType?: string, binary?: boolean,
 *   keepalive?: boolean, raw?: boolean}} [options] - json: a JSON body; body: bytes of
 *   `contentType` (json wins); keepalive: the request outlives the page (unload).
 */
async function request( method, url, { json, body, contentType, binary = false, keepalive = false, raw = false } = {} ) {

	if ( json !== undefined ) {

		body = JSON.stringify( json );
		contentType = 'application/json';

	}

	let response;
	try {

		response = await fetch( url, {
			method,
			headers: contentType === undefined ? {} : { 'Content-Type': contentType },
			body,
			keepalive,
		} );

	} catch ( error ) {

		throw new ApiError( 0, `${ method } ${ url } failed: the server did not answer (${ error.message })` );

	}

	if ( ! response.ok ) {

		const text = await response.text();
		let body = null;
		try {

			body = JSON.parse( text );

		} catch {

			// a proxy's or crash page's HTML: show its status line instead

		}

		throw new ApiError( response.status, detailOf( body, `${ method } ${ url }: ${ response.statusText || 'request failed' }` ) );

	}

	if ( raw ) return response;
	if ( response.status === 204 ) return null;
	return binary ? response.arrayBuffer() : response.json();

}

export const api = {

	/**
	 * What the server accepts.
	 * @returns {Promise<{version: string, max_upload_bytes: number, max_vertices: number,
	 *   mesh_extensions: string[], rig_methods: string[], default_rig_method: string}>}
	 */
	info: () => request( 'GET', '/api/info' ),

	/** @returns {Promise<Array<object>>} every project, oldest first */
	projects: () => request( 'GET', '/api/projects' ),

	project: ( id ) => request( 'GET', `/api/projects/${ id }` ),

	createProject: ( name ) => request( 'POST', '/api/projects', { json: { name } } ),

	/**
	 * @param {string} id
	 * @param {{name?: string, settings?: object}} patch
	 * @param {{keepalive?: boolean}} [options] - keepalive: the request outlives the page (unload).
	 */
	patchProject: ( id, patch, { keepalive = false } = {} ) => request( 'PATCH', `/api/projects/${ id }`, { json: patch, keepalive } ),

	deleteProject: ( id ) => request( 'DELETE', `/api/projects/${ id }` ),

	/** @returns {Promise<Array<object>>} layouts with points {name, region, side, mirror, reference} */
	layouts: () => request( 'GET', '/api/layouts' ),

	/**
	 * The built-in layouts and the project's custom ones (those with `custom: true`,
	 * `saved_as`, `spec`; a point with no reference position has `reference: null`).
	 * @returns {Promise<Array<object>>}
	 */
	projectLayouts: ( id ) => request( 'GET', `/api/projects/${ id }/layouts` ),

	/**
	 * Save a custom layout (its spec: {description, points: [{name, region, side, mirror?, anchor?}]}) as `name`.
	 * @returns {Promise<object>} the layout as GET lists it; refused (422) with the reason.
	 */
	putLayout: ( id, name, spec ) => request( 'PUT', `/api/projects/${ id }/layouts/${ encodeURIComponent( name ) }`, { json: spec } ),

	/** @returns {Promise<{take: string, names: string[]}>} a take's marker names, in its order. */
	takeMarkers: ( id, takeId ) => request( 'GET', `/api/projects/${ id }/layouts/from-take/${ encodeURIComponent( takeId ) }` ),

	/**
	 * Where each marker of a take tracked from a ring-marker video is on its first frame
	 * (x, y in the video's pixels, y down; null when not seen there); 404 for other takes.
	 * @returns {Promise<{size: number[], markers: Array<{name: string, x: number|null, y: number|null}>}>}
	 */
	takePreviewMarkers: ( id, takeId ) => request( 'GET', `/api/projects/${ id }/takes/${ encodeURIComponent( takeId ) }/preview/markers` ),

	/** @returns {string} the URL of that take's first frame (a JPEG at most 640 px wide). */
	takePreviewUrl: ( id, takeId ) => `/api/projects/${ id }/takes/${ encodeURIComponent( takeId ) }/preview`,

	/**
	 * A take file's marker names, read by the server and not stored (a take of markers no
	 * layout of the project has yet is refused as a take).
	 * @returns {Promise<{take: null, names: string[]}>}
	 */
	takeFileMarkers: ( id, file ) => upload( 'POST', `/api/projects/${ id }/layouts/from-take`, file, { fps: '30' } ),

	/**
	 * The mesh as arrays (the "RTMA" format of server/wire.py).
	 * @returns {Promise<{positions: Float32Array, faces: Uint32Array, uv: Float32Array|null, textured: boolean}>}
	 *   positions (3V) in the mesh's own units; faces (3F) vertex indices; uv (2V) or null;
	 *   textured: `meshTexture` has an image for it.
	 */
	async meshArrays( id ) {

		return new MeshArraysDecoder().decode( await request( 'GET', `/api/projects/${ id }/mesh/arrays`, { binary: true } ) );

	},

	/**
	 * The mesh's base-colour texture (GET .../mesh/texture, a PNG), flipped so its first
	 * row is at v = 0 as WebGL samples it with OBJ-convention uv.
	 * @returns {Promise<ImageBitmap>}
	 */
	async meshTexture( id ) {

		const response = await request( 'GET', `/api/projects/${ id }/mesh/texture`, { raw: true } );
		return createImageBitmap( await response.blob(), { imageOrientation: 'flipY' } );

	},

	/** @returns {Promise<{layout: string, triangles: number[][], barycentric: number[][]}>} */
	landmarks: ( id ) => request( 'GET', `/api/projects/${ id }/landmarks` ),

	/** @param {{layout: string, triangles: number[][], barycentric: number[][]}} landmarks */
	putLandmarks: ( id, landmarks ) => request( 'PUT', `/api/projects/${ id }/landmarks`, { json: landmarks } ),

	/**
	 * Find the layout's points on the mesh with no clicks (a server job).
	 * @param {{layout?: string, replace?: boolean}} options - replace: even over points placed by hand.
	 * @returns {Promise<object>} the job; its result {saved, layout, n_points, check, presence, reason}
	 */
	findLandmarks: ( id, options ) => request( 'POST', `/api/projects/${ id }/landmarks/find`, { json: options } ),

	/** @returns {Promise<object>} the job {id, state, progress, detail, result} */
	startRig: ( id, method ) => request( 'POST', `/api/projects/${ id }/rig`, { json: { method } } ),

	job: ( jobId ) => request( 'GET', `/api/jobs/${ jobId }` ),

	/**
	 * Follow a job (a rig, a tracked video) until it ends.
	 * @param {string} jobId
	 * @param {(job: {state: string, progress: number, detail: string}) => void} [onProgress] -
	 *   called with every answer, the last one included.
	 * @param {{what?: string, signal?: AbortSignal}} [options] - what: the job's name for the
	 *   failure's message ("<what> failed: <detail>"); signal: stop following (rejects with
	 *   the signal's reason).
	 * @returns {Promise<{state: 'done', progress: number, detail: string, result: object}>}
	 *   the done job: `detail` a sentence, `result` what it made (a rig: {method, n_joints,
	 *   n_influences}; a tracked take: {take, frames[, truncated, frames_claimed]}).
	 */
	async waitJob( jobId, onProgress, { what = 'The job', signal } = {} ) {

		for ( ;; ) {

			signal?.throwIfAborted();
			const job = await request( 'GET', `/api/jobs/${ jobId }` );
			signal?.throwIfAborted();
			onProgress?.( job );
			if ( job.state === 'done' ) return job;
			if ( job.state !== 'running' ) throw new ApiError( 0, `${ what } failed: ${ job.detail || 'no reason given' }` );
			await new Promise( ( resolve ) => setTimeout( resolve, JOB_POLL_MS ) );

		}

	},

	/** @returns {Promise<{method: string, n_vertices: number, n_joints: number, n_influences: number}>} */
	rig: ( id ) => request( 'GET', `/api/projects/${ id }/rig` ),

	/**
	 * The project's ARKit shapes' state and the user's settings (GET .../arkit):
	 * {names, state: 'missing'|'stale'|'ready', made_on, settings: {rig, gains, masks},
	 * max_gain, rigs, job}.
	 */
	arkit: ( id ) => request( 'GET', `/api/projects/${ id }/arkit` ),

	/** Save the ARKit settings {rig, gains, masks} (PUT .../arkit); answers as GET does. */
	putArkit: ( id, settings, { keepalive = false } = {} ) => request( 'PUT', `/api/projects/${ id }/arkit`, { json: settings, keepalive } ),

	/** Make the 52 shapes again on `rig` (POST .../arkit); answers the job. */
	makeArkit: ( id, rig ) => request( 'POST', `/api/projects/${ id }/arkit`, { json: { rig } } ),

	/**
	 * The project's ARKit shapes (the "RTAK" format of server/wire.py), decoded sparse.
	 * @returns {Promise<{nVertices: number, names: string[], shapes: object[]}>}
	 */
	async arkitShapes( id ) {

		return new ArkitShapesDecoder().decode( await request( 'GET', `/api/projects/${ id }/arkit/shapes`, { binary: true } ) );

	},

	/**
	 * The project's muscles as geometry (GET .../muscles: `MuscleFace.to_json` plus names,
	 * limits and whether the user saved them), placed from the saved landmarks on first need.
	 */
	muscles: ( id ) => request( 'GET', `/api/projects/${ id }/muscles` ),

	/** Save edited muscle geometry (PUT .../muscles); answers it as GET does. */
	putMuscles: ( id, muscles ) => request( 'PUT', `/api/projects/${ id }/muscles`, { json: muscles } ),

	/**
	 * The project's muscles as the page plays them (the "RTMM" format of server/wire.py),
	 * placed from the saved landmarks the first time they are asked for.
	 * @returns {Promise<{nVertices: number, nTargets: number, header: object, targets: Float32Array, jawWeights: Float32Array}>}
	 */
	async musclesPlayed( id ) {

		return new MuscleMorphsDecoder().decode( await request( 'GET', `/api/projects/${ id }/muscles/played`, { binary: true } ) );

	},

	/**
	 * The rig's skin weights (the "RTSW" format of server/wire.py, version 2: 20 bits a weight,
	 * within 2^-20 of the largest weight, gzip-encoded on the way).
	 * @returns {Promise<{nJoints: number, nInfluences: number, indices: Uint16Array, weights: Float32Array}>}
	 *   indices and weights are (V, k) row-major.
	 */
	async rigWeights( id ) {

		return new RigWeightsDecoder().decode( await request( 'GET', `/api/projects/${ id }/rig/weights?version=2`, { binary: true } ) );

	},

	/**
	 * Paint rows of the rig's skin weights (PATCH .../rig/weights, the binary "RTSE" edit
	 * of server/wire.py); the server refuses rows painted on an older version.
	 * @param {string} id
	 * @param {{version: number, nJoints: number, nInfluences: number}} rig - the rig the rows were painted on.
	 * @param {Int32Array} vertices - (R) the vertices whose rows change.
	 * @param {{indices: Uint16Array, weights: Float32Array}} rows - (R, k) row-major each.
	 * @param {{keepalive?: boolean}} [options] - keepalive: the page is being unloaded.
	 * @returns {Promise<object>} the rig's info (GET .../rig), with its new version
	 */
	patchRigWeights: ( id, rig, vertices, rows, { keepalive = false } = {} ) => request( 'PATCH', `/api/projects/${ id }/rig/weights`, {
		body: new WeightEditEncoder().encode( rig.version, rig.nJoints, rig.nInfluences, vertices, rows ), contentType: 'application/octet-stream', keepalive,
	} ),

	/**
	 * Paint joints back to the automatic rig's weights.
	 * @param {number[]|null} joints - null: every joint (the automatic rig again).
	 * @param {number} version - the rig version the page shows.
	 * @returns {Promise<object>} the rig's info (GET .../rig), with its new version
	 */
	resetRigWeights: ( id, joints, version ) => request( 'POST', `/api/projects/${ id }/rig/reset`, { json: { joints, version } } ),

	/**
	 * Upload a mesh file with progress.
	 * @param {string} id
	 * @param {File} file
	 * @param {(fraction: number) => void} onProgress - 0..1 of the bytes sent
	 * @returns {Promise<object>} the updated project
	 */
	/**
	 * Upload a mesh file with the files it refers to (an OBJ's MTL and images, a glTF's
	 * buffers), with progress.
	 * @param {File} file - the mesh, or a zip of it and its files.
	 * @param {(fraction: number) => void} [onProgress]
	 * @param {File[]} [sideFiles] - sent as the `files` field.
	 * @returns {Promise<object>} the project
	 */
	uploadMesh: ( id, file, onProgress, sideFiles = [] ) => upload( 'PUT', `/api/projects/${ id }/mesh`, file, { files: sideFiles }, onProgress ),

	/**
	 * Whether the mesh's lips are one surface, found from the saved landmarks.
	 * @returns {Promise<{joined: boolean|null, detail: string}>}
	 */
	lips: ( id ) => request( 'GET', `/api/projects/${ id }/mesh/lips` ),

	/** Cut the mesh open along the lip contact line (a new mesh revision); the project. */
	openMouth: ( id ) => request( 'POST', `/api/projects/${ id }/mesh/open-mouth` ),

	/** Go back to the mesh and landmarks before the mouth was opened; the project. */
	revertMesh: ( id ) => request( 'POST', `/api/projects/${ id }/mesh/revert` ),

	/** @returns {Promise<Array<object>>} takes {id, name, source, layout, fps, n_frames, n_points, dims, duration, trim}, oldest first */
	takes: ( id ) => request( 'GET', `/api/projects/${ id }/takes` ),

	/**
	 * Upload a take file (csv, json, npy, trc, c3d, glb, gltf, zip) with progress. When no
	 * answer comes it is sent once more with the same Idempotency-Key, so a take stored by
	 * the first try whose answer was lost is answered, not stored twice.
	 * @param {Object<string, string>} fields - optional form fields: name, fps, layout, mapping, labelled_vertices, source.
	 * @returns {Promise<object>} the stored take's info
	 */
	uploadTake: async ( id, file, fields, onProgress ) => {

		// a retry after a lost answer sends the same key, so the take is stored once
		const key = uploadKey();
		const send = () => upload( 'POST', `/api/projects/${ id }/takes`, file, fields, onProgress, { 'Idempotency-Key': key } );
		try {

			return await send();

		} catch ( error ) {

			if ( error.status !== 0 || error.cancelled ) throw error;
			return send();

		}

	},

	/**
	 * Upload a video of a face or of ring markers; the server tracks it in a job.
	 * @param {Object<string, string>} fields - method ('markerless' or 'markers'), layout, name.
	 * @returns {Promise<object>} the job
	 */
	trackVideo: ( id, file, fields, onProgress ) => upload( 'POST', `/api/projects/${ id }/takes/track`, file, fields, onProgress ),

	/**
	 * Upload a stereo pair of colour-marker videos and their calibration; the server checks
	 * them (and calibrates from checkerboard videos) before it answers, then tracks in a job.
	 * @param {File} left - the left camera's video
	 * @param {Object<string, File|string>} fields - right (File), and calibration (.npz File)
	 *   or calibration_left, calibration_right (Files) with cols, rows, square (mm); name.
	 * @returns {Promise<object>} the job, with calibration {source, rms, baseline, size, views}
	 */
	trackStereo: ( id, left, fields, onProgress ) => upload( 'POST', `/api/projects/${ id }/takes/track`, left, { ...fields, method: 'stereo' }, onProgress ),

	/** @param {{name?: string, trim?: [number, number|null]}} patch */
	patchTake: ( id, takeId, patch ) => request( 'PATCH', `/api/projects/${ id }/takes/${ takeId }`, { json: patch } ),

	deleteTake: ( id, takeId ) => request( 'DELETE', `/api/projects/${ id }/takes/${ takeId }` ),

	/** URL of the trimmed take's (F, N, D) float32 .npy */
	takePointsUrl: ( id, takeId ) => `/api/projects/${ id }/takes/${ takeId }/points`,

	/** URL of a stereo take's calibration (.npz, as `retarget calibrate` writes it) */
	takeCalibrationUrl: ( id, takeId ) => `/api/projects/${ id }/takes/${ takeId }/calibration`,

	/**
	 * The project as a glTF binary (server/routers/exports.py), its takes as animations.
	 * @param {{takes?: string, settings?: object|null, regions?: string[]|null, drive?: string,
	 *   units?: string, form?: string, rate?: string, keyTolerance?: number}} [options] -
	 *   takes: ids joined by commas, or 'all'; settings: ConditionSettings JSON; regions: the
	 *   regions that move (null: all); drive: 'points' (the rig), 'muscles' (a morph target
	 *   per muscle and a jaw joint) or 'arkit'; units: 'm' or 'keep'; form: 'exact' or 'skin'
	 *   (four influences a vertex, fitted); rate: '' (the takes' frames) or '24', '25', '30',
	 *   '60'; keyTolerance: millimetres (0 keeps every key).
	 * @returns {Promise<{blob: Blob, filename: string, fit: object|null}>} the file, the
	 *   server's name for it and, for the skin form, its fit's error (X-Retarget-Fit)
	 */
	async exportGltf( id, { takes = '', settings = null, regions = null, drive = 'points', units = 'm', form = 'exact', rate = '', keyTolerance = 0 } = {} ) {

		const query = new URLSearchParams( { takes, drive, units, form, rate, key_tolerance: keyTolerance } );
		if ( settings ) query.set( 'settings', JSON.stringify( settings ) );
		if ( regions ) query.set( 'regions', regions.join( ',' ) );
		const response = await request( 'GET', `/api/projects/${ id }/export.glb?${ query }`, { raw: true } );
		const disposition = response.headers.get( 'Content-Disposition' ) ?? '';
		const fit = response.headers.get( 'X-Retarget-Fit' );
		return { blob: await response.blob(), filename: /filename="([^"]+)"/.exec( disposition )?.[ 1 ] ?? 'project.glb',
			fit: fit ? JSON.parse( fit ) : null };

	},

	/**
	 * A project and its takes as a batch for `retarget batch` (GET .../manifest.zip): the
	 * project as an exported .glb, its takes with `settings` (ConditionSettings), a manifest.json.
	 * @returns {Promise<{blob: Blob, filename: string}>}
	 */
	async exportManifest( id, { settings = null, outputs = 'gltf,arkit_csv,npy' } = {} ) {

		const query = new URLSearchParams( { outputs } );
		if ( settings ) query.set( 'settings', JSON.stringify( settings ) );
		const response = await request( 'GET', `/api/projects/${ id }/manifest.zip?${ query }`, { raw: true } );
		const disposition = response.headers.get( 'Content-Disposition' ) ?? '';
		return { blob: await response.blob(), filename: /filename="([^"]+)"/.exec( disposition )?.[ 1 ] ?? 'project.manifest.zip' };

	},

	/**
	 * Upload a .glb exported by this app as a new project, with progress.
	 * @returns {Promise<{project: object, deformation: string, animations: string[]}>}
	 */
	importProject: ( file, onProgress ) => upload( 'POST', '/api/projects/import', file, {}, onProgress ),

};

/**
 * A fresh Idempotency-Key: 128 random bits as hex (crypto.getRandomValues, which pages
 * served over plain http on a LAN address have too, unlike crypto.randomUUID).
 * @returns {string}
 */
function uploadKey() {

	return Array.from( crypto.getRandomValues( new Uint8Array( 16 ) ), ( b ) => b.toString( 16 ).padStart( 2, '0' ) ).join( '' );

}

/**
 * A multipart upload (field "file" plus `fields`, whose Files, or arrays of them, go as
 * files) with progress; XHR because fetch reports no upload progress.
 * @param {Object<string, string>} [headers] - extra request headers
 * @returns {Promise<object>} the JSON answer
 */
function upload( method, url, file, fields, onProgress, headers = {} ) {

	return new Promise( ( resolve, reject ) => {

		const xhr = new XMLHttpRequest();
		xhr.open( method, url );
		for ( const [ name, value ] of Object.entries( headers ) ) xhr.setRequestHeader( name, value );
		xhr.responseType = 'text';
		xhr.upload.onprogress = ( event ) => {

			if ( event.lengthComputable && onProgress ) onProgress( event.loaded / event.total );

		};

		xhr.onload = () => {

			let body = null;
			try {

				body = JSON.parse( xhr.responseText );

			} catch {

				// not JSON: reported by status below

			}

			if ( xhr.status >= 200 && xhr.status < 300 ) resolve( body );
			else reject( new ApiError( xhr.status, detailOf( body, `upload of ${ file.name } failed: ${ xhr.statusText }` ) ) );

		};

		// the server closes early on an oversized body, which browsers may report as a
		// network error rather than the 413 it sent
		xhr.onerror = () => reject( new ApiError( 0, `upload of ${ file.name } failed: the connection was closed (is the file over the server's size limit?)` ) );
		xhr.onabort = () => reject( Object.assign( new ApiError( 0, `upload of ${ file.name } was cancelled` ), { cancelled: true } ) );
		const form = new FormData();
		form.append( 'file', file, file.name );
		for ( const [ key, value ] of Object.entries( fields ?? {} ) ) {

			if ( Array.isArray( value ) ) for ( const item of value ) form.append( key, item, item.name );
			else if ( value instanceof Blob ) form.append( key, value, value.name );
			else if ( value !== undefined && value !== null && value !== '' ) form.append( key, String( value ) );

		}

		xhr.send( form );

	} );

}
