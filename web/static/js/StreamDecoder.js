/**
 * Decoder of the stream's binary frames (target feature displacements).
 *
 * The JavaScript twin of `server/stream_codec.py`, whose docstring gives the byte layout:
 * a 32-byte little-endian header (magic "RTDF", version, flags, frame index, point count,
 * source and send timestamps) followed by N x 3 float32 displacements and, with flag
 * bit 2, the performer's head rotation as a quaternion (x, y, z, w).
 */
export class StreamDecoder {

	static MAGIC = 0x46445452; // "RTDF" read as a little-endian uint32
	static VERSION = 1;
	static HEADER_BYTES = 32;
	static FLAG_NEUTRAL = 1;
	static FLAG_LOST_POINTS = 2;
	static FLAG_HEAD_ROTATION = 4;
	static FLAG_LAST = 8;

	/**
	 * Decode one frame.
	 * @param {ArrayBuffer} buffer - the WebSocket message's bytes.
	 * @returns {{version: number, flags: number, frameIndex: number, count: number,
	 *   sourceTime: number, sendTime: number, displacements: Float32Array,
	 *   headRotation: Float32Array|null}} displacements is a view on `buffer` (no copy),
	 *   point-major x, y, z; headRotation a view of 4 floats (x, y, z, w) or null.
	 */
	decode( buffer ) {

		if ( ! ( buffer instanceof ArrayBuffer ) ) throw new TypeError( 'StreamDecoder: expected an ArrayBuffer.' );
		if ( buffer.byteLength < StreamDecoder.HEADER_BYTES ) {

			throw new Error( `StreamDecoder: frame is ${ buffer.byteLength } bytes, shorter than its header.` );

		}

		const view = new DataView( buffer );
		if ( view.getUint32( 0, true ) !== StreamDecoder.MAGIC ) throw new Error( 'StreamDecoder: not a displacement frame (bad magic).' );
		const version = view.getUint16( 4, true );
		if ( version !== StreamDecoder.VERSION ) throw new Error( `StreamDecoder: unsupported frame version ${ version }.` );
		const count = view.getUint32( 12, true );
		const flags = view.getUint16( 6, true );
		const rotated = ( flags & StreamDecoder.FLAG_HEAD_ROTATION ) !== 0;
		const expected = StreamDecoder.HEADER_BYTES + 12 * count + ( rotated ? 16 : 0 );
		if ( buffer.byteLength !== expected ) {

			throw new Error( `StreamDecoder: frame for ${ count } points must be ${ expected } bytes, got ${ buffer.byteLength }.` );

		}

		return {
			version,
			flags,
			frameIndex: view.getUint32( 8, true ),
			count,
			sourceTime: view.getFloat64( 16, true ),
			sendTime: view.getFloat64( 24, true ),
			displacements: new Float32Array( buffer, StreamDecoder.HEADER_BYTES, 3 * count ),
			headRotation: rotated ? new Float32Array( buffer, StreamDecoder.HEADER_BYTES + 12 * count, 4 ) : null,
		};

	}

}
