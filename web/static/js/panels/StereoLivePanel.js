import { StereoPairEncoder } from '../net/wire.js';
import { StereoCapture, videoInputs } from '../tracking/StereoCapture.js';
import { guarded, option } from './dom.js';

// Pairs sent and not yet answered: enough to keep the server busy, few enough that a
// slow server never builds a backlog (each answer lets the next pair go).
const IN_FLIGHT = 2;

const HTML = `
	<h2>Live stereo</h2>
	<div class="row">
		<label for="live-stereo-split">Cameras</label>
		<select id="live-stereo-split" title="Two cameras, or one whose frame holds both views">
			<option value="none">two cameras</option>
			<option value="side">one, views side by side</option>
			<option value="top">one, views top and bottom</option>
		</select>
	</div>
	<div class="row">
		<label for="live-stereo-left">Left</label><select id="live-stereo-left"></select>
		<label for="live-stereo-right">Right</label><select id="live-stereo-right"></select>
		<button id="live-stereo-open" type="button">Open</button>
	</div>
	<div class="row stereo-previews">
		<video id="live-stereo-video-left" width="160" muted playsinline></video>
		<video id="live-stereo-video-right" width="160" muted playsinline></video>
	</div>
	<div class="row">
		<label for="live-stereo-board" title="Inner corners across x down, and the square's side in mm">Board</label>
		<input id="live-stereo-board" value="9x6" size="4">
		<input id="live-stereo-square" type="number" min="1" max="500" value="25" title="square, mm">
		<button id="live-stereo-calibrate" type="button" disabled>Calibrate</button>
		<button id="live-stereo-save" type="button" disabled>Save calibration</button>
	</div>
	<div class="row">
		<label for="live-stereo-markers">Markers</label>
		<select id="live-stereo-markers" title="What the face carries: the layout's coloured markers, or unnamed stickers of one colour (Woodward's): named by where they sit when the layout was made from a stereo take of them, else m01, m02, ... as first seen">
			<option value="layout">layout colours</option>
			<option value="stickers">stickers, one colour</option>
		</select>
		<input id="live-stereo-color" value="blue" size="9" disabled
			title="The stickers' colour: a name (blue, green, ...), B,G,R or hsv:H,S,V">
		<input id="live-stereo-anchors" value="" size="14" placeholder="anchors: chosen" disabled
			title="At least 3 stickers that move with the head only (temples, forehead, nose bridge), as numbered when first seen, e.g. m01,m03,m04; empty: the layout's head anchors, or else the most rigid ones, chosen after 3 s of talking and smiling">
	</div>
	<div class="row">
		<label for="live-stereo-quality">JPEG</label>
		<input id="live-stereo-quality" type="number" min="0.3" max="0.95" step="0.05" value="0.8">
		<button id="live-stereo-start" type="button" disabled>Start</button>
	</div>
	<div id="live-stereo-status" class="note"></div>`;

/**
 * Live stereo from two cameras (Woodward et al.): pick the cameras (or one split in two),
 * calibrate on a checkerboard shown to both (the server counts the good views, then saves
 * the calibration with the project), then Start: each frame pair goes to the server as
 * two JPEGs (RTSJ, `WS .../stereo/live`), whose tracked points drive the project's stream
 * as the webcam's do. The panel shows frames per second and the bandwidth.
 *
 * Markers: the layout's colour markers, or unnamed stickers of one colour (a colour, and
 * optionally the anchors m01, ...). When the project's layout was made from a stereo take
 * of the stickers (it keeps each one's place), the server names them by where they sit;
 * otherwise it numbers them as it first sees them and sticker mK drives the landmark named
 * mK (a custom layout named m01..mM). The hello's sticker_points counts the landmarks
 * stickers can drive; without any the choice is disabled.
 */
export class StereoLivePanel {

	/** @param {import('../App.js').App} app */
	constructor( app ) {

		this.app = app;
		this.element = document.createElement( 'section' );
		this.element.id = 'live-stereo-panel';
		this.element.innerHTML = HTML;
		document.getElementById( 'source-panel' ).after( this.element );
		const el = ( id ) => this.element.querySelector( `#${ id }` );
		this.el = el;
		this.capture = null;
		this.socket = null;
		this.mode = null; // 'calibrate' | 'track' | null
		this.inFlight = 0;
		this.sent = []; // [performance.now(), bytes] of the last second's pairs
		this.answered = []; // performance.now() of the last second's answers
		this.frame = 0;
		this.pumping = false;
		this.last = null; // the server's last answer (tests read it)
		const run = ( fn ) => guarded( app.errors, fn );
		el( 'live-stereo-open' ).addEventListener( 'click', run( () => this.open() ) );
		el( 'live-stereo-calibrate' ).addEventListener( 'click', run( () => this.calibrate() ) );
		el( 'live-stereo-save' ).addEventListener( 'click', run( () => this.request( { type: 'calibration_save' } ) ) );
		el( 'live-stereo-start' ).addEventListener( 'click', run( () => ( this.mode === 'track' ? this.stop() : this.start() ) ) );
		el( 'live-stereo-split' ).addEventListener( 'change', () => ( el( 'live-stereo-right' ).disabled = el( 'live-stereo-split' ).value !== 'none' ) );
		el( 'live-stereo-markers' ).addEventListener( 'change', () => this.markersChanged() );
		this.listCameras().catch( ( error ) => app.errors.show( error ) );

	}

	async listCameras() {

		const cameras = await videoInputs();
		for ( const [ side, id ] of [ [ 0, 'live-stereo-left' ], [ 1, 'live-stereo-right' ] ] ) {

			const select = this.el( id );
			select.replaceChildren( ...cameras.map( ( c, i ) => option( c.deviceId, c.label || `camera ${ i + 1 }` ) ) );
			if ( cameras.length > side ) select.selectedIndex = side;

		}

	}

	/** Open the chosen cameras and the project's stereo socket. */
	async open() {

		this.close();
		const split = this.el( 'live-stereo-split' ).value;
		this.capture = new StereoCapture( [ this.el( 'live-stereo-video-left' ), this.el( 'live-stereo-video-right' ) ],
			{ left: this.el( 'live-stereo-left' ).value, right: this.el( 'live-stereo-right' ).value, split } );
		await this.capture.open();
		await this.listCameras(); // labels once a camera is allowed
		const hello = await this.connect( this.app.projectId );
		this.status( hello.calibration
			? `Calibrated: ${ hello.calibration.views } views, ${ hello.calibration.rms.toFixed( 2 ) } px, baseline ${ hello.calibration.baseline.toFixed( 0 ) } mm`
			: 'Not calibrated yet: show a checkerboard to both cameras and press Calibrate' );
		this.el( 'live-stereo-calibrate' ).disabled = false;
		this.el( 'live-stereo-start' ).disabled = ! hello.calibration;
		const stickers = this.el( 'live-stereo-markers' ).querySelector( 'option[value="stickers"]' );
		stickers.disabled = ! hello.sticker_points;
		stickers.title = hello.sticker_points
			? `${ hello.sticker_points } landmarks can be driven by stickers`
			: 'No landmark can be driven by stickers: make the layout from a stereo take of them, or name its points m01, m02, ...';
		if ( stickers.disabled ) this.el( 'live-stereo-markers' ).value = 'layout';
		this.markersChanged();

	}

	markersChanged() {

		const stickers = this.el( 'live-stereo-markers' ).value === 'stickers';
		this.el( 'live-stereo-color' ).disabled = this.el( 'live-stereo-anchors' ).disabled = ! stickers;

	}

	/** The start message's marker choice: {} for the layout's colours. */
	markers() {

		if ( this.el( 'live-stereo-markers' ).value !== 'stickers' ) return {};
		const anchors = this.el( 'live-stereo-anchors' ).value.split( /[\s,;]+/ ).filter( Boolean );
		return { markers: 'stickers', color: this.el( 'live-stereo-color' ).value.trim(), anchors: anchors.length ? anchors : null };

	}

	connect( projectId ) {

		const url = `${ location.protocol === 'https:' ? 'wss' : 'ws' }://${ location.host }/api/projects/${ encodeURIComponent( projectId ) }/stereo/live`;
		const socket = new WebSocket( url );
		this.socket = socket;
		return new Promise( ( resolve, reject ) => {

			socket.addEventListener( 'message', ( event ) => {

				const message = JSON.parse( event.data );
				if ( message.type === 'hello' ) resolve( message );
				else this.answer( message );

			} );
			socket.addEventListener( 'close', ( event ) => {

				reject( new Error( `The stereo connection closed: ${ event.reason || event.code }` ) );
				if ( this.socket === socket ) this.ended( event.reason );

			} );

		} );

	}

	async calibrate() {

		const [ cols, rows ] = this.el( 'live-stereo-board' ).value.split( 'x' ).map( Number );
		const square = Number( this.el( 'live-stereo-square' ).value );
		this.request( { type: 'calibrate', pattern: { cols, rows, square }, size: this.capture.size } );
		this.mode = 'calibrate';
		this.pump();

	}

	start() {

		this.request( { type: 'start', ...this.markers(), settings: this.app.conditioning.toJSON() } );
		this.mode = 'track';
		this.el( 'live-stereo-start' ).textContent = 'Stop';
		this.pump();

	}

	stop() {

		this.request( { type: 'stop' } );
		this.mode = null;
		this.el( 'live-stereo-start' ).textContent = 'Start';

	}

	request( message ) {

		this.socket.send( JSON.stringify( message ) );

	}

	/** Send frame pairs while a mode runs, at most IN_FLIGHT unanswered. */
	async pump() {

		if ( this.pumping ) return; // one loop: pairs leave in the order they were grabbed
		this.pumping = true;
		try {

			while ( this.mode && this.inFlight < IN_FLIGHT && this.socket?.readyState === WebSocket.OPEN ) {

				const { left, right, time } = await this.capture.grab( Number( this.el( 'live-stereo-quality' ).value ) );
				if ( ! this.mode || this.socket?.readyState !== WebSocket.OPEN ) return;
				const buffer = new StereoPairEncoder().encode( left, right, this.frame ++, time );
				this.socket.send( buffer );
				this.inFlight ++;
				this.sent.push( [ performance.now(), buffer.byteLength ] );

			}

		} finally {

			this.pumping = false;

		}

	}

	answer( message ) {

		this.last = message;
		if ( message.type === 'views' || message.type === 'tracked' || ( message.type === 'error' && this.inFlight ) ) {

			this.inFlight = Math.max( 0, this.inFlight - 1 );
			this.answered.push( performance.now() );
			this.pump().catch( ( error ) => this.app.errors.show( error ) );

		}

		// a view answered after the save must not overwrite the 'Calibrated' status
		if ( message.type === 'views' && this.mode === 'calibrate' ) {

			this.el( 'live-stereo-save' ).disabled = message.count < message.needed;
			this.status( `Good views: ${ message.count } of ${ message.needed } needed${ message.good ? ' (+1)' : '' } · ${ this.rates() }` );

		} else if ( message.type === 'tracked' ) {

			const stickers = message.stickers === undefined ? ''
				: ` · ${ message.stickers } stickers${ message.anchors.length ? `, anchors ${ message.anchors.join( ' ' ) }` : '' }`;
			// points the neutral was taken without (a temple seen only as the head turns) join when they show
			const waiting = message.waiting && message.waiting.length ? ` · waiting for ${ message.waiting.join( ', ' ) } to show` : '';
			this.status( `${ message.found }/${ message.n_points } points${ stickers } · ${ this.rates() }${ waiting }${ message.detail ? ` · ${ message.detail }` : '' }` );

		} else if ( message.type === 'calibrated' ) {

			this.mode = null;
			const c = message.calibration;
			this.status( `Calibrated: ${ c.views } views, ${ c.rms.toFixed( 2 ) } px, baseline ${ c.baseline.toFixed( 0 ) } mm` );
			this.el( 'live-stereo-start' ).disabled = false;

		} else if ( message.type === 'error' ) {

			this.app.errors.show( message.detail );
			if ( /calibrate the cameras first|before the frames|"markers"|"color"|"anchors"|sticker colour|stickers are unnamed/.test( message.detail ) ) this.stop();

		} else if ( message.type === 'ended' ) {

			this.app.errors.show( message.detail );

		}

	}

	/** "12.0 fps · 85 kB/s" over the last second. */
	rates() {

		const now = performance.now();
		this.sent = this.sent.filter( ( [ t ] ) => now - t < 1000 );
		this.answered = this.answered.filter( ( t ) => now - t < 1000 );
		const bytes = this.sent.reduce( ( sum, [ , n ] ) => sum + n, 0 );
		return `${ this.answered.length } fps · ${ Math.round( bytes / 1000 ) } kB/s`;

	}

	ended( reason ) {

		this.mode = null;
		this.inFlight = 0;
		this.socket = null;
		this.el( 'live-stereo-start' ).textContent = 'Start';
		this.el( 'live-stereo-start' ).disabled = this.el( 'live-stereo-calibrate' ).disabled = true;
		this.status( `Disconnected${ reason ? `: ${ reason }` : '' }; Open again` );

	}

	status( text ) {

		this.el( 'live-stereo-status' ).textContent = text;

	}

	/** Close the cameras and the socket (idempotent). */
	close() {

		this.mode = null;
		const socket = this.socket;
		this.socket = null;
		socket?.close();
		this.capture?.close();
		this.capture = null;

	}

}
