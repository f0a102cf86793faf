import { FaceMeshTracker, FACE_MESH_POINTS } from './FaceMeshTracker.js';

/**
 * A take from a video file, tracked in the page frame by frame: every frame of a <video>
 * goes through the face tracker, and the landmarks are read into a layout through its
 * `mediapipe468` indices (GET /api/layouts gives them per point).
 *
 * Stepping: the video plays at normal speed and pauses in each requestVideoFrameCallback
 * while that frame is tracked; a frame that playback skipped anyway (the page was too busy
 * to pause in time) is fetched by seeking to its middle, t + 0.5 / fps. Seeking alone
 * would do, but Chromium decodes from the previous key frame on every seek: on a 480 x 480
 * H.264 file with a key frame every 250 frames, 54 ms a frame over the first 150 frames
 * and 130-150 ms far from a key frame, against 28 ms (about one frame period at 30 fps)
 * for the paused playback (bench/markerless.py). Without requestVideoFrameCallback every
 * frame is sought.
 */

const STANDARD_FPS = [ 23.976, 24, 25, 29.97, 30, 48, 50, 59.94, 60, 90, 100, 119.88, 120 ];
const FPS_SAMPLES = 12;
const FPS_TIMEOUT_MS = 5000;

/**
 * Track a video file.
 * @param {File|Blob|string} fileOrUrl - the user's file, or a URL (fetched whole first, so
 *   seeking never depends on the server's range support).
 * @param {object} [options]
 * @param {ArrayLike<number>|null} [options.layoutIndices] - (N) face-mesh vertex per layout
 *   point; null keeps all 468 landmarks.
 * @param {number|null} [options.fps] - the video's frame rate when known (a <video> does not
 *   say); otherwise measured from a moment of muted playback. It sets the frame period by
 *   which skipped frames are noticed; the times returned are the frames' own.
 * @param {number} [options.maxFrames] - track at most this many frames from the start.
 * @param {function({done: number, total: number, faces: number}): void} [options.onProgress]
 *   total is the expected frame count (from the duration; null when the file does not
 *   state it).
 * @param {AbortSignal} [options.signal] - aborting rejects with the signal's reason.
 * @param {FaceMeshTracker} [options.tracker] - a tracker to reuse (its init() is awaited).
 * @returns {Promise<{fps: number, width: number, height: number, n_frames: number,
 *   n_points: number, points: Float32Array, times: Float64Array, faces: number,
 *   sought: number, seconds: number}>}
 *   points: (n_frames * n_points * 3) in pixels of the frame width, x right, y up, z toward
 *   the camera, NaN for every point of a frame without a face; times: (n_frames) each
 *   frame's presentation time, s; faces: frames with a face; sought: frames fetched by
 *   seeking; seconds: wall time spent decoding and tracking.
 */
export async function trackVideo( fileOrUrl, { layoutIndices = null, fps = null, maxFrames = Infinity,
	onProgress = null, signal = null, tracker = null } = {} ) {

	signal?.throwIfAborted();
	if ( ! ( maxFrames >= 1 ) ) throw new Error( `trackVideo: maxFrames must be at least 1, got ${ maxFrames }.` );
	const ownTracker = tracker === null;
	tracker = tracker ?? new FaceMeshTracker();
	const blob = await videoBlob( fileOrUrl, signal );
	const url = URL.createObjectURL( blob );
	const video = document.createElement( 'video' );
	video.muted = true;
	video.playsInline = true;
	video.preload = 'auto';
	try {

		await Promise.all( [ tracker.init(), loaded( video, url, fileOrUrl ) ] );
		const stepping = typeof video.requestVideoFrameCallback === 'function';
		if ( fps === null ) fps = await measuredFps( video );
		if ( ! ( fps > 0 ) ) throw new Error( `trackVideo: fps must be positive, got ${ fps }.` );
		// the duration runs to the end of the last frame, sometimes a little beyond; some
		// files (streamed WebM) do not say it, and only playing them to the end can tell
		const total = Number.isFinite( video.duration ) ? Math.min( Math.floor( video.duration * fps + 1e-3 ), maxFrames ) : null;
		if ( total === null && ! stepping ) throw new Error( `trackVideo: ${ nameOf( fileOrUrl ) } does not state its duration, and this browser cannot play it frame by frame (no requestVideoFrameCallback).` );
		if ( total !== null && ! ( total > 0 ) ) throw new Error( `trackVideo: ${ nameOf( fileOrUrl ) } holds no frames (duration ${ video.duration } s).` );

		const nPoints = layoutIndices === null ? FACE_MESH_POINTS : layoutIndices.length;
		const period = 1 / fps;
		const frames = []; // per frame: (N * 3) points, or null without a face
		const times = []; // per frame: its presentation time, s
		const start = performance.now();
		let faces = 0, sought = 0;
		const record = async ( time ) => {

			const mesh = await tracker.track( video );
			frames.push( mesh === null ? null : layoutIndices === null ? mesh : FaceMeshTracker.pick( mesh, layoutIndices ) );
			times.push( time );
			if ( mesh !== null ) faces ++;
			onProgress?.( { done: frames.length, total, faces } );

		};

		const seekAndRecord = async ( time ) => {

			signal?.throwIfAborted();
			await seek( video, time + period / 2 ); // the middle of the frame: no rounding doubt
			sought ++;
			await record( time );

		};

		await seekAndRecord( 0 );
		if ( stepping ) {

			// frames are counted from the time since the last tracked one, never from the
			// start, so an fps a little off cannot add up to a wrong frame far into the video
			while ( frames.length < maxFrames ) {

				signal?.throwIfAborted();
				const metadata = await nextFrame( video );
				if ( metadata === null ) break; // played to the end
				const last = times[ times.length - 1 ];
				const periods = Math.round( ( metadata.mediaTime - last ) / period );
				if ( periods < 1 ) continue; // the tracked frame again, shown after a seek
				if ( periods > 1 ) {

					// playback went past frames while the page was busy: fetch them by seeking,
					// then come back to this one
					for ( let k = 1; k < periods && frames.length < maxFrames; k ++ ) await seekAndRecord( last + k * period );
					if ( frames.length < maxFrames ) await seekAndRecord( metadata.mediaTime );

				} else {

					await record( metadata.mediaTime );

				}

			}

		} else {

			for ( let i = 1; i < total; i ++ ) await seekAndRecord( i * period );

		}

		const points = new Float32Array( frames.length * nPoints * 3 ).fill( NaN );
		frames.forEach( ( frame, i ) => {

			if ( frame !== null ) points.set( frame, i * nPoints * 3 );

		} );
		return {
			fps, width: video.videoWidth, height: video.videoHeight, n_frames: frames.length, n_points: nPoints,
			points, times: Float64Array.from( times ), faces, sought, seconds: ( performance.now() - start ) / 1000,
		};

	} finally {

		video.pause();
		video.removeAttribute( 'src' );
		video.load(); // frees the decoder now, not at garbage collection
		URL.revokeObjectURL( url );
		if ( ownTracker ) await tracker.dispose();

	}

}

function nameOf( fileOrUrl ) {

	return typeof fileOrUrl === 'string' ? fileOrUrl : ( fileOrUrl.name || 'the video' );

}

async function videoBlob( fileOrUrl, signal ) {

	if ( fileOrUrl instanceof Blob ) return fileOrUrl;
	let response;
	try {

		response = await fetch( fileOrUrl, { signal } );

	} catch ( error ) {

		if ( signal?.aborted ) throw signal.reason;
		throw new Error( `trackVideo: could not fetch ${ fileOrUrl }: ${ error.message }` );

	}

	if ( ! response.ok ) throw new Error( `trackVideo: could not fetch ${ fileOrUrl }: HTTP ${ response.status }` );
	return response.blob();

}

const MEDIA_ERRORS = { 1: 'loading was aborted', 2: 'a network error', 3: 'it could not be decoded', 4: 'it is not a video this browser can play' };

function loaded( video, url, fileOrUrl ) {

	return new Promise( ( resolve, reject ) => {

		// loadeddata, not loadedmetadata: the first frame must be decodable, or a file with a
		// valid header and broken frames would only fail later, frame by frame
		video.addEventListener( 'loadeddata', () => resolve(), { once: true } );
		video.addEventListener( 'error', () => {

			const error = video.error;
			reject( new Error( `trackVideo: cannot read ${ nameOf( fileOrUrl ) }: ${ MEDIA_ERRORS[ error?.code ] ?? 'unknown media error' }${ error?.message ? ` (${ error.message })` : '' }.` ) );

		}, { once: true } );
		video.src = url;

	} );

}

function seek( video, time ) {

	return new Promise( ( resolve, reject ) => {

		const done = () => {

			video.removeEventListener( 'error', failed );
			resolve();

		};

		const failed = () => {

			video.removeEventListener( 'seeked', done );
			reject( new Error( `trackVideo: decoding failed at ${ time.toFixed( 3 ) } s: ${ MEDIA_ERRORS[ video.error?.code ] ?? 'unknown media error' }.` ) );

		};

		video.addEventListener( 'seeked', done, { once: true } );
		video.addEventListener( 'error', failed, { once: true } );
		video.currentTime = time;

	} );

}

/**
 * Play to the next frame and pause on it.
 * @param {HTMLVideoElement} video
 * @returns {Promise<VideoFrameCallbackMetadata|null>} the frame's metadata, null at the end.
 */
function nextFrame( video ) {

	if ( video.ended ) return Promise.resolve( null );
	return new Promise( ( resolve, reject ) => {

		const finish = ( value, error ) => {

			video.cancelVideoFrameCallback( handle );
			video.removeEventListener( 'ended', ended );
			video.removeEventListener( 'error', failed );
			if ( error ) reject( error );
			else resolve( value );

		};

		const ended = () => finish( null );
		const failed = () => finish( null, new Error( `trackVideo: decoding failed after ${ video.currentTime.toFixed( 3 ) } s: ${ MEDIA_ERRORS[ video.error?.code ] ?? 'unknown media error' }.` ) );
		const handle = video.requestVideoFrameCallback( ( now, metadata ) => {

			video.pause(); // in the callback, before the clock reaches the next frame
			finish( metadata );

		} );
		video.addEventListener( 'ended', ended );
		video.addEventListener( 'error', failed );
		video.play().catch( ( error ) => {

			// pausing in the callback interrupts play() (AbortError): that is the plan
			if ( error.name !== 'AbortError' ) finish( null, new Error( `trackVideo: the video did not play: ${ error.message }` ) );

		} );

	} );

}

/**
 * The frame rate of a loaded video, from the presentation times of a few frames of muted
 * playback (requestVideoFrameCallback's mediaTime), snapped to the nearest standard rate
 * within 0.5 % (WebM times are in milliseconds: a few frames measure a rate to about that).
 * @param {HTMLVideoElement} video
 * @returns {Promise<number>}
 */
async function measuredFps( video ) {

	if ( typeof video.requestVideoFrameCallback !== 'function' ) {

		throw new Error( 'trackVideo: this browser cannot measure a video\'s frame rate (no requestVideoFrameCallback); pass fps.' );

	}

	const times = await new Promise( ( resolve, reject ) => {

		const seen = [];
		const timer = setTimeout( () => reject( new Error( 'trackVideo: the video did not play, so its frame rate is unknown; pass fps.' ) ), FPS_TIMEOUT_MS );
		const done = () => {

			clearTimeout( timer );
			video.removeEventListener( 'ended', done );
			resolve( seen );

		};

		const onFrame = ( now, metadata ) => {

			seen.push( metadata.mediaTime );
			if ( seen.length >= FPS_SAMPLES ) done();
			else video.requestVideoFrameCallback( onFrame );

		};

		video.requestVideoFrameCallback( onFrame );
		video.addEventListener( 'ended', done ); // a video shorter than the sample
		video.play().catch( ( error ) => {

			clearTimeout( timer );
			reject( new Error( `trackVideo: the video did not play, so its frame rate is unknown (${ error.message }); pass fps.` ) );

		} );

	} );
	video.pause();
	const steps = [];
	for ( let k = 1; k < times.length; k ++ ) if ( times[ k ] > times[ k - 1 ] ) steps.push( times[ k ] - times[ k - 1 ] );
	if ( steps.length === 0 ) throw new Error( 'trackVideo: the video showed fewer than two frames, so its frame rate is unknown; pass fps.' );
	// the median step tells how many periods each step spans (playback may drop a frame);
	// the whole span over those periods averages out timestamps rounded to milliseconds
	const median = [ ...steps ].sort( ( a, b ) => a - b )[ steps.length >> 1 ];
	const periods = steps.reduce( ( sum, step ) => sum + Math.max( 1, Math.round( step / median ) ), 0 );
	const fps = periods / steps.reduce( ( sum, step ) => sum + step, 0 );
	const nearest = STANDARD_FPS.reduce( ( a, b ) => ( Math.abs( b - fps ) < Math.abs( a - fps ) ? b : a ) );
	return Math.abs( nearest - fps ) < 5e-3 * nearest ? nearest : fps;

}
