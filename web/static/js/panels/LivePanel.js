import { StreamClient } from '../net/StreamClient.js';
import { StreamDecoder } from '../net/wire.js';
import { regionColor } from '../scene/palette.js';
import { $, guarded } from './dom.js';
import { PointsToggle } from './PointsToggle.js';

const STATS_MS = 250;

/**
 * The Live panel (index.html #live-panel) and the project's stream: *Play* starts the
 * Performance panel's source, *Stop* stops it; frames pose the face and the markers (and
 * turn the face with the performer's head when the conditioning says so), or, driven by
 * muscles, pose the face's muscles and feed the expression readout and the Muscles
 * panel's sliders; the status
 * badge, frame rate and latency; the region toggles, a view of the page's RegionMask
 * (`app.regions`), whose `movingRegions()` the stream's mask is. The feature points hide
 * while a source plays (PointsToggle, the view's *Show points*).
 */
export class LivePanel {

	/**
	 * @param {import('../App.js').App} app
	 */
	constructor( app ) {

		this.app = app;
		/** @type {StreamClient|null} */
		this.stream = null;
		/** Whether a source is playing on the stream. */
		this.streaming = false;
		/** (D) the contractions on the face from the last contraction frame, or null. */
		this.lastContractions = null;
		this.points = new PointsToggle( app.picker );
		this._events = new AbortController();
		this._stats = setInterval( () => this._showStats(), STATS_MS );
		this._bind();

	}

	/** Open a new stream for the shown project (its saved landmarks), closing the old one. */
	connect() {

		const app = this.app, old = this.stream;
		const stream = new StreamClient( app.projectId );
		this.stream = stream; // before closing the old one, whose 'closed' status is then ignored
		old?.close();
		this.streaming = false;
		stream.addEventListener( 'status', ( event ) => {

			if ( stream !== this.stream ) return;
			const { state, reason } = event.detail;
			const badge = $( 'status' );
			badge.textContent = state;
			badge.className = 'badge' + ( state === 'open' ? ' good' : state === 'closed' ? ' bad' : ' warn' );
			badge.title = reason || '';
			if ( state !== 'open' ) this._setStreaming( false );
			if ( state === 'closed' && reason ) app.errors.show( `Live stream closed: ${ reason }` );

		} );
		stream.addEventListener( 'frame', ( event ) => {

			if ( stream !== this.stream || ! app.face ) return;
			const frame = event.detail;
			app.face.setDisplacements( frame.displacements );
			app.face.setHeadRotation( frame.headRotation ); // a source's head pose, when the conditioning applies it
			app.picker.setDisplacements( frame.displacements );
			stream.markApplied( frame );
			if ( frame.flags & StreamDecoder.FLAG_LAST ) this._setStreaming( false );

		} );
		stream.addEventListener( 'contractions', ( event ) => {

			if ( stream !== this.stream || ! app.face?.muscles ) return; // the muscles are loading
			const frame = event.detail;
			app.face.setContractions( frame.contractions );
			app.face.setHeadRotation( frame.headRotation );
			this.lastContractions = Float32Array.from( frame.contractions ); // the frame views the message
			app.sources.expressions.push( frame );
			app.muscles.show( frame.contractions );
			stream.markApplied( frame );
			if ( frame.flags & StreamDecoder.FLAG_LAST ) this._setStreaming( false );

		} );
		stream.addEventListener( 'arkit', ( event ) => {

			if ( stream !== this.stream || ! app.face?.arkit ) return; // the shapes are loading
			const frame = event.detail;
			app.face.setArkitWeights( frame.weights );
			app.face.setHeadRotation( frame.headRotation );
			app.blendshapes.show( frame.weights );
			stream.markApplied( frame );
			if ( frame.flags & StreamDecoder.FLAG_LAST ) this._setStreaming( false );

		} );
		stream.addEventListener( 'message', ( event ) => {

			if ( stream !== this.stream ) return;
			const message = event.detail;
			if ( message.type === 'started' ) this._setStreaming( true );
			else if ( message.type === 'stopped' ) this._setStreaming( false );
			else if ( message.type === 'error' ) app.errors.show( `Live stream: ${ message.detail }` );
			else app.sources.onMessage( message );

		} );
		stream.connect();

	}

	/** Close the stream (another project is being opened). */
	close() {

		if ( this.stream ) {

			const stream = this.stream;
			this.stream = null; // first: its 'closed' status is no news to report
			stream.close();

		}

		this.streaming = false;
		$( 'status' ).textContent = 'offline';
		$( 'status' ).className = 'badge';
		this.points.setPlaying( false );
		// the figures were the old project's stream's
		$( 'fps' ).textContent = '–';
		$( 'latency' ).textContent = '–';
		$( 'play' ).textContent = '▶ Play';
		$( 'stop' ).disabled = true;

	}

	/**
	 * The region toggles of a layout's regions that have points, ticked as the region
	 * mask says.
	 * @param {{regions: string[], points: Array<{region: string}>}|null} layout
	 */
	setLayout( layout ) {

		const mask = this.app.regions;
		mask.setRegions( layout ? layout.regions.filter( ( region ) => layout.points.some( ( p ) => p.region === region ) ) : [] );
		const fieldset = $( 'regions' );
		fieldset.replaceChildren( fieldset.querySelector( 'legend' ), ...mask.regions.map( ( region ) => {

			const label = document.createElement( 'label' );
			const box = document.createElement( 'input' );
			box.type = 'checkbox';
			box.checked = mask.moves( region );
			box.dataset.region = region;
			const swatch = document.createElement( 'span' );
			swatch.className = 'swatch';
			swatch.style.background = regionColor( region );
			label.append( box, swatch, region.replace( /_/g, ' ' ) );
			return label;

		} ) );

	}

	/** Send the region mask, if a stream is open or opening. */
	sendMask() {

		this.stream?.send( { type: 'mask', regions: this.app.regions.movingRegions() } );

	}

	/**
	 * What the stream still needs before it can play, or '' when it can.
	 * @returns {string}
	 */
	missing() {

		const project = this.app.project, landmarks = this.app.landmarks;
		if ( ! project ) return 'Create a project first.';
		if ( ! project.mesh ) return 'Upload a mesh first.';
		if ( ! project.landmarks ) return `Place and save the ${ landmarks.layout?.n_points ?? '' } landmarks first (${ landmarks.placedCount } placed).`;
		if ( ! project.rig && this.app.sources.drive === 'points' ) return 'Compute the rig first (or drive by muscles or ARKit shapes): the stream moves the feature points, the rig carries them to the skin.';
		return '';

	}

	/** The note under Play: what is missing, or that unsaved landmarks are not what plays. */
	update() {

		const missing = this.missing();
		const note = $( 'live-note' );
		note.textContent = missing || ( this.app.landmarks.dirty && this.app.project?.landmarks ? 'The stream drives the saved landmarks; save to use your edits.' : '' );
		note.className = 'note' + ( missing ? ' warn' : '' );
		$( 'play' ).title = missing || 'Play the chosen performance source on this face';
		$( 'stop' ).disabled = ! this.streaming;

	}

	/** Stop listening and polling the statistics; close the stream. */
	dispose() {

		this._events.abort();
		this.points.dispose();
		clearInterval( this._stats );
		this.close();

	}

	/** Play the Performance panel's source (what *Play* does); a reason shows when it cannot. */
	async play() {

		const missing = this.missing();
		if ( missing ) {

			this.app.errors.show( `Cannot play: ${ missing }` );
			return;

		}

		if ( ! this.stream ) this.connect();
		const drive = this.app.sources.drive;
		if ( drive === 'muscles' ) await this.app.muscles.load();
		if ( drive === 'arkit' ) await this.app.blendshapes.load();
		const start = await this.app.sources.startMessage();
		this.sendMask();
		this.stream.send( { type: 'drive', drive } ); // a new stream (new landmarks) knows none yet
		this.stream.send( start );

	}

	_stop() {

		this.stream?.send( { type: 'stop' } );
		this.app.sources.stopWebcam();
		this._setStreaming( false );

	}

	_setStreaming( on ) {

		this.streaming = on;
		this.points.setPlaying( on );
		$( 'play' ).textContent = on ? '↻ Restart' : '▶ Play';
		$( 'stop' ).disabled = ! on;
		if ( ! on ) {

			$( 'fps' ).textContent = '–';
			this.app.face?.setHeadRotation( null );
			this.app.sources.onStopped();

		}

	}

	_showStats() {

		const stream = this.stream;
		if ( ! stream || ! this.streaming || ! stream.stats.frames ) return;
		const { fps, latencyMs } = stream.stats;
		$( 'fps' ).textContent = fps.toFixed( 0 );
		if ( Number.isFinite( latencyMs.median ) ) $( 'latency' ).textContent = `${ latencyMs.median.toFixed( 1 ) } / ${ latencyMs.p99.toFixed( 1 ) } ms`;

	}

	_bind() {

		const signal = this._events.signal;
		$( 'play' ).addEventListener( 'click', guarded( this.app.errors, () => this.play() ), { signal } );
		$( 'stop' ).addEventListener( 'click', () => this._stop(), { signal } );
		$( 'regions' ).addEventListener( 'change', ( event ) => {

			const region = event.target.dataset?.region;
			if ( region ) this.app.regions.setMoving( region, event.target.checked );

		}, { signal } );

	}

}
