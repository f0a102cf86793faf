import { PointsEncoder } from '../net/wire.js';
import { ConditioningForm } from './ConditioningForm.js';
import { $, guarded } from './dom.js';
import { ExpressionReadout } from './ExpressionReadout.js';
import { NeutralCapture } from './NeutralCapture.js';
import { Recorder } from './Recorder.js';
import { SourceStatus } from './SourceStatus.js';
import { TakeImport } from './TakeImport.js';
import { TakeList } from './TakeList.js';

/**
 * The Performance panel (index.html #source-panel): which source drives the face (the
 * built-in demo, the webcam tracked in this page, or a recorded take) and the start
 * message for it; around it the project's takes (TakeList), new takes (TakeImport),
 * recording (Recorder) and the conditioning (ConditioningForm, a view of the page's
 * ConditioningSettings, which every start carries), and what drives the face: its
 * feature points (the rig) or its muscles (*Drive by*, saved with the project; the
 * server solves each frame into contractions, the shader plays them, and the expression
 * they show is read out live: ExpressionReadout).
 *
 * The webcam is tracked here, in the page (tracking/). Its neutral is captured after a
 * countdown (NeutralCapture): no points go out before it ends, so the performer's rest
 * pose is what the server captures, and a capture the server refuses (the performer
 * moved) says so and takes none. The panel holds no maths: the
 * server conditions and retargets whatever the page sends.
 */
export class PerformancePanel {

	/**
	 * @param {import('../App.js').App} app
	 */
	constructor( app ) {

		this.app = app;
		this.webcam = null; // a Promise of {stop()} from the moment the webcam starts
		this.status = new SourceStatus( app.errors );
		this.list = new TakeList( app );
		this.imports = new TakeImport( app, this.list, this.status, ( take ) => this._chooseTake( take ) );
		this.recorder = new Recorder( app, this.status );
		this.conditioning = new ConditioningForm( app.conditioning );
		this.capture = new NeutralCapture();
		this.expressions = new ExpressionReadout();
		this._sending = true; // whether tracked points go out (not during the first countdown)
		this._pointIndex = 0; // the index of the webcam's next points message
		this._neutralFrom = 0; // _pointIndex when the last neutral capture was asked for
		this._neutralWait = null; // {stream, listener} until a neutral capture is in
		this._events = new AbortController();
		this._bind();

	}

	/** The project's takes, oldest first. */
	get takes() {

		return this.list.takes;

	}

	/** List the project's takes again. */
	refreshTakes() {

		return this.list.refresh();

	}

	/**
	 * The conditioning settings every start carries.
	 * @returns {object} ConditionSettings JSON (`app.conditioning.toJSON()`).
	 */
	settings() {

		return this.app.conditioning.toJSON();

	}

	/**
	 * What drives the face: 'points' (the feature points, through the rig), 'muscles' or
	 * 'arkit' (ARKit's 52 blendshapes, the Blendshapes panel's).
	 * @returns {'points'|'muscles'|'arkit'}
	 */
	get drive() {

		return $( 'drive-muscles' ).checked ? 'muscles' : $( 'drive-arkit' ).checked ? 'arkit' : 'points';

	}

	/**
	 * Drive the face by its feature points or its muscles: the muscles are loaded first
	 * (placed by the server on first need), then the stream (a playing source from its
	 * next frame) is told, and the choice saved with the project. A failure goes back to
	 * the feature points and rejects.
	 * @param {'points'|'muscles'|'arkit'} drive
	 */
	async setDrive( drive ) {

		const app = this.app;
		$( `drive-${ drive }` ).checked = true;
		this.expressions.setVisible( drive === 'muscles' );
		app.live.update();
		try {

			if ( drive === 'muscles' ) await app.muscles.load();
			if ( drive === 'arkit' ) await app.blendshapes.load();

		} catch ( error ) {

			$( 'drive-points' ).checked = true;
			this.expressions.setVisible( false );
			app.live.update();
			throw error;

		}

		if ( this.drive !== drive ) return; // switched back meanwhile
		app.stream?.send( { type: 'drive', drive } );
		if ( app.projectId && ( app.project?.settings?.drive ?? 'points' ) !== drive ) app.projectSettings.schedule( app.projectId, 'drive', () => this.drive );

	}

	/** The project changed (or none): list its takes, show its conditioning. */
	async setProject( project ) {

		this.stopWebcam();
		this.recorder.set( false ); // its source went with the old project's stream
		this.list.clear();
		this.status.note( '' ); // "Recorded ...", "Imported ...": news of the old project
		$( 'record-name' ).value = '';
		this.app.conditioning.load( project?.settings?.conditioning ?? null );
		this.setLayout( this.app.layouts?.find( ( l ) => l.name === project?.landmarks?.layout ) ?? ( project ? this.app.landmarks.layout : null ) );
		if ( ! project ) return;
		const saved = project.settings?.drive;
		const drive = ( saved === 'muscles' || saved === 'arkit' ) && project.landmarks && this.app.face ? saved : 'points';
		await Promise.all( [ this.list.refresh(), this.setDrive( drive ).catch( ( error ) => this.app.errors.show( error ) ) ] );

	}

	/**
	 * The start message for the selected source.
	 * @returns {Promise<object>} {type: 'start', source, ...}; rejects saying why the source cannot start.
	 */
	async startMessage() {

		const kind = $( 'source-select' ).value;
		this.recorder.watch( this.app.stream );
		this.recorder.playing = kind;
		if ( kind === 'demo' ) return { type: 'start', source: 'demo', fps: 60 };
		if ( kind === 'take' ) {

			const id = this.list.selected;
			if ( ! id ) throw new Error( 'No take selected: import a file, track a video or record one first.' );
			const settings = this.settings();
			const take = this.list.selectedTake;
			const span = take ? take.trim[ 1 ] - take.trim[ 0 ] : Infinity;
			// the first seconds of a take are its neutral capture, which the player does not
			// show: a take no longer than that has nothing left to play
			if ( settings.neutral.mode === 'first_seconds' && span <= settings.neutral.seconds ) {

				throw new Error( `"${ take.name }" lasts ${ span.toFixed( 2 ) } s, no longer than the neutral capture of its first ${ settings.neutral.seconds } s: under Conditioning, take the neutral from a frame number instead, or capture it over fewer seconds.` );

			}

			this.recorder.playing = take?.name ?? kind;
			return { type: 'start', source: 'take', take: id, loop: $( 'take-loop' ).checked, settings };

		}

		const webcam = this.startWebcam();
		await webcam;
		if ( webcam !== this.webcam ) throw new Error( 'The webcam was stopped before it started.' );
		this._captureNeutral( { holdPoints: true } ); // a new live source has no neutral: none before the countdown ends
		return { type: 'start', source: 'live', dims: 3, fps: 30, settings: this.settings() };

	}

	/** The conditioning changed: a playing source takes it now. */
	sendSettings() {

		if ( this.app.streaming ) this.app.stream?.send( { type: 'settings', settings: this.settings() } );

	}

	/**
	 * A stream message the page did not handle itself.
	 * @param {{type: string}} message
	 */
	onMessage( message ) {

		if ( message.type === 'recorded' ) {

			this.status.note( `Recorded "${ message.take.name }": ${ message.take.n_frames } frames, ${ message.take.duration.toFixed( 1 ) } s.` );
			this.list.selected = message.take.id;
			this.recorder.saved();
			guarded( this.app.errors, async () => {

				await this.list.refresh();
				this.list.reveal();

			} )();

		} else if ( message.type === 'recording' ) {

			this.recorder.set( true );

		} else if ( message.type === 'neutral' ) {

			this._awaitNeutral();

		} else if ( message.type === 'neutral_refused' ) {

			this._endNeutralWait();
			this.capture.refused( message.detail );
			this.status.note( `Webcam: ${ message.detail }`, true );

		}

	}

	/**
	 * The stream stopped (Stop, the end of a take played once, a reconnect): the server
	 * keeps a recording its source ended with for one record_stop, so it is saved now
	 * (queued until the stream is open again after a drop).
	 */
	onStopped() {

		if ( this.recorder.recording ) this.recorder.save();
		this._endNeutralWait();

	}

	/**
	 * Show a gain and cutoff row for each region of `layout` that has points (a layout
	 * without jaw points has no jaw row).
	 * @param {{points: Array<{region: string}>}|null} layout - the saved landmarks' layout,
	 *   else the one being placed.
	 */
	setLayout( layout ) {

		this.app.conditioning.setRegions( layout ? [ ...new Set( layout.points.map( ( p ) => p.region ) ) ] : [] );
		this.conditioning.render();

	}

	/**
	 * The project's layout, whose points tracked sources give.
	 * @returns {object} GET /api/layouts' entry (ibug68 until landmarks are saved).
	 */
	layout() {

		const name = this.app.project?.landmarks?.layout || 'ibug68';
		const layout = this.app.layouts?.find( ( l ) => l.name === name );
		if ( ! layout ) throw new Error( `Unknown layout ${ name }.` );
		return layout;

	}

	// webcam

	/** Start the webcam once: Play again while it starts waits for the same camera. */
	startWebcam() {

		if ( this.webcam ) return this.webcam;
		const webcam = this.webcam = this._openWebcam();
		webcam.catch( () => {

			if ( this.webcam === webcam ) this.webcam = null;

		} );
		return webcam;

	}

	/** Stop the webcam (one still starting stops once it runs). */
	stopWebcam() {

		this.webcam?.then( ( webcam ) => webcam.stop(), () => {} ); // one still starting stops once it runs
		this.webcam = null;
		if ( this.status.text.startsWith( 'Webcam:' ) ) this.status.note( '' ); // not tracking any more
		$( 'webcam-box' ).hidden = true;
		this.capture.cancel();
		this._endNeutralWait();

	}

	/** Stop listening and the webcam; free the sub-panels. */
	dispose() {

		this._events.abort();
		this.stopWebcam();
		this.imports.dispose();
		this.recorder.dispose();
		this.conditioning.dispose();

	}

	async _openWebcam() {

		this.status.note( 'Webcam: starting the camera and the face tracker…' );
		const { startWebcam, frameEcho } = await import( '../tracking/webcam.js' );
		const layout = this.layout();
		const encoder = new PointsEncoder();
		const video = $( 'webcam-video' );
		$( 'webcam-box' ).hidden = false;
		this._pointIndex = 0;
		const lost = new Float32Array( 3 * layout.points.length ).fill( NaN );
		return startWebcam( video, ( { points, time } ) => {

			if ( ! this._sending ) return null; // counting down: the performer is not ready yet
			// a frame without a face goes as lost points, so the stream knows the time
			const stream = this.app.stream;
			const index = this._pointIndex ++;
			const sent = stream?.sendPoints( encoder.encode( points ?? lost, 3, index, time ) );
			// the next frame is tracked once this one's motion is drawn; lost points move nothing
			return sent && points !== null ? frameEcho( stream, index ) : null;

		}, {
			layoutIndices: layout.points.map( ( p ) => p.mediapipe468 ),
			onError: ( error ) => this.app.errors.show( error ),
			onFace: ( found ) => this.status.note( found ? 'Webcam: tracking a face.' : 'Webcam: no face found in the camera image. Face the camera, in good light.' ),
		} );

	}

	/** The server captures the webcam's neutral again: once a frame retargeted with it comes, show it. */
	_awaitNeutral() {

		this._endNeutralWait();
		const stream = this.app.stream;
		if ( ! stream || ! this.webcam ) return;
		// points sent after the request reach the server after it: the first frame echoing
		// one of them is retargeted from the new neutral
		const first = this._neutralFrom;
		const listener = ( event ) => {

			if ( event.detail.frameIndex < first ) return;
			this._endNeutralWait();
			this.status.note( 'Webcam: neutral captured.' );
			this.capture.captured();

		};
		stream.addEventListener( 'frame', listener );
		this._neutralWait = { stream, listener }; // the overlay over the view asks the performer to hold still

	}

	_endNeutralWait() {

		const wait = this._neutralWait;
		wait?.stream.removeEventListener( 'frame', wait.listener );
		this._neutralWait = null;

	}

	/**
	 * Count down, then have the server capture the neutral from the next points.
	 * @param {{holdPoints?: boolean}} [options] - holdPoints: send no points until then
	 *   (a new live source would capture them; a recapture keeps the old neutral meanwhile).
	 */
	_captureNeutral( { holdPoints = false } = {} ) {

		if ( holdPoints ) this._sending = false;
		const neutral = this.settings().neutral;
		this.capture.start( $( 'webcam-video' ), () => {

			this._neutralFrom = this._pointIndex;
			this._sending = true;
			this.app.stream?.send( { type: 'neutral' } );

		}, neutral.mode === 'first_seconds' ? neutral.seconds : 0 );

	}

	/** A new take (imported, tracked, recorded): it becomes the chosen source. */
	async _chooseTake( take ) {

		$( 'source-select' ).value = 'take';
		await this.list.select( take );

	}

	_bind() {

		const signal = this._events.signal;
		this.list.addEventListener( 'select', () => {

			$( 'source-select' ).value = 'take';

		}, { signal } );
		$( 'source-select' ).addEventListener( 'change', () => {

			if ( $( 'source-select' ).value !== 'webcam' ) this.stopWebcam();

		}, { signal } );
		$( 'recapture-neutral' ).addEventListener( 'click', () => this._captureNeutral(), { signal } );
		$( 'drive-switch' ).addEventListener( 'change', guarded( this.app.errors, () => this.setDrive( this.drive ) ), { signal } );

	}

}
