import { FaceMeshTracker } from './FaceMeshTracker.js';

// How long a tracked frame may wait for its retargeted frame to come back and be applied
// before the next camera frame is tracked anyway (no neutral yet, a dropped connection).
// The round trip takes about 30 ms on an idle page, a few hundred on a loaded one.
const ECHO_TIMEOUT_MS = 250;

/**
 * Live markerless tracking of the webcam: getUserMedia into a <video>, and each new camera
 * frame (requestVideoFrameCallback) through the face tracker. When tracking is slower than
 * the camera, the frames that arrive meanwhile are dropped and the newest is tracked next,
 * so the points never lag behind a backlog. Frames stay in the page.
 *
 * The tracker runs on the page's main thread, where each frame takes it tens to hundreds of
 * milliseconds (not in a worker: @mediapipe/face_mesh 0.4's worker path uploads frames
 * without a WebGL context, and once patched ran on WebGL 1, many times slower). Started
 * again at once, it would keep the page from handling the retargeted frame that comes back
 * and from drawing it (about 0.4 s each on a loaded machine). So between two tracked
 * frames the loop waits for what `onFrame` returns (frameEcho: the frame back and
 * applied), then for one animation frame, in which the page draws it.
 *
 * @param {HTMLVideoElement} videoEl - shows the camera (muted, inline); the page may mirror
 *   it with CSS, the points are of the unmirrored frame.
 * @param {function({points: Float32Array|null, time: number, width: number, height: number}): (Promise|void)} onFrame
 *   points: (N * 3) in pixels of the frame width, x right, y up, z toward the camera (the
 *   layout's points, or all 468), null when no face was found; time: seconds since
 *   the start, when the frame was captured where the browser says, else when it was shown.
 *   It may return a promise that settles once the page has used the frame (frameEcho, which
 *   settles within ECHO_TIMEOUT_MS); the next frame is tracked after that.
 * @param {object} [options]
 * @param {ArrayLike<number>|null} [options.layoutIndices] - (N) face-mesh vertex per layout
 *   point (GET /api/layouts' `mediapipe468`); null keeps all 468 landmarks.
 * @param {MediaStreamConstraints['video']} [options.video] - camera constraints.
 * @param {FaceMeshTracker} [options.tracker] - a tracker to reuse (not disposed by stop()).
 * @param {function(Error): void} [options.onError] - a tracking failure; the loop stops.
 * @param {function(boolean): void} [options.onFace] - whether the camera shows a face: called
 *   after the first tracked frame, then whenever a face appears or is lost (not every frame).
 * @returns {Promise<{stop: function(): Promise<void>, stream: MediaStream, tracker: FaceMeshTracker}>}
 *   resolves once the camera plays and the tracker is loaded; rejects when the camera is
 *   refused or missing (getUserMedia's error, with its name).
 */
export async function startWebcam( videoEl, onFrame, { layoutIndices = null, video = { width: 640, height: 480 },
	tracker = null, onError = null, onFace = null } = {} ) {

	if ( typeof videoEl.requestVideoFrameCallback !== 'function' ) {

		throw new Error( 'startWebcam: this browser has no requestVideoFrameCallback, which live tracking needs.' );

	}

	if ( ! navigator.mediaDevices?.getUserMedia ) {

		throw new Error( 'startWebcam: no camera access here (getUserMedia needs https or localhost).' );

	}

	const ownTracker = tracker === null;
	tracker = tracker ?? new FaceMeshTracker();
	const [ stream ] = await Promise.all( [ navigator.mediaDevices.getUserMedia( { video, audio: false } ), tracker.init() ] );
	videoEl.muted = true;
	videoEl.playsInline = true;
	videoEl.srcObject = stream;
	try {

		await videoEl.play();

	} catch ( error ) {

		stream.getTracks().forEach( ( track ) => track.stop() );
		videoEl.srcObject = null;
		throw error;

	}

	let running = true;
	let handle = 0;
	let face = null; // whether the last tracked frame had a face; null before the first
	const origin = performance.now();

	const onVideoFrame = async ( now, metadata ) => {

		if ( ! running ) return;
		try {

			const mesh = await tracker.track( videoEl );
			if ( ! running ) return;
			const points = mesh === null || layoutIndices === null ? mesh : FaceMeshTracker.pick( mesh, layoutIndices );
			const shown = metadata.captureTime ?? metadata.expectedDisplayTime ?? now;
			if ( ( mesh !== null ) !== face ) {

				face = mesh !== null;
				if ( onFace ) onFace( face );

			}

			await onFrame( { points, time: ( shown - origin ) / 1000, width: metadata.width, height: metadata.height } );
			await animationFrame();
			if ( ! running ) return;

		} catch ( error ) {

			running = false;
			if ( onError ) onError( error );
			else console.error( 'startWebcam:', error );
			return;

		}

		// registered after tracking: frames shown meanwhile are skipped, the next one is fresh
		handle = videoEl.requestVideoFrameCallback( onVideoFrame );

	};

	handle = videoEl.requestVideoFrameCallback( onVideoFrame );

	return {
		stream,
		tracker,
		async stop() {

			if ( ! running && videoEl.srcObject !== stream ) return;
			running = false;
			videoEl.cancelVideoFrameCallback( handle );
			stream.getTracks().forEach( ( track ) => track.stop() );
			if ( videoEl.srcObject === stream ) videoEl.srcObject = null;
			if ( ownTracker ) await tracker.dispose();

		},
	};

}

/**
 * Settles once `stream` has dispatched the frame of index `index`, or a later one, as its
 * 'frame' event (a StreamClient's: detail.frameIndex, the index the points went with), or
 * after `timeoutMs`, whichever comes first. Listening after the page's own 'frame' handler
 * (added when the stream was made), it settles once that handler has applied the frame.
 * @param {EventTarget} stream
 * @param {number} index
 * @param {number} [timeoutMs]
 * @returns {Promise<boolean>} whether the frame came back in time.
 */
export function frameEcho( stream, index, timeoutMs = ECHO_TIMEOUT_MS ) {

	return new Promise( ( resolve ) => {

		const finish = ( echoed ) => {

			clearTimeout( timer );
			stream.removeEventListener( 'frame', onFrame );
			resolve( echoed );

		};

		const onFrame = ( event ) => {

			if ( event.detail.frameIndex >= index ) finish( true );

		};

		const timer = setTimeout( () => finish( false ), timeoutMs );
		stream.addEventListener( 'frame', onFrame );

	} );

}

function animationFrame() {

	return new Promise( ( resolve ) => requestAnimationFrame( resolve ) );

}
