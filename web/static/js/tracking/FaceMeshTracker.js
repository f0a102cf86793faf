/**
 * Markerless face tracking in the page: MediaPipe's 468-point face mesh (the npm package
 * `@mediapipe/face_mesh`, served by the app under /vendor, model and wasm included).
 *
 * It tracks the live webcam (webcam.js), where frames never leave the page, and is the
 * reference the native face mesh is checked against (track.html, driven headless by
 * `retarget.sources.markerless`; bench/facemesh.py): video files are tracked by the
 * native one, on the server or by `retarget track`.
 *
 * Landmarks are returned in **pixel units of the frame width**, x right, y UP, z toward the
 * camera, origin at the image's bottom-left corner: MediaPipe's normalised (x, y, z) with y
 * down and z away from the camera become (x w, (1 - y) h, -z w). MediaPipe scales z
 * "roughly like x", hence w for z too.
 */

export const FACE_MESH_POINTS = 468;
const DEFAULT_BASE = '/vendor/@mediapipe/face_mesh/';

const scripts = new Map(); // script URL -> Promise of the global FaceMesh class

/**
 * The package's `FaceMesh` class, loading its classic script once per page.
 * @param {string} base - the package's folder URL, ending in '/'.
 * @returns {Promise<Function>}
 */
function faceMeshClass( base ) {

	const src = base + 'face_mesh.js';
	if ( ! scripts.has( src ) ) {

		scripts.set( src, new Promise( ( resolve, reject ) => {

			if ( typeof window.FaceMesh === 'function' ) return resolve( window.FaceMesh );
			const script = document.createElement( 'script' );
			script.src = src;
			script.onload = () => typeof window.FaceMesh === 'function'
				? resolve( window.FaceMesh )
				: reject( new Error( `FaceMeshTracker: ${ src } loaded but defined no FaceMesh.` ) );
			script.onerror = () => {

				scripts.delete( src ); // let a later init() try again
				reject( new Error( `FaceMeshTracker: could not load ${ src } (are the npm packages installed? npm ci --prefix web).` ) );

			};

			document.head.appendChild( script );

		} ) );

	}

	return scripts.get( src );

}

/**
 * Width and height in pixels of anything MediaPipe accepts as an image.
 * @param {HTMLVideoElement|HTMLImageElement|HTMLCanvasElement|ImageBitmap} image
 * @returns {[number, number]}
 */
function frameSize( image ) {

	if ( typeof HTMLVideoElement !== 'undefined' && image instanceof HTMLVideoElement ) return [ image.videoWidth, image.videoHeight ];
	if ( typeof HTMLImageElement !== 'undefined' && image instanceof HTMLImageElement ) return [ image.naturalWidth, image.naturalHeight ];
	return [ image.width, image.height ];

}

export class FaceMeshTracker {

	/**
	 * @param {{base?: string, minDetectionConfidence?: number, minTrackingConfidence?: number}} [options]
	 *   base: URL of the package folder (default the app's /vendor/@mediapipe/face_mesh/);
	 *   the confidences are MediaPipe's (0.5 each by default).
	 */
	constructor( { base = DEFAULT_BASE, minDetectionConfidence = 0.5, minTrackingConfidence = 0.5 } = {} ) {

		this.base = base.endsWith( '/' ) ? base : base + '/';
		this.options = {
			maxNumFaces: 1,
			refineLandmarks: false, // the 10 iris points are not part of any layout
			minDetectionConfidence,
			minTrackingConfidence,
			selfieMode: false, // x right as in the frame; a mirrored preview is the page's business
		};
		this._mesh = null;
		this._ready = null;
		this._landmarks = null; // the last onResults' first face, or null
		this._queue = Promise.resolve(); // send() calls one after another

	}

	/**
	 * Load the script, the model and the wasm (several MB the first time) and run the
	 * graph once. Calling it again returns the same promise.
	 * @returns {Promise<FaceMeshTracker>}
	 */
	init() {

		if ( this._ready === null ) {

			this._ready = ( async () => {

				const FaceMesh = await faceMeshClass( this.base );
				const mesh = new FaceMesh( { locateFile: ( file ) => this.base + file } );
				mesh.setOptions( this.options );
				mesh.onResults( ( results ) => {

					const faces = results.multiFaceLandmarks;
					this._landmarks = faces && faces.length > 0 ? faces[ 0 ] : null;

				} );
				await mesh.initialize();
				// the first send builds the graph's GPU programs (about 2 s in SwiftShader):
				// done here on a blank frame, so that the first real frame is not late
				const blank = document.createElement( 'canvas' );
				blank.width = blank.height = 64;
				await mesh.send( { image: blank } );
				this._mesh = mesh;
				return this;

			} )();
			this._ready.catch( () => {

				this._ready = null;

			} );

		}

		return this._ready;

	}

	/**
	 * Track one frame. Frames of one sequence should come in order: MediaPipe follows the
	 * face from the previous frame's landmarks and only runs its detector when it lost it.
	 * Calls are queued, so overlapping calls are safe.
	 * @param {HTMLVideoElement|HTMLImageElement|HTMLCanvasElement|ImageBitmap} image
	 * @returns {Promise<Float32Array|null>} (468 * 3) x, y, z per landmark in pixels of the
	 *   frame width (x right, y up, z toward the camera), or null when no face was found.
	 */
	track( image ) {

		const run = this._queue.then( async () => {

			await this.init();
			const [ width, height ] = frameSize( image );
			if ( ! ( width > 0 && height > 0 ) ) throw new Error( 'FaceMeshTracker: the image has no pixels yet (not loaded or not decoded).' );
			this._landmarks = null;
			await this._mesh.send( { image } );
			const landmarks = this._landmarks;
			if ( landmarks === null ) return null;
			const out = new Float32Array( 3 * FACE_MESH_POINTS );
			for ( let i = 0; i < FACE_MESH_POINTS; i ++ ) {

				const p = landmarks[ i ];
				out[ 3 * i ] = p.x * width;
				out[ 3 * i + 1 ] = ( 1 - p.y ) * height;
				out[ 3 * i + 2 ] = - p.z * width;

			}

			return out;

		} );
		this._queue = run.catch( () => {} );
		return run;

	}

	/**
	 * Restart MediaPipe's graph, forgetting the followed face. Rarely needed: when the face
	 * is not where the last frame had it, the tracker notices (low face score) and runs its
	 * detector anyway. Costly: the next frame rebuilds the graph (about 2 s in SwiftShader).
	 */
	reset() {

		if ( this._mesh !== null ) this._mesh.reset();

	}

	/** Release MediaPipe's graph and its WebGL context. */
	async dispose() {

		const ready = this._ready;
		this._ready = null;
		if ( ready === null ) return;
		try {

			await ready;

		} catch {

			return; // it never started; nothing to release

		}

		await this._queue;
		await this._mesh.close();
		this._mesh = null;

	}

	/**
	 * Some of the 468 landmarks, in a given order (a layout's `mediapipe468` indices).
	 * @param {Float32Array} points468 - (468 * 3), as `track` returns.
	 * @param {ArrayLike<number>} indices - (N) face-mesh vertex per output point.
	 * @param {Float32Array} [out] - (N * 3) to fill; a new array by default.
	 * @returns {Float32Array} (N * 3)
	 */
	static pick( points468, indices, out = new Float32Array( 3 * indices.length ) ) {

		for ( let k = 0; k < indices.length; k ++ ) {

			const i = indices[ k ];
			out[ 3 * k ] = points468[ 3 * i ];
			out[ 3 * k + 1 ] = points468[ 3 * i + 1 ];
			out[ 3 * k + 2 ] = points468[ 3 * i + 2 ];

		}

		return out;

	}

}
