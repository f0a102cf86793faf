/**
 * Two cameras for live stereo (Woodward et al.'s two webcams): each camera into a <video>,
 * and on demand the current frame pair as two JPEGs, which the server decodes, tracks and
 * triangulates (the page does no stereo maths).
 *
 * Two devices, or one device "split": a single camera whose frame holds both views side
 * by side (the left half is the left camera) or one above the other (the top half is the
 * left camera), as a stereo webcam delivers them, or a test's fake camera playing a
 * rendered pair.
 *
 * The JPEGs are encoded in a module worker (jpegWorker.js: the frames travel as
 * ImageBitmaps, drawn to an OffscreenCanvas there), not on the page's main thread, where
 * a canvas's toBlob encodes in the idle time the page's rendering leaves (Chromium). In
 * Chromium on SwiftShader most of a pair's time (about 80 ms of 90 on a loaded 2-core
 * machine) is the read-back of the video frame from the (software) GPU, which the worker
 * waits for instead of the page; the encoding itself takes a few ms. No main-thread
 * fallback: every browser the app runs in has OffscreenCanvas with a 2D context and module
 * workers (Chrome 80, Firefox 114, Safari 16.4), and a fallback would be code no test runs.
 */

/** Frame pairs the worker encodes at once at most; `grab` refuses more (drop, don't queue). */
export const MAX_ENCODING = 2;

/**
 * The video inputs the browser offers, [{deviceId, label}] (labels are empty until the
 * user allowed a camera once).
 * @returns {Promise<{deviceId: string, label: string}[]>}
 */
export async function videoInputs() {

	if ( ! navigator.mediaDevices?.enumerateDevices ) throw new Error( 'No camera access here (it needs https or localhost).' );
	const devices = await navigator.mediaDevices.enumerateDevices();
	return devices.filter( ( d ) => d.kind === 'videoinput' ).map( ( d ) => ( { deviceId: d.deviceId, label: d.label } ) );

}

export class StereoCapture {

	/**
	 * @param {HTMLVideoElement[]} videos - [left, right] elements that show the cameras (the
	 *   right one stays empty in split mode).
	 * @param {object} options
	 * @param {string} options.left - the left camera's deviceId.
	 * @param {string} [options.right] - the right camera's deviceId (two-device mode).
	 * @param {'none'|'side'|'top'} [options.split] - one device holding both views.
	 * @param {number} [options.width] - px of one view asked of each camera.
	 * @param {number} [options.height]
	 */
	constructor( videos, { left, right = '', split = 'none', width = 640, height = 480 } ) {

		this.videos = videos;
		this.devices = split === 'none' ? [ left, right ] : [ left ];
		this.split = split;
		this.width = width;
		this.height = height;
		this.streams = [];
		this.worker = null;
		this.pending = new Map(); // the worker's jobs: id -> {resolve, reject}
		this.jobs = 0;

	}

	/** Open the camera(s) and play them; rejects with getUserMedia's error. */
	async open() {

		if ( typeof OffscreenCanvas === 'undefined' || ! OffscreenCanvas.prototype.convertToBlob ) {

			throw new Error( 'This browser cannot encode camera frames in a worker (no OffscreenCanvas): live stereo needs a current Chrome, Edge, Firefox or Safari.' );

		}

		for ( const [ i, deviceId ] of this.devices.entries() ) {

			const wide = this.split === 'side' ? 2 : 1, tall = this.split === 'top' ? 2 : 1;
			const stream = await navigator.mediaDevices.getUserMedia( { audio: false, video: {
				deviceId: deviceId ? { exact: deviceId } : undefined, width: this.width * wide, height: this.height * tall } } );
			this.streams.push( stream );
			const video = this.videos[ i ];
			video.muted = true;
			video.playsInline = true;
			video.srcObject = stream;
			await video.play();

		}

	}

	/** Stop the cameras (idempotent). */
	close() {

		for ( const stream of this.streams ) stream.getTracks().forEach( ( track ) => track.stop() );
		this.streams = [];
		for ( const video of this.videos ) video.srcObject = null;
		// the pairs being encoded still come (a grab begun before close ends as before it)
		const worker = this.worker;
		this.worker = null;
		Promise.allSettled( [ ...this.pending.values() ].map( ( { job } ) => job ) ).then( () => worker?.terminate() );

	}

	/** (width, height) px of one view: what the server is told for calibration. */
	get size() {

		const video = this.videos[ 0 ];
		const w = video.videoWidth / ( this.split === 'side' ? 2 : 1 ), h = video.videoHeight / ( this.split === 'top' ? 2 : 1 );
		return [ Math.round( w ), Math.round( h ) ];

	}

	/**
	 * The current frame pair as JPEGs, encoded in the worker. At most `MAX_ENCODING` pairs
	 * encode at once: a call beyond rejects at once (the frame is dropped, not queued, so
	 * no backlog builds up; the panel asks for one pair at a time).
	 * @param {number} quality - JPEG quality, 0 to 1.
	 * @returns {Promise<{left: Uint8Array, right: Uint8Array, time: number}>} time: seconds
	 *   since the Unix epoch, when the frames were read.
	 */
	async grab( quality ) {

		if ( ! this.streams.length ) throw new Error( 'The cameras are closed: Open them first.' );
		if ( this.pending.size >= MAX_ENCODING ) throw new Error( `${ MAX_ENCODING } frame pairs are being encoded already; this one was dropped` );
		const worker = this._worker();
		const id = ++ this.jobs;
		let settle;
		const job = new Promise( ( resolve, reject ) => ( settle = { resolve, reject } ) );
		job.catch( () => {} ); // awaited below; not "unhandled" if it fails before that
		this.pending.set( id, { ...settle, job } );
		try {

			const time = Date.now() / 1000;
			const [ w, h ] = this.size;
			let views;
			if ( this.split === 'none' ) {

				const bitmaps = await Promise.all( this.videos.map( ( video ) => createImageBitmap( video ) ) );
				views = bitmaps.map( ( bitmap ) => ( { bitmap, x: 0, y: 0 } ) );

			} else {

				const bitmap = await createImageBitmap( this.videos[ 0 ] ); // both views, cut in the worker
				views = [ { bitmap, x: 0, y: 0 }, { bitmap, x: this.split === 'side' ? w : 0, y: this.split === 'top' ? h : 0 } ];

			}

			if ( ! this.pending.has( id ) ) { // the worker failed meanwhile

				views.forEach( ( view ) => view.bitmap.close() );
				return await job;

			}

			worker.postMessage( { id, quality, width: w, height: h, views }, [ ...new Set( views.map( ( view ) => view.bitmap ) ) ] );
			const [ left, right ] = await job;
			return { left: new Uint8Array( left ), right: new Uint8Array( right ), time };

		} finally {

			this.pending.delete( id );

		}

	}

	_worker() {

		if ( ! this.worker ) {

			const worker = new Worker( new URL( './jpegWorker.js', import.meta.url ), { type: 'module' } );
			this.worker = worker;
			worker.addEventListener( 'message', ( { data } ) => {

				const job = this.pending.get( data.id );
				if ( data.error !== undefined ) job?.reject( new Error( `JPEG encoding failed: ${ data.error }` ) );
				else job?.resolve( data.jpegs );

			} );
			worker.addEventListener( 'error', ( event ) => {

				event.preventDefault();
				worker.terminate();
				if ( this.worker === worker ) this.worker = null; // the next grab starts another
				this._failAll( new Error( `The JPEG encoder stopped: ${ event.message || 'its script did not load' }` ) );

			} );

		}

		return this.worker;

	}

	_failAll( error ) {

		for ( const { reject } of this.pending.values() ) reject( error );
		this.pending.clear();

	}

}
