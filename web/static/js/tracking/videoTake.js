import { FaceMeshTracker, FACE_MESH_POINTS } from './FaceMeshTracker.js';
import { containerFrames, snappedFps } from './containerFrames.js';

/**
 * A take from a video file, tracked in the page frame by frame: every frame of a <video>
 * goes through the face tracker, and the landmarks are read into a layout through its
 * `mediapipe468` indices (GET /api/layouts gives them per point).
 *
 * Frames: how many and at what rate come from the container's index (containerFrames.js:
 * MP4 / MOV, WebM / Matroska), so neither depends on how busy the page is; frame i is the
 * one shown at start + i / fps. Other containers are measured from slowed playback and
 * counted from the duration.
 *
 * Stepping: the video plays at normal speed and pauses in each requestVideoFrameCallback
 * while that frame is tracked; a frame that playback skipped anyway (the page was too busy
 * to pause in time), or that it ran past at the end, is fetched by seeking to its middle,
 * start + (i + 0.5) / fps. Seeking alone would do, but Chromium decodes from the previous
 * key frame on every seek: on a 480 x 480 H.264 file with a key frame every 250 frames,
 * 54 ms a frame over the first 150 frames and 130-150 ms far from a key frame, against
 * 28 ms (about one frame period at 30 fps) for the paused playback (bench/markerless.py).
 * Without requestVideoFrameCallback every frame is sought.
 */

const SINGLE_FRAME_FPS = 30; // a one-frame video has no rate; retarget.sources.take.DEFAULT_FPS
const FPS_SAMPLES = 12;
const FPS_PLAYBACK_RATE = 0.25; // slowed, so that a busy page still sees most frames
const FPS_TIMEOUT_MS = 5000 / FPS_PLAYBACK_RATE;

/**
 * Track a video file.
 * @param {File|Blob|string} fileOrUrl - the user's file, or a URL (fetched whole first, so
 *   seeking never depends on the server's range support).
 * @param {object} [options]
 * @param {ArrayLike<number>|null} [options.layoutIndices] - (N) face-mesh vertex per layout
 *   point; null keeps all 468 landmarks.
 * @param {number|null} [options.fps] - the video's frame rate, instead of the container's
 *   (or, for other containers, one measured from playback).
 * @param {number} [options.maxFrames] - track at most this many frames from the start.
 * @param {function({done: number, total: number, faces: number}): void} [options.onProgress]
 *   total is the expected frame count (null when neither the container nor the duration
 *   states it).
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
	if ( fps !== null && ! ( fps > 0 ) ) throw new Error( `trackVideo: fps must be positive, got ${ fps }.` );
	const ownTracker = tracker === null;
	tracker = tracker ?? new FaceMeshTracker();
	const blob = await videoBlob( fileOrUrl, signal );
	const url = URL.createObjectURL( blob );
	const video = document.createElement( 'video' );
	video.muted = true;
	video.playsInline = true;
	video.preload = 'auto';
	try {

		const [ listed ] = await Promise.all( [ containerFrames( blob ), tracker.init(), loaded( video, url, fileOrUrl ) ] );
		const stepping = typeof video.requestVideoFrameCallback === 'function';
		fps = fps ?? listed?.fps ?? ( listed?.count === 1 ? SINGLE_FRAME_FPS : await measuredFps( video, fileOrUrl ) );
		// the duration runs to the end of the last frame, sometimes a little beyond; some
		// files (streamed WebM) do not say it, and only playing them to the end can tell
		const stated = listed?.count ?? ( Number.isFinite( video.duration ) ? Math.floor( video.duration * fps + 1e-3 ) : null );
		const total = stated === null ? null : Math.min( stated, maxFrames );
		if ( total === null && ! stepping ) throw new Error( `trackVideo: ${ nameOf( fileOrUrl ) } does not state its duration, and this browser cannot play it frame by frame (no requestVideoFrameCallback).` );
		if ( total !== null && ! ( total > 0 ) ) throw new Error( `trackVideo: ${ nameOf( fileOrUrl ) } holds no frames (duration ${ video.duration } s).` );

		const nPoints = layoutIndices === null ? FACE_MESH_POINTS : layoutIndices.length;
		const period = 1 / fps;
		const start = listed?.start ?? 0;
		const timeOf = ( i ) => start + i * period;
		const last = total ?? Infinity;
		const frames = []; // per frame: (N * 3) points, or null without a face
		const times = []; // per frame: its presentation time, s
		const began = performance.now();
		let faces = 0, sought = 0;
		const record = async ( time ) => {

			const mesh = await tracker.track( video );
			frames.push( mesh === null ? null : layoutIndices === null ? mesh : FaceMeshTracker.pick( mesh, layoutIndices ) );
			times.push( time );
			if ( mesh !== null ) faces ++;
			onProgress?.( { done: frames.length, total, faces } );

		};

		// the next frame, frames.length, fetched by seeking to its middle: no rounding doubt
		const seekAndRecord = async () => {

			signal?.throwIfAborted();
			const time = timeOf( frames.length );
			await seek( video, time + period / 2 );
			sought ++;
			await record( time );

		};

		await seekAndRecord();
		while ( stepping && frames.length < last ) {

			signal?.throwIfAborted();
			const metadata = await nextFrame( video );
			if ( metadata === null ) break; // played to the end
			const i = Math.round( ( metadata.mediaTime - start ) / period );
			if ( i < frames.length ) continue; // a tracked frame again, shown after a seek
			// playback went past frames while the page was busy: fetch them by seeking, and
			// this one too when the clock ran on into the next before the pause
			while ( frames.length < Math.min( i, last ) ) await seekAndRecord();
			if ( frames.length === last ) break;
			if ( video.currentTime < timeOf( i + 1 ) ) await record( metadata.mediaTime );
			else await seekAndRecord();

		}

		// frames after the last one playback showed (it ran to the end while one was tracked),
		// or every frame without requestVideoFrameCallback
		while ( total !== null && frames.length < total ) await seekAndRecord();

		const points = new Float32Array( frames.length * nPoints * 3 ).fill( NaN );
		frames.forEach( ( frame, i ) => {

			if ( frame !== null ) points.set( frame, i * nPoints * 3 );

		} );
		return {
			fps, width: video.videoWidth, height: video.videoHeight, n_frames: frames.length, n_points: nPoints,
			points, times: Float64Array.from( times ), faces, sought, seconds: ( performance.now() - began ) / 1000,
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
const NOT_A_VIDEO = 'not a video the browser can read: use MP4 (H.264) or WebM';

function loaded( video, url, fileOrUrl ) {

	return new Promise( ( resolve, reject ) => {

		// loadeddata, not loadedmetadata: the first frame must be decodable, or a file with a
		// valid header and broken frames would only fail later, frame by frame
		video.addEventListener( 'loadeddata', () => resolve(), { once: true } );
		video.addEventListener( 'error', () => {

			const code = video.error?.code;
			// a file the browser cannot open or decode is, to the user, not a video: the
			// decoder's own words (PipelineStatus::DEMUXER_ERROR_...) tell them nothing
			if ( code === MediaError.MEDIA_ERR_SRC_NOT_SUPPORTED || code === MediaError.MEDIA_ERR_DECODE ) {

				reject( new Error( `${ nameOf( fileOrUrl ) } is ${ NOT_A_VIDEO }.` ) );

			} else {

				reject( new Error( `trackVideo: cannot read ${ nameOf( fileOrUrl ) }: ${ MEDIA_ERRORS[ code ] ?? 'unknown media error' }.` ) );

			}

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
 * The frame rate of a loaded video whose container does not index its frames, from the
 * presentation times of a few frames of muted, slowed playback (requestVideoFrameCallback's
 * mediaTime), snapped to the nearest standard rate within 0.5 % (WebM times are in
 * milliseconds: a few frames measure a rate to about that).
 * @param {HTMLVideoElement} video
 * @param {File|Blob|string} fileOrUrl - for messages.
 * @returns {Promise<number>}
 */
async function measuredFps( video, fileOrUrl ) {

	const unknown = `trackVideo: cannot tell the frame rate of ${ nameOf( fileOrUrl ) }: its container is neither MP4 nor WebM, whose index states it`;
	const remedy = 'Convert it to MP4 or WebM (e.g. ffmpeg -i in.ogv out.mp4) and track that.';
	if ( typeof video.requestVideoFrameCallback !== 'function' ) {

		throw new Error( `${ unknown }, and this browser cannot measure it (no requestVideoFrameCallback). ${ remedy }` );

	}

	const times = await new Promise( ( resolve, reject ) => {

		const seen = [];
		const timer = setTimeout( () => reject( new Error( `${ unknown }, and it did not play. ${ remedy }` ) ), FPS_TIMEOUT_MS );
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
		video.playbackRate = FPS_PLAYBACK_RATE;
		video.play().catch( ( error ) => {

			clearTimeout( timer );
			reject( new Error( `${ unknown }, and it did not play (${ error.message }). ${ remedy }` ) );

		} );

	} );
	video.pause();
	video.playbackRate = 1;
	const steps = [];
	for ( let k = 1; k < times.length; k ++ ) if ( times[ k ] > times[ k - 1 ] ) steps.push( times[ k ] - times[ k - 1 ] );
	if ( steps.length === 0 ) throw new Error( `${ unknown }, and playing it showed fewer than two frames. ${ remedy }` );
	// the median step tells how many periods each step spans (playback may drop a frame);
	// the whole span over those periods averages out timestamps rounded to milliseconds
	const median = [ ...steps ].sort( ( a, b ) => a - b )[ steps.length >> 1 ];
	const periods = steps.reduce( ( sum, step ) => sum + Math.max( 1, Math.round( step / median ) ), 0 );
	return snappedFps( periods / steps.reduce( ( sum, step ) => sum + step, 0 ), 5e-3 );

}
