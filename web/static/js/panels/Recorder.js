import { $, guarded } from './dom.js';

const RECORD_TICK_MS = 100;

/**
 * *Record* in the Performance panel: whatever source plays is kept as a new take. The
 * server records between `record` and `record_stop` and answers 'recorded' with the take;
 * the button shows the state, the badge the seconds so far.
 */
export class Recorder {

	/**
	 * @param {import('../App.js').App} app
	 * @param {import('./SourceStatus.js').SourceStatus} status - the panel's note.
	 */
	constructor( app, status ) {

		this.app = app;
		this.status = status;
		/** Whether the server records. */
		this.recording = false;
		/** What the last start plays, for a recording's default name. */
		this.playing = '';
		this._watched = null; // the stream whose 'started' replies enable recording
		this._clock = { since: 0, timer: 0 }; // performance.now() the recording began, ms
		this._events = new AbortController();
		$( 'record' ).addEventListener( 'click', guarded( app.errors, () => this._toggle() ), { signal: this._events.signal } );
		this.set( false ); // disabled until a source plays, and why

	}

	/**
	 * Follow `stream`'s 'started' replies, which the page keeps to itself: recording can
	 * begin once a source plays, and a restarted source records nothing any more.
	 * @param {import('../net/StreamClient.js').StreamClient|null} stream
	 */
	watch( stream ) {

		if ( ! stream || stream === this._watched ) return;
		this._watched = stream;
		stream.addEventListener( 'message', ( event ) => {

			if ( stream !== this.app.stream || event.detail.type !== 'started' ) return;
			if ( this.recording && ! event.detail.recording ) this.status.note( 'The source started again: the recording so far was not kept.', true );
			this.set( Boolean( event.detail.recording ) );

		} );

	}

	/**
	 * Show `on` in the record button, its tooltip and the elapsed-time badge.
	 * @param {boolean} on
	 */
	set( on ) {

		const clock = this._clock;
		if ( on && ! this.recording ) {

			clock.since = performance.now();
			clock.timer = setInterval( () => this._showElapsed(), RECORD_TICK_MS );

		} else if ( ! on ) {

			clearInterval( clock.timer );

		}

		this.recording = on;
		const button = $( 'record' ), streaming = this.app.streaming;
		button.textContent = on ? '■ Stop & save' : '● Record';
		button.classList.toggle( 'recording', on );
		button.disabled = ! streaming;
		button.title = ! streaming ? 'Press ▶ Play first: a recording keeps what the playing source (demo, webcam or take) performs.'
			: on ? 'Stop recording and keep it as a take under the name in the box' : 'Record what the source plays as a new take';
		this._showElapsed();

	}

	/** Ask the server to store the recording as a take (its reply, 'recorded', lists it). */
	save() {

		const name = $( 'record-name' ).value.trim() || `${ this.playing } ${ new Date().toLocaleTimeString() }`;
		this.app.stream.send( { type: 'record_stop', name } );
		this.set( false );

	}

	/** The server stored a recording: the next one is another take. */
	saved() {

		$( 'record-name' ).value = '';

	}

	/** Stop listening and ticking. */
	dispose() {

		this._events.abort();
		clearInterval( this._clock.timer );

	}

	_showElapsed() {

		const seconds = ( performance.now() - this._clock.since ) / 1000;
		$( 'record-time' ).textContent = this.recording ? `REC ${ seconds.toFixed( 1 ) } s` : '';

	}

	_toggle() {

		if ( ! this.app.streaming ) throw new Error( 'Nothing is playing to record: press ▶ Play first.' );
		if ( this.recording ) this.save();
		else this.app.stream.send( { type: 'record' } );

	}

}
