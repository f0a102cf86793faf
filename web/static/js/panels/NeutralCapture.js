import { $ } from './dom.js';

/** Seconds of the countdown before a webcam neutral is captured ("3, 2, 1"). */
export const COUNTDOWN_S = 3;
const CAPTURED_SHOWN_MS = 2500; // how long "Neutral captured" stays over the view

/**
 * The webcam's neutral capture as the performer sees it: a countdown over the viewer
 * ("Hold a neutral face: 3, 2, 1", index.html #neutral-overlay), then the capture window
 * ("hold still"), then either the captured neutral (a thumbnail of the camera image taken
 * as the capture began, #neutral-thumb, and "Neutral captured") or the server's refusal
 * (the performer moved: `retarget.sources.conditioning.NeutralMoved`), which stays shown
 * until the next capture. The server decides; this only counts, shows and says.
 */
export class NeutralCapture {

	constructor() {

		/** 'idle' | 'countdown' | 'capturing' | 'captured' | 'refused' */
		this.state = 'idle';
		this._timers = [];

	}

	/**
	 * Count down, then call `capture` (which starts the capture on the server) and show
	 * the capture window until `captured` or `refused` is called.
	 * @param {HTMLVideoElement} video - the camera, for the thumbnail.
	 * @param {() => void} capture
	 * @param {number} [seconds] - the capture window the conditioning asks for.
	 */
	start( video, capture, seconds = 0.5 ) {

		this.cancel();
		this.state = 'countdown';
		$( 'neutral-thumb-box' ).hidden = true;
		for ( let left = COUNTDOWN_S; left > 0; left -- ) {

			this._later( ( COUNTDOWN_S - left ) * 1000, () => this._say( `Hold a neutral face: ${ left }` ) );

		}

		this._later( COUNTDOWN_S * 1000, () => {

			this.state = 'capturing';
			this._snapshot( video );
			this._say( seconds > 0 ? `Hold still: capturing the neutral (${ seconds } s)…` : 'Hold still: capturing the neutral…' );
			capture();

		} );

	}

	/** The server retargets with the new neutral: show it. */
	captured() {

		if ( this.state !== 'capturing' ) return;
		this.state = 'captured';
		$( 'neutral-thumb-box' ).hidden = false;
		this._say( 'Neutral captured' );
		this._later( CAPTURED_SHOWN_MS, () => this._say( '' ) );

	}

	/**
	 * The server refused the capture.
	 * @param {string} reason - its detail ("You moved during the neutral capture: ...").
	 */
	refused( reason ) {

		this._clearTimers();
		this.state = 'refused';
		$( 'neutral-thumb-box' ).hidden = true;
		this._say( reason, true );

	}

	/** Stop counting and hide everything (the webcam stopped). */
	cancel() {

		this._clearTimers();
		this.state = 'idle';
		this._say( '' );
		$( 'neutral-thumb-box' ).hidden = true;

	}

	_say( text, warn = false ) {

		const overlay = $( 'neutral-overlay' );
		overlay.textContent = text;
		overlay.hidden = ! text;
		overlay.classList.toggle( 'warn', warn );

	}

	/** The camera image as the capture begins, drawn as the video shows it (mirrored). */
	_snapshot( video ) {

		const canvas = $( 'neutral-thumb' );
		const width = video.videoWidth, height = video.videoHeight;
		if ( ! width || ! height ) return;
		canvas.width = 160;
		canvas.height = Math.round( 160 * height / width );
		const context = canvas.getContext( '2d' );
		context.setTransform( - 1, 0, 0, 1, canvas.width, 0 );
		context.drawImage( video, 0, 0, canvas.width, canvas.height );

	}

	_later( ms, fn ) {

		this._timers.push( setTimeout( fn, ms ) );

	}

	_clearTimers() {

		this._timers.forEach( clearTimeout );
		this._timers = [];

	}

}
