import { api } from './net/api.js';
import { ask } from './dialogs.js';
import { PointsEncoder } from './net/wire.js';
import { StereoTrack } from './StereoTrack.js';
import { trackVideo } from './tracking/videoTake.js';

/**
 * The performance panel: which source drives the face (the built-in demo, the webcam
 * tracked in this page, or a recorded take), the project's takes (import, track a video,
 * rename, trim, download, delete), recording whatever source plays into a new take, and
 * the conditioning settings sent with every start
 * (`retarget.sources.conditioning.ConditionSettings`: neutral, head pose, jitter filter and
 * gain per region).
 *
 * Markerless tracking runs here, in the page (tracking/); marker videos are tracked by
 * the server in a job whose progress feeds the bar. The panel holds no maths: the server
 * conditions and retargets whatever the page sends.
 */

const $ = ( id ) => document.getElementById( id );
const TAKE_EXTENSIONS = [ 'csv', 'json', 'npy', 'trc', 'c3d', 'glb', 'gltf', 'zip' ];
const RECORD_TICK_MS = 100;

export class SourcePanel {

	/**
	 * @param {object} app - the page's App: {projectId, project, stream, errors, layouts,
	 *   connectStream(), liveMissing()}.
	 */
	constructor( app ) {

		this.app = app;
		this.takes = [];
		this.selectedTake = null;
		this.webcam = null; // a Promise of {stop()} from the moment the webcam starts
		this.recording = false;
		this._playing = ''; // what the last start plays, for a recording's default name
		this._watched = null; // the stream whose 'started' replies enable recording
		this._recordClock = { since: 0, timer: 0 }; // performance.now() the recording began, ms
		this._pointIndex = 0; // the index of the webcam's next points message
		this._neutralFrom = 0; // _pointIndex when the last neutral capture was asked for
		this._neutralWait = null; // {stream, listener} until a neutral capture is in
		this.stereo = new StereoTrack( {
			projectId: () => this.app.projectId,
			run: ( work ) => this._task( work ),
			onTracked: async ( take ) => {

				this.selectedTake = take;
				$( 'source-select' ).value = 'take';
				await this.refreshTakes();

			},
		} );
		this._bind();
		this._setRecording( false ); // disabled until a source plays, and why

	}

	/** The conditioning settings of the form, as ConditionSettings JSON. */
	settings() {

		const regions = {};
		const gain = {};
		for ( const row of $( 'gain-table' ).querySelectorAll( 'tr[data-region]' ) ) {

			const region = row.dataset.region;
			gain[ region ] = Number( row.querySelector( '.gain' ).value );
			regions[ region ] = { min_cutoff: Number( row.querySelector( '.cutoff' ).value ), beta: Number( $( 'oe-beta' ).value ) };

		}

		const mode = $( 'neutral-mode' ).value;
		const value = Number( $( 'neutral-value' ).value );
		return {
			neutral: mode === 'frame' ? { mode, frame: Math.max( 0, Math.round( value ) ) } : { mode, seconds: Math.max( 0, value ) },
			head_pose: $( 'head-remove' ).checked ? 'remove' : 'keep',
			apply_rotation: $( 'head-apply' ).checked,
			filter: $( 'filter' ).value,
			one_euro: regions,
			gain,
		};

	}

	/** The project changed (or its landmarks): list its takes, rebuild the region rows. */
	async setProject( project ) {

		this.stopWebcam();
		this._setRecording( false ); // its source went with the old project's stream
		this._abort?.abort( new Error( 'Video tracking stopped: another project was opened.' ) );
		this.takes = [];
		this.selectedTake = null;
		this._regionRows( project?.landmarks?.layout || 'ibug68' );
		this._renderTakes();
		if ( ! project ) return;
		await this.refreshTakes();

	}

	async refreshTakes() {

		const id = this.app.projectId;
		const takes = await api.takes( id );
		if ( id !== this.app.projectId ) return;
		this.takes = takes;
		if ( ! takes.some( ( t ) => t.id === this.selectedTake ) ) this.selectedTake = takes.length ? takes[ takes.length - 1 ].id : null;
		this._renderTakes();

	}

	/** The start message for the selected source, or null after showing why it cannot start. */
	async startMessage() {

		const kind = $( 'source-select' ).value;
		this._watch( this.app.stream );
		this._playing = kind;
		if ( kind === 'demo' ) return { type: 'start', source: 'demo', fps: 60 };
		if ( kind === 'take' ) {

			if ( ! this.selectedTake ) throw new Error( 'No take selected: import a file, track a video or record one first.' );
			const settings = this.settings();
			const take = this.takes.find( ( t ) => t.id === this.selectedTake );
			const span = take ? take.trim[ 1 ] - take.trim[ 0 ] : Infinity;
			// the first seconds of a take are its neutral capture, which the player does not
			// show: a take no longer than that has nothing left to play
			if ( settings.neutral.mode === 'first_seconds' && span <= settings.neutral.seconds ) {

				throw new Error( `"${ take.name }" lasts ${ span.toFixed( 2 ) } s, no longer than the neutral capture of its first ${ settings.neutral.seconds } s: under Conditioning, take the neutral from a frame number instead, or capture it over fewer seconds.` );

			}

			this._playing = take?.name ?? kind;
			return { type: 'start', source: 'take', take: this.selectedTake, loop: $( 'take-loop' ).checked, settings };

		}

		const webcam = this.startWebcam();
		await webcam;
		if ( webcam !== this.webcam ) throw new Error( 'The webcam was stopped before it started.' );
		return { type: 'start', source: 'live', dims: 3, fps: 30, settings: this.settings() };

	}

	/** A stream message the page did not handle itself. */
	onMessage( message ) {

		if ( message.type === 'recorded' ) {

			this._note( `Recorded "${ message.take.name }": ${ message.take.n_frames } frames, ${ message.take.duration.toFixed( 1 ) } s.` );
			this.selectedTake = message.take.id;
			$( 'record-name' ).value = ''; // the next recording is another take
			this._guard( async () => {

				await this.refreshTakes();
				$( 'take-list' ).querySelector( 'li.selected' )?.scrollIntoView( { block: 'nearest' } );

			} );

		} else if ( message.type === 'recording' ) {

			this._setRecording( true );

		} else if ( message.type === 'neutral' ) {

			this._awaitNeutral();

		}

	}

	/**
	 * The stream stopped (Stop, the end of a take played once, a reconnect): the server
	 * keeps a recording its source ended with for one record_stop, so it is saved now
	 * (queued until the stream is open again after a drop).
	 */
	onStopped() {

		if ( this.recording ) this._saveRecording();
		this._endNeutralWait();

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

	async _openWebcam() {

		this._note( 'Webcam: starting the camera and the face tracker…' );
		const { startWebcam, frameEcho } = await import( './tracking/webcam.js' );
		const layout = this._layout();
		const encoder = new PointsEncoder();
		const video = $( 'webcam-video' );
		$( 'webcam-box' ).hidden = false;
		this._pointIndex = 0;
		const lost = new Float32Array( 3 * layout.points.length ).fill( NaN );
		return startWebcam( video, ( { points, time } ) => {

			// a frame without a face goes as lost points, so the stream knows the time
			const stream = this.app.stream;
			const index = this._pointIndex ++;
			const sent = stream?.sendPoints( encoder.encode( points ?? lost, 3, index, time ) );
			// the next frame is tracked once this one's motion is drawn; lost points move nothing
			return sent && points !== null ? frameEcho( stream, index ) : null;

		}, {
			layoutIndices: layout.points.map( ( p ) => p.mediapipe468 ),
			onError: ( error ) => this.app.errors.show( error ),
			onFace: ( found ) => this._note( found ? 'Webcam: tracking a face.' : 'Webcam: no face found in the camera image. Face the camera, in good light.' ),
		} );

	}

	stopWebcam() {

		this.webcam?.then( ( webcam ) => webcam.stop(), () => {} ); // one still starting stops once it runs
		this.webcam = null;
		if ( $( 'source-note' ).textContent.startsWith( 'Webcam:' ) ) this._note( '' ); // not tracking any more
		$( 'webcam-box' ).hidden = true;
		this._endNeutralWait();

	}

	// takes

	async importTake( file ) {

		const ext = file.name.split( '.' ).pop().toLowerCase();
		if ( ! TAKE_EXTENSIONS.includes( ext ) ) throw new Error( `${ file.name }: a take is read from ${ TAKE_EXTENSIONS.map( ( e ) => '.' + e ).join( ', ' ) }.` );
		const fields = ext === 'npy' ? { layout: this._layout().name } : {};
		const info = await this._withProgress( `Uploading ${ file.name }…`, ( progress ) => api.uploadTake( this.app.projectId, file, fields, progress ) );
		this._note( `Imported "${ info.name }": ${ info.n_frames } frames of ${ info.n_points } points (${ info.source }).` );
		this.selectedTake = info.id;
		$( 'source-select' ).value = 'take';
		await this.refreshTakes();

	}

	async trackVideoFile( file ) {

		const method = $( 'video-method' ).value;
		if ( method === 'markers' ) return this._trackOnServer( file );
		const id = this.app.projectId;
		const layout = this._layout();
		const controller = new AbortController();
		this._abort = controller; // another project stops it (setProject)
		const result = await this._withProgress( `Tracking ${ file.name } in this page…`, ( progress ) => trackVideo( file, {
			layoutIndices: layout.points.map( ( p ) => p.mediapipe468 ),
			signal: controller.signal,
			onProgress: ( { done, total, faces } ) => {

				if ( total ) progress( done / total );
				this._note( `Tracking ${ file.name }: frame ${ done }${ total ? ' / ' + total : '' }, a face in ${ faces }.` );

			},
		} ) );
		if ( result.faces === 0 ) throw new Error( `No face was found in ${ file.name } (${ result.n_frames } frames): nothing to keep.` );
		const npy = new File( [ npyBytes( result.points, [ result.n_frames, result.n_points, 3 ] ) ], file.name.replace( /\.[^.]*$/, '' ) + '.npy' );
		const info = await api.uploadTake( id, npy, { layout: layout.name, fps: result.fps, name: file.name.replace( /\.[^.]*$/, '' ) } );
		if ( id !== this.app.projectId ) return; // kept in its project; this one lists its own takes
		const share = result.faces / result.n_frames;
		this._note( `Tracked "${ info.name }": ${ result.n_frames } frames at ${ +result.fps.toFixed( 3 ) } fps, a face in ${ ( 100 * share ).toFixed( 0 ) } % of them (${ ( result.n_frames / result.seconds ).toFixed( 1 ) } frames tracked a second).`, share < 0.9 );
		this.selectedTake = info.id;
		$( 'source-select' ).value = 'take';
		await this.refreshTakes();

	}

	async _trackOnServer( file ) {

		const id = this.app.projectId;
		const job = await this._withProgress( `Uploading ${ file.name }…`, ( progress ) => api.trackVideo( id, file, { method: 'markers', layout: 'dutreve21' }, progress ) );
		const bar = $( 'source-progress' );
		bar.value = 0; // the job's share done, no longer the upload's
		bar.hidden = false;
		let result; // {take, frames, truncated?, frames_claimed?}
		try {

			( { result } = await api.waitJob( job.id, ( state ) => {

				bar.value = state.progress;
				this._note( `Tracking the markers of ${ file.name } on the server: ${ ( 100 * state.progress ).toFixed( 0 ) } %` );

			}, { what: 'Marker tracking' } ) );
			this.selectedTake = result.take;

		} finally {

			bar.hidden = true;

		}

		$( 'source-select' ).value = 'take';
		if ( id !== this.app.projectId ) return;
		await this.refreshTakes();
		const info = this.takes.find( ( t ) => t.id === result.take );
		let text = `Tracked "${ info?.name ?? file.name }": ${ info?.n_points ?? '' } markers in ${ result.frames } frames of ${ file.name }.`;
		// a cut-off file still gives its frames up to the cut: say so, or the take looks whole
		if ( result.truncated ) text += ` The file is cut off: only ${ result.frames } of the ${ result.frames_claimed } frames it announces could be read.`;
		this._note( text, result.truncated );

	}

	/** Edit the take's name in its row: Enter or leaving the box saves, Escape cancels. */
	_rename( take, label ) {

		const box = document.createElement( 'input' );
		box.type = 'text';
		box.className = 'take-rename';
		box.maxLength = 200;
		box.value = take.name;
		box.setAttribute( 'aria-label', 'Take name' );
		let done = false;
		const finish = ( save ) => {

			if ( done ) return;
			done = true;
			const name = box.value.trim();
			if ( ! save || ! name || name === take.name ) {

				this._renderTakes();
				return;

			}

			this._guard( async () => {

				try {

					await api.patchTake( this.app.projectId, take.id, { name } );

				} finally {

					await this.refreshTakes();

				}

			} );

		};

		box.addEventListener( 'keydown', ( event ) => {

			if ( event.key === 'Enter' ) finish( true );
			else if ( event.key === 'Escape' ) finish( false );

		} );
		box.addEventListener( 'blur', () => finish( true ) );
		label.replaceWith( box );
		box.focus();
		box.select();

	}

	async _trim( take, start, stop ) {

		try {

			await api.patchTake( this.app.projectId, take.id, { trim: [ start, stop >= take.duration ? null : stop ] } );

		} finally {

			// a refused span puts the boxes back to the stored one
			await this.refreshTakes();

		}

	}

	async _delete( take ) {

		const answer = await ask( `Delete the take "${ take.name }"? This cannot be undone.`, { ok: 'Delete' } );
		if ( answer !== 'ok' ) return;
		await api.deleteTake( this.app.projectId, take.id );
		await this.refreshTakes();

	}

	_renderTakes() {

		const list = $( 'take-list' );
		list.replaceChildren();
		$( 'takes-empty' ).hidden = this.takes.length > 0;
		for ( const take of this.takes ) {

			const li = document.createElement( 'li' );
			li.dataset.take = take.id;
			li.className = take.id === this.selectedTake ? 'selected' : '';
			const [ start, stop ] = take.trim;
			li.innerHTML = `<label class="take-name"><input type="radio" name="take"></label>
				<span class="muted take-meta"></span>
				<span class="take-tools">
					<input class="trim-start" type="number" min="0" step="0.1" title="Trim: start (s)">
					<input class="trim-stop" type="number" min="0" step="0.1" title="Trim: stop (s)">
					<button class="quiet rename" title="Rename" aria-label="Rename">✎</button>
					<a class="button quiet download" title="Download the points (.npy)">⤓</a>
					<button class="quiet delete" title="Delete" aria-label="Delete">✕</button>
				</span>`;
			const radio = li.querySelector( 'input[type=radio]' );
			radio.checked = take.id === this.selectedTake;
			radio.after( document.createTextNode( ' ' + take.name ) );
			// click, not change: choosing the take already selected must still choose the take source
			radio.addEventListener( 'click', () => {

				this.selectedTake = take.id;
				$( 'source-select' ).value = 'take';
				this._renderTakes();

			} );
			li.querySelector( '.take-meta' ).textContent = `${ take.source || 'file' } · ${ take.n_points } pts ${ take.dims }D · ${ ( stop - start ).toFixed( 1 ) } / ${ take.duration.toFixed( 1 ) } s`;
			const startInput = li.querySelector( '.trim-start' ), stopInput = li.querySelector( '.trim-stop' );
			startInput.value = start.toFixed( 2 );
			stopInput.value = stop.toFixed( 2 );
			startInput.max = stopInput.max = take.duration.toFixed( 3 );
			const trim = () => this._guard( () => this._trim( take, Number( startInput.value ), Number( stopInput.value ) ) );
			startInput.addEventListener( 'change', trim );
			stopInput.addEventListener( 'change', trim );
			li.querySelector( '.rename' ).addEventListener( 'click', () => this._rename( take, li.querySelector( '.take-name' ) ) );
			li.querySelector( '.delete' ).addEventListener( 'click', () => this._guard( () => this._delete( take ) ) );
			const download = li.querySelector( '.download' );
			download.href = api.takePointsUrl( this.app.projectId, take.id );
			download.download = `${ take.name }.npy`;
			list.append( li );

		}

	}

	_regionRows( layoutName ) {

		const layout = this.app.layouts?.find( ( l ) => l.name === layoutName );
		const regions = layout ? [ ...new Set( layout.points.map( ( p ) => p.region ) ) ] : [];
		const table = $( 'gain-table' );
		const old = this.settings();
		table.querySelectorAll( 'tr[data-region]' ).forEach( ( r ) => r.remove() );
		for ( const region of regions ) {

			const row = document.createElement( 'tr' );
			row.dataset.region = region;
			row.innerHTML = `<td>${ region }</td>
				<td><input class="gain" type="range" min="0" max="2" step="0.05" title="Gain: 1 = as performed"></td>
				<td><input class="cutoff" type="number" min="0.01" max="30" step="0.1" title="One Euro minimum cutoff (Hz): lower = smoother at rest"></td>`;
			row.querySelector( '.gain' ).value = old.gain[ region ] ?? 1;
			row.querySelector( '.cutoff' ).value = old.one_euro[ region ]?.min_cutoff ?? 1;
			table.append( row );

		}

	}

	_layout() {

		const name = this.app.project?.landmarks?.layout || 'ibug68';
		const layout = this.app.layouts?.find( ( l ) => l.name === name );
		if ( ! layout ) throw new Error( `Unknown layout ${ name }.` );
		return layout;

	}

	// recording

	/**
	 * Follow `stream`'s 'started' replies, which the page keeps to itself: recording can
	 * begin once a source plays, and a restarted source records nothing any more.
	 */
	_watch( stream ) {

		if ( ! stream || stream === this._watched ) return;
		this._watched = stream;
		stream.addEventListener( 'message', ( event ) => {

			if ( stream !== this.app.stream || event.detail.type !== 'started' ) return;
			if ( this.recording && ! event.detail.recording ) this._note( 'The source started again: the recording so far was not kept.', true );
			this._setRecording( Boolean( event.detail.recording ) );

		} );

	}

	/** Show `on` in the record button, its tooltip and the elapsed-time badge. */
	_setRecording( on ) {

		const clock = this._recordClock;
		if ( on && ! this.recording ) {

			clock.since = performance.now();
			clock.timer = setInterval( () => this._showElapsed(), RECORD_TICK_MS );

		} else if ( ! on ) {

			clearInterval( clock.timer );

		}

		this.recording = on;
		const button = $( 'record' );
		button.textContent = on ? '■ Stop & save' : '● Record';
		button.classList.toggle( 'recording', on );
		button.disabled = ! this.app.streaming;
		button.title = ! this.app.streaming ? 'Press ▶ Play first: a recording keeps what the playing source (demo, webcam or take) performs.'
			: on ? 'Stop recording and keep it as a take under the name in the box' : 'Record what the source plays as a new take';
		this._showElapsed();

	}

	_showElapsed() {

		const seconds = ( performance.now() - this._recordClock.since ) / 1000;
		$( 'record-time' ).textContent = this.recording ? `REC ${ seconds.toFixed( 1 ) } s` : '';

	}

	_toggleRecording() {

		if ( ! this.app.streaming ) throw new Error( 'Nothing is playing to record: press ▶ Play first.' );
		if ( this.recording ) {

			this._saveRecording();

		} else {

			this.app.stream.send( { type: 'record' } );

		}

	}

	/** Ask the server to store the recording as a take (its reply, 'recorded', lists it). */
	_saveRecording() {

		const name = $( 'record-name' ).value.trim() || `${ this._playing } ${ new Date().toLocaleTimeString() }`;
		this.app.stream.send( { type: 'record_stop', name } );
		this._setRecording( false );

	}

	/** The server captures the webcam's neutral again: say so until a frame retargeted with it comes. */
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
			this._note( 'Webcam: neutral captured.' );

		};
		stream.addEventListener( 'frame', listener );
		this._neutralWait = { stream, listener };
		this._note( 'Webcam: hold a neutral face…' );

	}

	_endNeutralWait() {

		const wait = this._neutralWait;
		wait?.stream.removeEventListener( 'frame', wait.listener );
		this._neutralWait = null;

	}

	_sendSettings() {

		if ( this.app.streaming ) this.app.stream?.send( { type: 'settings', settings: this.settings() } );

	}

	async _withProgress( text, work ) {

		const bar = $( 'source-progress' );
		bar.hidden = false;
		bar.value = 0;
		this._note( text );
		try {

			return await work( ( fraction ) => {

				bar.value = fraction;

			} );

		} finally {

			bar.hidden = true;

		}

	}

	/** Say `text` under the take tools; `warn` shows it as a warning. */
	_note( text, warn = false ) {

		$( 'source-note' ).textContent = text;
		$( 'source-note' ).classList.toggle( 'warn', Boolean( warn ) );

	}

	/**
	 * Run an import or a tracking: the file controls wait until it ends, and a failure
	 * leaves no stale progress behind (bar hidden, note cleared) and shows why.
	 */
	async _task( work ) {

		const controls = [ 'take-file', 'video-file', 'video-method' ].map( $ );
		for ( const control of controls ) control.disabled = true;
		$( 'source-panel' ).classList.add( 'busy' );
		try {

			await work();

		} catch ( error ) {

			this._note( '' );
			this.app.errors.show( error );

		} finally {

			$( 'source-progress' ).hidden = true;
			for ( const control of controls ) control.disabled = false;
			$( 'source-panel' ).classList.remove( 'busy' );

		}

	}

	async _guard( fn ) {

		try {

			await fn();

		} catch ( error ) {

			this.app.errors.show( error );

		}

	}

	_bind() {

		$( 'take-file' ).addEventListener( 'change', ( event ) => {

			const file = event.target.files[ 0 ];
			event.target.value = '';
			if ( file ) this._task( () => this.importTake( file ) );

		} );
		$( 'video-file' ).addEventListener( 'click', ( event ) => {

			// a stereo pair is two videos and a calibration: its own form
			if ( $( 'video-method' ).value !== 'stereo' ) return;
			event.preventDefault();
			this.stereo.open();

		} );
		$( 'video-file' ).addEventListener( 'change', ( event ) => {

			const file = event.target.files[ 0 ];
			event.target.value = '';
			if ( file ) this._task( () => this.trackVideoFile( file ) );

		} );
		$( 'source-select' ).addEventListener( 'change', () => {

			if ( $( 'source-select' ).value !== 'webcam' ) this.stopWebcam();

		} );
		$( 'recapture-neutral' ).addEventListener( 'click', () => {

			this._neutralFrom = this._pointIndex;
			this.app.stream?.send( { type: 'neutral' } );

		} );
		$( 'record' ).addEventListener( 'click', () => this._guard( () => this._toggleRecording() ) );
		$( 'conditioning' ).addEventListener( 'change', () => this._sendSettings() );

	}

}

/**
 * A NumPy .npy file (format 1.0) of little-endian float32 values.
 * @param {Float32Array} values
 * @param {number[]} shape
 * @returns {Uint8Array}
 */
export function npyBytes( values, shape ) {

	let header = `{'descr': '<f4', 'fortran_order': False, 'shape': (${ shape.join( ', ' ) }${ shape.length === 1 ? ',' : '' }), }`;
	const unpadded = 10 + header.length + 1;
	header += ' '.repeat( ( 64 - ( unpadded % 64 ) ) % 64 ) + '\n';
	const bytes = new Uint8Array( 10 + header.length + 4 * values.length );
	bytes.set( [ 0x93, 0x4e, 0x55, 0x4d, 0x50, 0x59, 1, 0 ] );
	new DataView( bytes.buffer ).setUint16( 8, header.length, true );
	for ( let i = 0; i < header.length; i ++ ) bytes[ 10 + i ] = header.charCodeAt( i );
	new Float32Array( bytes.buffer, 10 + header.length ).set( values );
	return bytes;

}
