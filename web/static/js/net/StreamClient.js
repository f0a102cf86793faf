import { ArkitWeightsDecoder, ContractionDecoder, StreamDecoder } from './wire.js';

const BACKOFF_MIN_MS = 250;
const BACKOFF_MAX_MS = 5000;
const POLICY_VIOLATION = 1008;
const FPS_WINDOW_MS = 1000;
const LATENCY_FRAMES = 300;

/**
 * The live stream of a project's target feature displacements (WS /api/projects/{id}/stream).
 *
 * Events:
 * - 'hello'   detail: the server's hello JSON ({type, project, n_points, layout, source});
 * - 'frame'   detail: a decoded frame (StreamDecoder.decode; its displacements view the
 *             message's bytes);
 * - 'arkit'   detail: a decoded ARKit weight frame of a source driven by ARKit's 52
 *   blendshapes (ArkitWeightsDecoder.decode; its weights view the message);
 * - 'contractions' detail: a decoded contraction frame of a source driven by muscles
 *             (ContractionDecoder.decode);
 * - 'message' detail: any other JSON the server sends (started, stopped, mask, pong, error);
 * - 'status'  detail: {state: 'connecting'|'open'|'reconnecting'|'closed', reason?}.
 *
 * After a dropped connection it reconnects with exponential backoff (0.25 s doubling to 5 s)
 * and re-sends the last start, mask and drive controls, since the server stops a project's source
 * when its last viewer leaves. It does not reconnect after `close()` or when the server
 * refuses the project (close code 1008, e.g. no landmarks yet): that reason is the 'closed'
 * status's `reason`.
 */
export class StreamClient extends EventTarget {

	/**
	 * @param {string} projectId
	 * @param {{url?: string}} [options] - the WebSocket URL; by default this page's host.
	 */
	constructor( projectId, { url } = {} ) {

		super();
		this.projectId = projectId;
		this.url = url ?? `${ location.protocol === 'https:' ? 'wss' : 'ws' }://${ location.host }/api/projects/${ encodeURIComponent( projectId ) }/stream`;
		/** 'idle' before connect(), then the last status state. */
		this.state = 'idle';

		this._decoder = new StreamDecoder();
		this._contractions = new ContractionDecoder();
		this._arkit = new ArkitWeightsDecoder();
		this._socket = null;
		this._closed = false;
		this._attempts = 0; // connections lost since the last hello
		this._reconnectTimer = null;
		this._queue = []; // controls sent before the socket opened, other than start and mask
		this._replayed = { mask: null, drive: null, start: null, settings: null }; // the last ones sent, for a reconnect

		this._frames = 0;
		this._arrivals = []; // performance.now() of the frames received in the last second, ms
		this._latencies = new Float64Array( LATENCY_FRAMES ); // a ring of applied-frame latencies, ms
		this._latencyCount = 0;

	}

	/** Open the connection (again, after `close()`). */
	connect() {

		if ( this._socket !== null ) return;
		this._closed = false;
		this._attempts = 0;
		clearTimeout( this._reconnectTimer );
		this._open( 'connecting' );

	}

	/** Close for good: no reconnect, and nothing queued or replayed, until `connect()`. */
	close() {

		this._closed = true;
		clearTimeout( this._reconnectTimer );
		this._queue.length = 0;
		this._replayed = { mask: null, drive: null, start: null, settings: null };
		const socket = this._socket;
		this._socket = null;
		if ( socket !== null ) {

			detach( socket );
			socket.close( 1000, 'closed by the page' );

		}

		this._setState( 'closed', 'closed by the page' );

	}

	/**
	 * Send a JSON control message ({type: 'start'|'stop'|'mask'|'ping', ...}), now or as
	 * soon as the connection opens.
	 * @param {Object} message
	 */
	send( message ) {

		if ( message === null || typeof message !== 'object' || typeof message.type !== 'string' ) {

			throw new TypeError( `StreamClient.send: a control message is an object with a string "type"; got ${ JSON.stringify( message ) }.` );

		}

		const text = JSON.stringify( message );
		const replayed = message.type in this._replayed;
		if ( replayed ) this._replayed[ message.type ] = text;
		if ( message.type === 'start' || message.type === 'stop' ) this._replayed.settings = null;
		if ( message.type === 'stop' ) this._replayed.start = null;

		if ( this._socket !== null && this._socket.readyState === WebSocket.OPEN ) {

			this._socket.send( text );

		} else if ( ! replayed ) {

			this._queue.push( text ); // start and mask go out with the replay on open

		}

	}

	/**
	 * Send one binary source-points message (PointsEncoder) if the socket is open. Tracked
	 * frames are perishable: while (re)connecting they are dropped, not queued.
	 * @param {ArrayBuffer} buffer
	 * @returns {boolean} whether it was sent
	 */
	sendPoints( buffer ) {

		if ( this._socket === null || this._socket.readyState !== WebSocket.OPEN ) return false;
		this._socket.send( buffer );
		return true;

	}

	/**
	 * Record that `frame`'s displacements are now on screen (call it after applying them),
	 * for the latency statistics.
	 * @param {{sendTime: number}} frame - sendTime: epoch seconds when the server sent it.
	 */
	markApplied( frame ) {

		// the wall clock, as the server's send time is: timeOrigin + now() follows the
		// monotonic clock from the browser's start, and drifted 7 ms from the wall clock in a
		// test run, which made the median latency negative
		const appliedMs = Date.now();
		this._latencies[ this._latencyCount % LATENCY_FRAMES ] = appliedMs - frame.sendTime * 1000;
		this._latencyCount ++;

	}

	/**
	 * @returns {{fps: number, latencyMs: {median: number, p99: number}, frames: number}} fps:
	 *   frames received in the last second; latency: applied time minus the server's send time
	 *   over the last 300 applied frames (NaN before the first), ms; frames: received in all.
	 */
	get stats() {

		this._forgetArrivalsBefore( performance.now() - FPS_WINDOW_MS );
		const n = Math.min( this._latencyCount, LATENCY_FRAMES );
		const sorted = this._latencies.slice( 0, n ).sort();
		return {
			fps: this._arrivals.length * 1000 / FPS_WINDOW_MS,
			latencyMs: { median: quantile( sorted, 0.5 ), p99: quantile( sorted, 0.99 ) },
			frames: this._frames,
		};

	}

	_open( state ) {

		this._setState( state );
		const socket = new WebSocket( this.url );
		socket.binaryType = 'arraybuffer';
		socket.onopen = () => this._onOpen();
		socket.onmessage = ( event ) => this._onMessage( event );
		socket.onclose = ( event ) => this._onClose( event );
		this._socket = socket;

	}

	_onOpen() {

		this._setState( 'open' );
		// mask and drive first, so the first frames after a start are already masked and driven
		const { mask, drive, start, settings } = this._replayed;
		for ( const text of [ mask, drive, start, settings, ...this._queue ] ) {

			if ( text !== null ) this._socket.send( text );

		}

		this._queue.length = 0;

	}

	_onMessage( event ) {

		if ( event.data instanceof ArrayBuffer ) {

			const magic = event.data.byteLength >= 4 ? new DataView( event.data ).getUint32( 0, true ) : 0;
			const kind = magic === ContractionDecoder.MAGIC ? 'contractions' : magic === ArkitWeightsDecoder.MAGIC ? 'arkit' : 'frame';
			const frame = ( kind === 'contractions' ? this._contractions : kind === 'arkit' ? this._arkit : this._decoder ).decode( event.data );
			this._frames ++;
			const now = performance.now();
			this._arrivals.push( now );
			this._forgetArrivalsBefore( now - FPS_WINDOW_MS );
			this.dispatchEvent( new CustomEvent( kind, { detail: frame } ) );
			return;

		}

		const message = JSON.parse( event.data );
		// the backoff restarts only once the server has accepted the stream: one that opens
		// and then drops every connection is still retried ever more slowly
		if ( message.type === 'hello' ) this._attempts = 0;
		this.dispatchEvent( new CustomEvent( message.type === 'hello' ? 'hello' : 'message', { detail: message } ) );

	}

	_onClose( event ) {

		detach( event.target );
		this._socket = null;
		if ( this._closed ) return;
		if ( event.code === POLICY_VIOLATION ) {

			this._closed = true;
			this._setState( 'closed', event.reason || 'the server refused the stream' );
			return;

		}

		const delay = Math.min( BACKOFF_MAX_MS, BACKOFF_MIN_MS * 2 ** this._attempts );
		this._attempts ++;
		this._setState( 'reconnecting', `connection lost (code ${ event.code }); retrying in ${ ( delay / 1000 ).toFixed( 2 ) } s` );
		this._reconnectTimer = setTimeout( () => this._open( 'reconnecting' ), delay );

	}

	_setState( state, reason ) {

		this.state = state;
		const detail = reason === undefined ? { state } : { state, reason };
		this.dispatchEvent( new CustomEvent( 'status', { detail } ) );

	}

	_forgetArrivalsBefore( time ) {

		let stale = 0;
		while ( stale < this._arrivals.length && this._arrivals[ stale ] <= time ) stale ++;
		if ( stale > 0 ) this._arrivals.splice( 0, stale );

	}

}

function detach( socket ) {

	socket.onopen = socket.onmessage = socket.onclose = null;

}

/** Linear-interpolated quantile of an ascending array; NaN when it is empty. */
function quantile( sorted, q ) {

	if ( sorted.length === 0 ) return NaN;
	const position = q * ( sorted.length - 1 );
	const below = Math.floor( position );
	const above = Math.min( below + 1, sorted.length - 1 );
	return sorted[ below ] + ( sorted[ above ] - sorted[ below ] ) * ( position - below );

}
