/**
 * Two cameras for live stereo (Woodward et al.'s two webcams): each camera into a <video>,
 * and on demand the current frame pair as two JPEGs, which the server decodes, tracks and
 * triangulates (the page does no stereo maths).
 *
 * Two devices, or one device "split": a single camera whose frame holds both views side
 * by side (the left half is the left camera) or one above the other (the top half is the
 * left camera), as a stereo webcam delivers them, or a test's fake camera playing a
 * rendered pair.
 */

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
		this.canvas = document.createElement( 'canvas' );

	}

	/** Open the camera(s) and play them; rejects with getUserMedia's error. */
	async open() {

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

	}

	/** (width, height) px of one view: what the server is told for calibration. */
	get size() {

		const video = this.videos[ 0 ];
		const w = video.videoWidth / ( this.split === 'side' ? 2 : 1 ), h = video.videoHeight / ( this.split === 'top' ? 2 : 1 );
		return [ Math.round( w ), Math.round( h ) ];

	}

	/**
	 * The current frame pair as JPEGs.
	 * @param {number} quality - JPEG quality, 0 to 1.
	 * @returns {Promise<{left: Uint8Array, right: Uint8Array, time: number}>} time: seconds
	 *   since the Unix epoch, when the frames were read.
	 */
	async grab( quality ) {

		const time = Date.now() / 1000;
		const [ w, h ] = this.size;
		const views = this.split === 'none'
			? [ [ this.videos[ 0 ], 0, 0 ], [ this.videos[ 1 ], 0, 0 ] ]
			: [ [ this.videos[ 0 ], 0, 0 ], [ this.videos[ 0 ], this.split === 'side' ? w : 0, this.split === 'top' ? h : 0 ] ];
		const [ left, right ] = [ await this._jpeg( ...views[ 0 ], w, h, quality ), await this._jpeg( ...views[ 1 ], w, h, quality ) ];
		return { left, right, time };

	}

	async _jpeg( video, x, y, w, h, quality ) {

		this.canvas.width = w;
		this.canvas.height = h;
		this.canvas.getContext( '2d' ).drawImage( video, x, y, w, h, 0, 0, w, h );
		const blob = await new Promise( ( resolve ) => this.canvas.toBlob( resolve, 'image/jpeg', quality ) );
		return new Uint8Array( await blob.arrayBuffer() );

	}

}
