/**
 * Encoder of source-points messages: the browser's tracked points, sent to the server
 * over the stream's WebSocket.
 *
 * The JavaScript twin of `decode_points` in `server/stream_codec.py`, whose comment gives
 * the byte layout: a 32-byte little-endian header (magic "RTSP", version, dims, frame
 * index, point count, capture time in seconds, 8 reserved bytes) followed by N x D
 * float32 points, NaN for a lost point.
 */
export class PointsEncoder {

	static MAGIC = 0x50535452; // "RTSP" read as a little-endian uint32
	static VERSION = 1;
	static HEADER_BYTES = 32;

	/**
	 * @param {Float32Array|number[]} points - N x dims values, point-major.
	 * @param {number} dims - 2 or 3.
	 * @param {number} frameIndex
	 * @param {number} captureTime - seconds.
	 * @returns {ArrayBuffer}
	 */
	encode( points, dims, frameIndex, captureTime ) {

		if ( dims !== 2 && dims !== 3 ) throw new RangeError( `PointsEncoder: dims must be 2 or 3, got ${ dims }.` );
		if ( points.length % dims !== 0 ) throw new RangeError( `PointsEncoder: ${ points.length } values are not whole points of ${ dims }.` );
		const count = points.length / dims;
		const buffer = new ArrayBuffer( PointsEncoder.HEADER_BYTES + 4 * points.length );
		const view = new DataView( buffer );
		view.setUint32( 0, PointsEncoder.MAGIC, true );
		view.setUint16( 4, PointsEncoder.VERSION, true );
		view.setUint16( 6, dims, true );
		view.setUint32( 8, frameIndex >>> 0, true );
		view.setUint32( 12, count, true );
		view.setFloat64( 16, captureTime, true );
		new Float32Array( buffer, PointsEncoder.HEADER_BYTES ).set( points );
		return buffer;

	}

}
