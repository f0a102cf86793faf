/**
 * How many frames a video file holds and at what rate, read from its container's index
 * without decoding: MP4 / MOV (ISO/IEC 14496-12: the first video track's sample table,
 * `stts`) and WebM / Matroska (the first video track's blocks and their timestamps).
 *
 * A <video> element states neither, and measuring them from playback depends on how busy
 * the page is; the container's index does not.
 */

const STANDARD_FPS = [ 23.976, 24, 25, 29.97, 30, 48, 50, 59.94, 60, 90, 100, 119.88, 120 ];
const CHUNK = 1 << 20; // bytes read from the file at a time
const BOX_HEADER = 16; // bytes: 32-bit size, type, and a 64-bit size when the first is 1
const MP4_FIRST_BOXES = new Set( [ 'ftyp', 'moov', 'mdat', 'wide', 'free', 'skip' ] ); // old QuickTime files have no ftyp

// Matroska element IDs (with their length marker, as written)
const EBML = 0x1A45DFA3;
const SEGMENT = 0x18538067, INFO = 0x1549A966, TIMESTAMP_SCALE = 0x2AD7B1;
const TRACKS = 0x1654AE6B, TRACK_ENTRY = 0xAE, TRACK_NUMBER = 0xD7, TRACK_TYPE = 0x83;
const CLUSTER = 0x1F43B675, CLUSTER_TIMESTAMP = 0xE7, SIMPLE_BLOCK = 0xA3, BLOCK_GROUP = 0xA0, BLOCK = 0xA1;
const ENTERED = new Set( [ SEGMENT, INFO, TRACKS, TRACK_ENTRY, CLUSTER, BLOCK_GROUP ] ); // masters read inside
const VIDEO_TRACK = 1;

/**
 * The frames of a video file's first video track, from its container.
 * @param {Blob} blob
 * @returns {Promise<{count: number, fps: number|null, start: number}|null>} count: frames;
 *   fps: the mean rate (frames per second over the time they span; null for one frame),
 *   snapped to a standard rate (29.97, 30, ...) when it is one within the precision of the
 *   container's timestamps;
 *   start: the first frame's presentation time, s. Null for another container, or one
 *   that does not index its frames this way (fragmented or cut MP4). A cut WebM counts the
 *   frames before the cut.
 */
export async function containerFrames( blob ) {

	const reader = new ChunkReader( blob );
	const head = await reader.view( 0, 8 );
	if ( head === null ) return null;
	try {

		if ( head.getUint32( 0 ) === EBML ) return await matroskaFrames( reader );
		if ( MP4_FIRST_BOXES.has( fourcc( head, 4 ) ) ) return await mp4Frames( reader );

	} catch ( error ) {

		if ( error instanceof RangeError ) return null; // an index that runs past its box or the file
		throw error;

	}

	return null;

}

/** Reads a Blob in CHUNK-sized windows: sequential small reads cost one file read per chunk. */
class ChunkReader {

	constructor( blob ) {

		this.blob = blob;
		this.size = blob.size;
		this._start = 0;
		this._bytes = new Uint8Array( 0 );

	}

	/**
	 * @returns {Promise<DataView|null>} `length` bytes at `offset`; null past the end of the file.
	 */
	async view( offset, length ) {

		if ( offset + length > this.size ) return null;
		if ( offset < this._start || offset + length > this._start + this._bytes.length ) {

			this._start = offset;
			this._bytes = new Uint8Array( await this.blob.slice( offset, Math.min( this.size, offset + Math.max( CHUNK, length ) ) ).arrayBuffer() );

		}

		return new DataView( this._bytes.buffer, offset - this._start, length );

	}

}

function fourcc( view, at ) {

	return String.fromCharCode( view.getUint8( at ), view.getUint8( at + 1 ), view.getUint8( at + 2 ), view.getUint8( at + 3 ) );

}

/**
 * The standard frame rate (24, 29.97, 30, ...) nearest to `fps` when within `uncertainty`
 * (relative) of it, else `fps`.
 */
export function snappedFps( fps, uncertainty ) {

	const nearest = STANDARD_FPS.reduce( ( a, b ) => ( Math.abs( b - fps ) < Math.abs( a - fps ) ? b : a ) );
	return Math.abs( nearest - fps ) <= uncertainty * fps ? nearest : fps;

}

// MP4 / MOV

/** {count, fps, start} of the first video track's sample table, or null. */
async function mp4Frames( reader ) {

	let moov = null;
	for ( let offset = 0; offset < reader.size; ) {

		const box = await boxAt( reader, offset );
		if ( box === null ) return null;
		if ( box.type === 'moov' ) moov = new DataView( await reader.blob.slice( box.start, box.end ).arrayBuffer() );
		offset = box.end;

	}

	if ( moov === null ) return null;
	for ( const trak of children( moov, 0, moov.byteLength, 'trak' ) ) {

		const mdia = children( moov, trak.start, trak.end, 'mdia' )[ 0 ];
		const hdlr = mdia && children( moov, mdia.start, mdia.end, 'hdlr' )[ 0 ];
		if ( ! hdlr || fourcc( moov, hdlr.start + 8 ) !== 'vide' ) continue;
		const mdhd = children( moov, mdia.start, mdia.end, 'mdhd' )[ 0 ];
		const stbl = descendant( moov, mdia, [ 'minf', 'stbl' ] );
		const stts = stbl && children( moov, stbl.start, stbl.end, 'stts' )[ 0 ];
		if ( ! mdhd || ! stts ) return null;
		const timescale = moov.getUint32( mdhd.start + ( moov.getUint8( mdhd.start ) === 1 ? 20 : 12 ) );
		let count = 0, ticks = 0;
		const entries = moov.getUint32( stts.start + 4 );
		for ( let i = 0; i < entries; i ++ ) {

			const n = moov.getUint32( stts.start + 8 + 8 * i );
			count += n;
			ticks += n * moov.getUint32( stts.start + 12 + 8 * i );

		}

		// a fragmented file lists its samples in its fragments, not here
		if ( count === 0 || ! ( ticks > 0 && timescale > 0 ) ) return null;
		// sample durations are whole ticks: the mean rate is exact, nothing to snap
		return { count, fps: count * timescale / ticks, start: 0 };

	}

	return null;

}

/** {type, start, end} of the top-level box at `offset` (start: its payload), or null when cut. */
async function boxAt( reader, offset ) {

	const view = await reader.view( offset, Math.min( BOX_HEADER, reader.size - offset ) );
	if ( view === null ) return null;
	const box = boxIn( view, 0, reader.size - offset );
	return box && { type: box.type, start: offset + box.start, end: offset + box.end };

}

/**
 * {type, start, end} of the box at `at` in `view`, in its coordinates, within a parent
 * that ends at `end` (which the view may not reach); null when its header is cut.
 */
function boxIn( view, at, end ) {

	if ( at + 8 > view.byteLength ) return null;
	let size = view.getUint32( at );
	let header = 8;
	if ( size === 1 ) {

		if ( at + 16 > view.byteLength ) return null;
		size = Number( view.getBigUint64( at + 8 ) );
		header = 16;

	} else if ( size === 0 ) {

		size = end - at; // to the end of its parent (the file, at the top)

	}

	if ( size < header || at + size > end ) return null;
	return { type: fourcc( view, at + 4 ), start: at + header, end: at + size };

}

/** The boxes of type `type` directly within [start, end) of `view`. */
function children( view, start, end, type ) {

	const found = [];
	for ( let at = start; at < end; ) {

		const box = boxIn( view, at, end );
		if ( box === null ) throw new RangeError( 'a box runs past its parent' );
		if ( box.type === type ) found.push( box );
		at = box.end;

	}

	return found;

}

/** The first box down the chain of `types` from `box`, or undefined. */
function descendant( view, box, types ) {

	for ( const type of types ) {

		box = box && children( view, box.start, box.end, type )[ 0 ];

	}

	return box;

}

// WebM / Matroska

/** {count, fps, start} of the first video track's blocks, or null. */
async function matroskaFrames( reader ) {

	let scale = 1e6; // ns per timestamp tick (TimestampScale's default)
	let track = {}; // the TrackEntry being read: {number, type}
	let video = null; // the first video track's number
	let cluster = 0; // the current cluster's timestamp, ticks
	const blocks = new Map(); // track number -> {count, first, last} (ticks)
	for ( let offset = 0; offset < reader.size; ) {

		const element = await elementAt( reader, offset );
		if ( element === null ) break; // cut in its header
		const { id, start, size } = element;
		if ( ENTERED.has( id ) ) {

			if ( id === TRACK_ENTRY ) track = {};
			offset = start; // read its children, however long it says it is (live WebM: unknown)
			continue;

		}

		if ( size === null ) return null; // an unknown length only a master may have
		if ( start + size > reader.size ) break; // a cut last element: count the blocks before it
		if ( id === TIMESTAMP_SCALE ) scale = await uintAt( reader, start, size );
		else if ( id === TRACK_NUMBER ) track.number = await uintAt( reader, start, size );
		else if ( id === TRACK_TYPE ) track.type = await uintAt( reader, start, size );
		else if ( id === CLUSTER_TIMESTAMP ) cluster = await uintAt( reader, start, size );
		else if ( id === SIMPLE_BLOCK || id === BLOCK ) {

			const block = await blockAt( reader, start, size );
			if ( block === null ) break;
			const time = cluster + block.time;
			const seen = blocks.get( block.track );
			if ( seen === undefined ) blocks.set( block.track, { count: block.frames, first: time, last: time } );
			else {

				seen.count += block.frames;
				seen.first = Math.min( seen.first, time );
				seen.last = Math.max( seen.last, time );

			}

		}

		if ( track.type === VIDEO_TRACK && track.number !== undefined && video === null ) video = track.number;
		offset = start + size;

	}

	const frames = blocks.get( video );
	if ( frames === undefined ) return null;
	const seconds = scale * 1e-9;
	const start = frames.first * seconds;
	if ( frames.count < 2 || frames.last === frames.first ) return { count: frames.count, fps: null, start };
	const span = ( frames.last - frames.first ) * seconds;
	// each end of the span is rounded to a tick (a millisecond by default)
	return { count: frames.count, fps: snappedFps( ( frames.count - 1 ) / span, seconds / span ), start };

}

/** {id, start, size} of the element at `offset` (size null: unknown), or null when it is cut. */
async function elementAt( reader, offset ) {

	const view = await reader.view( offset, Math.min( 12, reader.size - offset ) );
	if ( view === null ) return null;
	const id = vint( view, 0, true );
	const size = id && vint( view, id.length, false );
	if ( ! id || ! size ) return null;
	return { id: id.value, start: offset + id.length + size.length, size: size.value };

}

/**
 * An EBML variable-length integer at `at`: {value, length}, value null for "unknown"
 * (all value bits set); null when it does not fit.
 * @param {boolean} marked - keep the length marker (element IDs are written with it)
 */
function vint( view, at, marked ) {

	if ( at >= view.byteLength ) return null;
	const first = view.getUint8( at );
	const length = Math.clz32( first ) - 23;
	if ( length < 1 || length > 8 || at + length > view.byteLength ) return null;
	let value = marked ? first : first & ( 0xFF >> length );
	let unknown = value === 0xFF >> length;
	for ( let k = 1; k < length; k ++ ) {

		const byte = view.getUint8( at + k );
		value = value * 256 + byte;
		unknown = unknown && byte === 0xFF;

	}

	return { value: unknown && ! marked ? null : value, length };

}

async function uintAt( reader, start, size ) {

	const view = await reader.view( start, size );
	let value = 0;
	for ( let k = 0; k < size; k ++ ) value = value * 256 + view.getUint8( k );
	return value;

}

/** A (Simple)Block's {track, time (ticks from its cluster's), frames}, or null when it is cut. */
async function blockAt( reader, start, size ) {

	const view = await reader.view( start, Math.min( size, 12 ) );
	const track = vint( view, 0, false );
	if ( ! track || track.length + 4 > view.byteLength ) return null;
	const time = view.getInt16( track.length );
	const lacing = ( view.getUint8( track.length + 2 ) >> 1 ) & 3;
	// laced frames share the block's timestamp; the byte after the flags counts them less one
	const frames = lacing === 0 ? 1 : view.getUint8( track.length + 3 ) + 1;
	return { track: track.value, time, frames };

}
