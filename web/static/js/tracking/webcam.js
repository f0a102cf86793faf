import { FaceMeshTracker } from './FaceMeshTracker.js';

/**
 * Live markerless tracking of the webcam: getUserMedia into a <video>, and each new camera
 * frame (requestVideoFrameCallback) through the face tracker. When tracking is slower than
 * the camera, the frames that arrive meanwhile are dropped and the newest is tracked next,
 * so the points never lag behind a backlog. Frames stay in the page.
 *
 * @param {HTMLVideoElement} videoEl - shows the camera (muted, inline); the page may mirror
 *   it with CSS, the points are of the unmirrored frame.
 * @param {function({points: Float32Array|null, time: number, width: number, height: number}): void} onFrame
 *   points: (N * 3) in pixels of the frame width, x right, y up, z toward the camera (the
 *   layout's points, or all 468), null when no face was found; time: seconds since
 *   the start, when the frame was captured where the browser says, else when it was shown.
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

			onFrame( { points, time: ( shown - origin ) / 1000, width: metadata.width, height: metadata.height } );

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
