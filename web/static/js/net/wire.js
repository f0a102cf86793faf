/**
 * Every binary format between the server and the page, in one module: the JavaScript
 * twin of `server/wire.py`, whose docstring gives each byte layout (tests/api/test_wire.py
 * runs the two against each other in node).
 *
 * - `StreamDecoder`: stream frames "RTDF" (server -> page, WebSocket), a frame's feature
 *   displacements;
 * - `ContractionDecoder`: contraction frames "RTMC" (server -> page, WebSocket, muscle
 *   mode), a frame's muscle contractions and the expression they show;
 * - `StereoPairEncoder`: a stereo pair "RTSJ" (page -> server, WebSocket), two JPEGs;
 * - `PointsEncoder`: source points "RTSP" (page -> server, WebSocket), one frame of
 *   tracked points;
 * - `MeshArraysDecoder`: mesh arrays "RTMA" (GET .../mesh/arrays);
 * - `RigWeightsDecoder`: rig weights "RTSW" (GET .../rig/weights);
 * - `WeightEditEncoder`: weight edits "RTSE" (PATCH .../rig/weights), painted rows;
 * - `MuscleMorphsDecoder`: played muscles "RTMM" (GET .../muscles/played), morph targets
 *   and the jaw joint.
 * - `ArkitWeightsDecoder`: ARKit weight frames "RTAW" (server -> page, WebSocket, ARKit
 *   mode), the 52 blendshape weights;
 * - `ArkitShapesDecoder`: ARKit shapes "RTAK" (GET .../arkit/shapes), 52 sparse morph targets.
 *
 * All little-endian; every array starts at a multiple of 4 bytes, so a decoder views it in
 * place without copying. Five small codecs in one file, against the one-class-per-file
 * habit, because they are one thing: the page's half of one wire protocol, each the mirror
 * of a function in one Python module, sharing its header checks. Errors are prefixed with
 * the codec's name.
 */

/** The 4-byte magic `text` read as a little-endian uint32. */
function magicNumber( text ) {

	return ( text.charCodeAt( 0 ) | text.charCodeAt( 1 ) << 8 | text.charCodeAt( 2 ) << 16 | text.charCodeAt( 3 ) << 24 ) >>> 0;

}

/**
 * A DataView on a REST format's bytes after checking its 4-byte magic and uint32 version
 * (one of `versions`) and that it holds at least its header.
 * @param {string} who - the codec, for the message.
 * @param {ArrayBuffer} buffer
 * @param {string} magic
 * @param {number} headerBytes
 * @param {number[]} [versions] - the versions the codec reads.
 * @returns {DataView}
 */
function checkedHeader( who, buffer, magic, headerBytes, versions = [ 1 ] ) {

	if ( ! ( buffer instanceof ArrayBuffer ) ) throw new TypeError( `${ who }: expected an ArrayBuffer.` );
	const found = String.fromCharCode( ...new Uint8Array( buffer, 0, Math.min( 4, buffer.byteLength ) ) );
	if ( found !== magic ) throw new Error( `${ who }: expected "${ magic }" data, got "${ found }".` );
	if ( buffer.byteLength < headerBytes ) throw new Error( `${ who }: ${ buffer.byteLength } bytes is shorter than its ${ headerBytes }-byte header.` );
	const view = new DataView( buffer );
	const version = view.getUint32( 4, true );
	if ( ! versions.includes( version ) ) throw new Error( `${ who }: unsupported format version ${ version }.` );
	return view;

}

const STREAM_HEADER_BYTES = 32;
const FLAG_HEAD_ROTATION = 4;

/**
 * The header every stream frame shares (RTDF, RTMC, RTAW: magic, uint16 version, uint16
 * flags, uint32 frame index, 4 bytes of the frame's own counts, float64 source and send
 * times) after checking the frame holds it, its magic and its version.
 * @param {string} who - the codec, for the message.
 * @param {ArrayBuffer} buffer
 * @param {number} magic - `magicNumber` of the frame's magic.
 * @param {number} expectedVersion - the version the codec reads.
 * @param {string} what - the frame's kind, for the message.
 * @returns {{view: DataView, version: number, flags: number, rotated: boolean,
 *   frameIndex: number, sourceTime: number, sendTime: number}} rotated: flag bit 2, the
 *   head rotation follows the body.
 */
function streamHeader( who, buffer, magic, expectedVersion, what ) {

	if ( ! ( buffer instanceof ArrayBuffer ) ) throw new TypeError( `${ who }: expected an ArrayBuffer.` );
	if ( buffer.byteLength < STREAM_HEADER_BYTES ) throw new Error( `${ who }: frame is ${ buffer.byteLength } bytes, shorter than its header.` );
	const view = new DataView( buffer );
	if ( view.getUint32( 0, true ) !== magic ) throw new Error( `${ who }: not ${ what } (bad magic).` );
	const version = view.getUint16( 4, true );
	if ( version !== expectedVersion ) throw new Error( `${ who }: unsupported frame version ${ version }.` );
	const flags = view.getUint16( 6, true );
	return {
		view, version, flags,
		rotated: ( flags & FLAG_HEAD_ROTATION ) !== 0,
		frameIndex: view.getUint32( 8, true ),
		sourceTime: view.getFloat64( 16, true ),
		sendTime: view.getFloat64( 24, true ),
	};

}

/** Bytes of `n` uint16 values rounded up to a multiple of 4 (the formats' padding). */
function paddedUint16Bytes( n ) {

	return 2 * n + ( ( 2 * n ) % 4 );

}

/**
 * Decoder of the stream's frames (target feature displacements): a 32-byte header (magic
 * "RTDF", uint16 version, uint16 flags, uint32 frame index, uint32 point count, float64
 * source and send times) followed by N x 3 float32 displacements and, with flag bit 2,
 * the performer's head rotation as a quaternion (x, y, z, w).
 */
export class StreamDecoder {

	static MAGIC = magicNumber( 'RTDF' );
	static VERSION = 1;
	static HEADER_BYTES = 32;
	static FLAG_NEUTRAL = 1;
	static FLAG_LOST_POINTS = 2;
	static FLAG_HEAD_ROTATION = FLAG_HEAD_ROTATION;
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

		const { view, version, flags, rotated, frameIndex, sourceTime, sendTime } = streamHeader( 'StreamDecoder', buffer, StreamDecoder.MAGIC, StreamDecoder.VERSION, 'a displacement frame' );
		const count = view.getUint32( 12, true );
		const expected = StreamDecoder.HEADER_BYTES + 12 * count + ( rotated ? 16 : 0 );
		if ( buffer.byteLength !== expected ) {

			throw new Error( `StreamDecoder: frame for ${ count } points must be ${ expected } bytes, got ${ buffer.byteLength }.` );

		}

		return {
			version,
			flags,
			frameIndex,
			count,
			sourceTime,
			sendTime,
			displacements: new Float32Array( buffer, StreamDecoder.HEADER_BYTES, 3 * count ),
			headRotation: rotated ? new Float32Array( buffer, StreamDecoder.HEADER_BYTES + 12 * count, 4 ) : null,
		};

	}

}

/**
 * Decoder of the stream's contraction frames (muscle mode): RTDF's 32-byte header with
 * magic "RTMC" and, in place of the point count, uint16 D (dofs) and uint16 E
 * (expressions); then D float32 contractions (the jaw's last, radians), E float32
 * normalised expression distances, a float32 confidence, a uint32 expression index and,
 * with flag bit 2, the head rotation (x, y, z, w). Flags are StreamDecoder's.
 */
export class ContractionDecoder {

	static MAGIC = magicNumber( 'RTMC' );
	static VERSION = 1;
	static HEADER_BYTES = 32;

	/**
	 * Decode one frame.
	 * @param {ArrayBuffer} buffer - the WebSocket message's bytes.
	 * @returns {{version: number, flags: number, frameIndex: number, sourceTime: number,
	 *   sendTime: number, contractions: Float32Array, distances: Float32Array,
	 *   confidence: number, label: number, headRotation: Float32Array|null}} contractions
	 *   (D) and distances (E) view `buffer`; label indexes the played muscles' expressions.
	 */
	decode( buffer ) {

		const { view, version, flags, rotated, frameIndex, sourceTime, sendTime } = streamHeader( 'ContractionDecoder', buffer, ContractionDecoder.MAGIC, ContractionDecoder.VERSION, 'a contraction frame' );
		const d = view.getUint16( 12, true ), e = view.getUint16( 14, true );
		const body = ContractionDecoder.HEADER_BYTES + 4 * ( d + e + 2 );
		const expected = body + ( rotated ? 16 : 0 );
		if ( buffer.byteLength !== expected ) {

			throw new Error( `ContractionDecoder: frame of ${ d } dofs and ${ e } expressions must be ${ expected } bytes, got ${ buffer.byteLength }.` );

		}

		const at = ContractionDecoder.HEADER_BYTES;
		return {
			version,
			flags,
			frameIndex,
			sourceTime,
			sendTime,
			contractions: new Float32Array( buffer, at, d ),
			distances: new Float32Array( buffer, at + 4 * d, e ),
			confidence: view.getFloat32( at + 4 * ( d + e ), true ),
			label: view.getUint32( at + 4 * ( d + e + 1 ), true ),
			headRotation: rotated ? new Float32Array( buffer, body, 4 ) : null,
		};

	}

}

/**
 * Encoder of source-points messages, the browser's tracked points for the server: a
 * 32-byte header (magic "RTSP", uint16 version, uint16 dims, uint32 frame index, uint32
 * point count, float64 capture time in seconds, 8 reserved bytes) followed by N x D
 * float32 points, NaN for a lost point.
 */
export class PointsEncoder {

	static MAGIC = magicNumber( 'RTSP' );
	static VERSION = 1;
	static HEADER_BYTES = 32;

	/**
	 * @param {Float32Array|number[]} points - N x dims values, point-major; NaN: lost.
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

/**
 * Encoder of stereo-pair messages, the page's two cameras for the server's live stereo
 * tracker: a 32-byte header (magic "RTSJ", uint16 version, uint16 flags (0), uint32 frame
 * index, uint32 left JPEG length, uint32 right JPEG length, 4 reserved bytes, float64
 * capture time in seconds since the Unix epoch) followed by the two JPEGs.
 */
export class StereoPairEncoder {

	static MAGIC = magicNumber( 'RTSJ' );
	static VERSION = 1;
	static HEADER_BYTES = 32;

	/**
	 * @param {Uint8Array} left - the left camera's JPEG bytes.
	 * @param {Uint8Array} right - the right camera's JPEG bytes.
	 * @param {number} frameIndex
	 * @param {number} captureTime - seconds since the Unix epoch.
	 * @returns {ArrayBuffer}
	 */
	encode( left, right, frameIndex, captureTime ) {

		for ( const [ side, jpeg ] of [ [ 'left', left ], [ 'right', right ] ] ) {

			if ( ! ( jpeg instanceof Uint8Array ) || jpeg.length < 2 || jpeg[ 0 ] !== 0xff || jpeg[ 1 ] !== 0xd8 ) {

				throw new RangeError( `StereoPairEncoder: the ${ side } image is not JPEG bytes.` );

			}

		}

		const buffer = new ArrayBuffer( StereoPairEncoder.HEADER_BYTES + left.length + right.length );
		const view = new DataView( buffer );
		view.setUint32( 0, StereoPairEncoder.MAGIC, true );
		view.setUint16( 4, StereoPairEncoder.VERSION, true );
		view.setUint16( 6, 0, true );
		view.setUint32( 8, frameIndex >>> 0, true );
		view.setUint32( 12, left.length, true );
		view.setUint32( 16, right.length, true );
		view.setFloat64( 24, captureTime, true );
		const bytes = new Uint8Array( buffer );
		bytes.set( left, StereoPairEncoder.HEADER_BYTES );
		bytes.set( right, StereoPairEncoder.HEADER_BYTES + left.length );
		return buffer;

	}

}

/**
 * Decoder of a mesh's arrays: a 16-byte header (magic "RTMA", uint32 version, uint32 V,
 * uint32 F) followed by V x 3 float32 vertices and F x 3 uint32 triangles; for a mesh with
 * uv, then a uint32 of flags (bit 0: a base-colour texture is served at .../mesh/texture)
 * and V x 2 float32 uv.
 */
export class MeshArraysDecoder {

	static HEADER_BYTES = 16;
	static TEXTURED = 1;

	/**
	 * @param {ArrayBuffer} buffer
	 * @returns {{positions: Float32Array, faces: Uint32Array, uv: Float32Array|null, textured: boolean}}
	 *   views on `buffer`: positions (3V) in the mesh's own units, faces (3F) vertex indices,
	 *   uv (2V, OBJ's convention: v up) or null, textured: the mesh has a base-colour texture.
	 */
	decode( buffer ) {

		const view = checkedHeader( 'MeshArraysDecoder', buffer, 'RTMA', MeshArraysDecoder.HEADER_BYTES );
		const v = view.getUint32( 8, true ), f = view.getUint32( 12, true );
		const size = MeshArraysDecoder.HEADER_BYTES + 12 * v + 12 * f;
		const withUv = size + 4 + 8 * v;
		if ( buffer.byteLength !== size && buffer.byteLength !== withUv ) {

			throw new Error( `MeshArraysDecoder: ${ v } vertices and ${ f } triangles need ${ size } bytes (${ withUv } with uv), got ${ buffer.byteLength }.` );

		}

		const hasUv = buffer.byteLength === withUv;
		return {
			positions: new Float32Array( buffer, MeshArraysDecoder.HEADER_BYTES, 3 * v ),
			faces: new Uint32Array( buffer, MeshArraysDecoder.HEADER_BYTES + 12 * v, 3 * f ),
			uv: hasUv ? new Float32Array( buffer, size + 4, 2 * v ) : null,
			textured: hasUv && ( view.getUint32( size, true ) & MeshArraysDecoder.TEXTURED ) !== 0,
		};

	}

}

/**
 * Decoder of a rig's skin weights (server/wire.py's docstring has both layouts): version 1,
 * a 20-byte header (magic "RTSW", uint32 version, uint32 V, uint32 K, uint32 N) followed by
 * V x K uint16 joint indices, 0 or 2 bytes of padding and V x K float32 weights; version 2
 * (GET .../rig/weights?version=2), a 28-byte header (the same, then uint32 flags and a
 * float32 step) followed, for a dense rig (flag bit 0: joints 0..K-1 in order), by the
 * weights over step as 20-bit signed integers in three byte planes (bits 0-3, 4-11, 12-19),
 * slot-major; otherwise by version 1's indices, padding and float32 weights.
 */
export class RigWeightsDecoder {

	static HEADER_BYTES = 20;
	static HEADER_BYTES_V2 = 28;
	static DENSE = 1;

	/**
	 * @param {ArrayBuffer} buffer
	 * @returns {{nJoints: number, nInfluences: number, indices: Uint16Array, weights: Float32Array}}
	 *   indices and weights are (V, k) row-major (views on `buffer` for version 1; version 2's
	 *   dequantised weights, and a dense rig's indices, are new arrays); unused slots have
	 *   weight 0.
	 */
	decode( buffer ) {

		const view = checkedHeader( 'RigWeightsDecoder', buffer, 'RTSW', RigWeightsDecoder.HEADER_BYTES, [ 1, 2 ] );
		const version = view.getUint32( 4, true );
		const v = view.getUint32( 8, true ), k = view.getUint32( 12, true ), n = view.getUint32( 16, true );
		if ( version === 1 ) {

			const start = RigWeightsDecoder.HEADER_BYTES + paddedUint16Bytes( v * k );
			const size = start + 4 * v * k;
			if ( buffer.byteLength !== size ) {

				throw new Error( `RigWeightsDecoder: ${ v } rows of ${ k } influences need ${ size } bytes, got ${ buffer.byteLength }.` );

			}

			return {
				nJoints: n,
				nInfluences: k,
				indices: new Uint16Array( buffer, RigWeightsDecoder.HEADER_BYTES, v * k ),
				weights: new Float32Array( buffer, start, v * k ),
			};

		}

		const header = RigWeightsDecoder.HEADER_BYTES_V2;
		if ( buffer.byteLength < header ) throw new Error( `RigWeightsDecoder: ${ buffer.byteLength } bytes is shorter than its ${ header }-byte header.` );
		const dense = ( view.getUint32( 20, true ) & RigWeightsDecoder.DENSE ) !== 0;
		const step = view.getFloat32( 24, true );
		const vk = v * k;
		const start = header + ( dense ? 0 : paddedUint16Bytes( vk ) );
		const size = start + ( dense ? 3 : 4 ) * vk;
		if ( buffer.byteLength !== size || ( dense && k !== n ) ) {

			throw new Error( `RigWeightsDecoder: ${ v } rows of ${ k } influences of ${ n } joints need ${ size } bytes, got ${ buffer.byteLength }.` );

		}

		if ( ! dense ) {

			// a sparse rig travels as in version 1: float32 weights
			return { nJoints: n, nInfluences: k, indices: new Uint16Array( buffer, header, vk ), weights: new Float32Array( buffer, start, vk ) };

		}

		const indices = new Uint16Array( vk );
		for ( let i = 0; i < vk; i += k ) for ( let s = 0; s < k; s ++ ) indices[ i + s ] = s;

		// q = bits 12-19 (signed) | 4-11 | 0-3; |q| < 2^19 and step is a power of two, so q * step
		// is exact in float32
		const planes = new Uint8Array( buffer, start, 3 * vk );
		const weights = new Float32Array( vk );
		for ( let s = 0, t = 0; s < k; s ++ ) {

			for ( let i = s; i < vk; i += k, t ++ ) {

				weights[ i ] = ( ( planes[ 2 * vk + t ] << 24 >> 12 ) | planes[ vk + t ] << 4 | planes[ t ] ) * step;

			}

		}

		return { nJoints: n, nInfluences: k, indices, weights };

	}

}

/**
 * Encoder of a weight edit, painted rows of a rig: a 24-byte header (magic "RTSE", uint32
 * version, uint32 R, uint32 K, uint32 N, uint32 rig version) followed by R uint32 vertex
 * indices, R x K uint16 joint indices, 0 or 2 bytes of padding and R x K float32 weights.
 */
export class WeightEditEncoder {

	static HEADER_BYTES = 24;

	/**
	 * @param {number} version - the rig version the rows were painted on.
	 * @param {number} nJoints - the rig's joint count N.
	 * @param {number} k - influences per row.
	 * @param {ArrayLike<number>} vertices - (R) the vertices whose rows changed.
	 * @param {{indices: ArrayLike<number>, weights: ArrayLike<number>}} rows - (R*k) each, row-major.
	 * @returns {ArrayBuffer}
	 */
	encode( version, nJoints, k, vertices, rows ) {

		const r = vertices.length;
		if ( ! Number.isInteger( k ) || k < 1 ) throw new RangeError( `WeightEditEncoder: k must be a positive integer, got ${ k }.` );
		if ( rows.indices.length !== r * k || rows.weights.length !== r * k ) {

			throw new RangeError( `WeightEditEncoder: ${ r } rows of ${ k } influences need ${ r * k } indices and weights, got ${ rows.indices.length } and ${ rows.weights.length }.` );

		}

		const header = WeightEditEncoder.HEADER_BYTES;
		const start = header + 4 * r + paddedUint16Bytes( r * k );
		const buffer = new ArrayBuffer( start + 4 * r * k );
		const view = new DataView( buffer );
		view.setUint32( 0, magicNumber( 'RTSE' ), true );
		[ 1, r, k, nJoints, version ].forEach( ( value, i ) => view.setUint32( 4 + 4 * i, value, true ) );
		new Uint32Array( buffer, header, r ).set( vertices );
		new Uint16Array( buffer, header + 4 * r, r * k ).set( rows.indices );
		new Float32Array( buffer, start, r * k ).set( rows.weights );
		return buffer;

	}

}

/**
 * Decoder of the played muscles: a 20-byte header (magic "RTMM", uint32 version, uint32
 * V, uint32 M targets, uint32 J) followed by J bytes of JSON (names, dofs, high, limits,
 * jaw_pivot, jaw_axis, expressions), M x V x 3 float32 morph targets and V float32 jaw
 * weights.
 */
export class MuscleMorphsDecoder {

	static HEADER_BYTES = 20;

	/**
	 * @param {ArrayBuffer} buffer
	 * @returns {{nVertices: number, nTargets: number, header: object, targets: Float32Array,
	 *   jawWeights: Float32Array}} header: the JSON; targets (M*V*3, target-major) and
	 *   jawWeights (V) view `buffer`.
	 */
	decode( buffer ) {

		const view = checkedHeader( 'MuscleMorphsDecoder', buffer, 'RTMM', MuscleMorphsDecoder.HEADER_BYTES );
		const v = view.getUint32( 8, true ), m = view.getUint32( 12, true ), j = view.getUint32( 16, true );
		const start = MuscleMorphsDecoder.HEADER_BYTES + j;
		const size = start + 12 * m * v + 4 * v;
		if ( j % 4 !== 0 || buffer.byteLength !== size ) {

			throw new Error( `MuscleMorphsDecoder: ${ m } targets of ${ v } vertices after a ${ j }-byte header need ${ size } bytes, got ${ buffer.byteLength }.` );

		}

		return {
			nVertices: v,
			nTargets: m,
			header: JSON.parse( new TextDecoder().decode( new Uint8Array( buffer, MuscleMorphsDecoder.HEADER_BYTES, j ) ) ),
			targets: new Float32Array( buffer, start, 3 * m * v ),
			jawWeights: new Float32Array( buffer, start + 12 * m * v, v ),
		};

	}

}

// -- ARKit weight frames "RTAW" and ARKit shapes "RTAK" (issue 16) -------------------------

/**
 * Decoder of ARKit weight frames (a stream driven by ARKit's 52 blendshapes): a 32-byte
 * header (magic "RTAW", uint16 version, uint16 flags as RTDF's, uint32 frame index, uint16
 * weight count K, uint16 reserved, float64 source and send times), K float32 weights in
 * [0, 1] (ARKit's order) and, with flag bit 2, the head rotation.
 */
export class ArkitWeightsDecoder {

	static MAGIC = magicNumber( 'RTAW' );
	static VERSION = 1;
	static HEADER_BYTES = 32;

	/**
	 * Decode one frame.
	 * @param {ArrayBuffer} buffer - the WebSocket message's bytes.
	 * @returns {{version: number, flags: number, frameIndex: number, sourceTime: number,
	 *   sendTime: number, weights: Float32Array, headRotation: Float32Array|null}} weights
	 *   (K) view `buffer`.
	 */
	decode( buffer ) {

		const { view, version, flags, rotated, frameIndex, sourceTime, sendTime } = streamHeader( 'ArkitWeightsDecoder', buffer, ArkitWeightsDecoder.MAGIC, ArkitWeightsDecoder.VERSION, 'an ARKit weight frame' );
		const k = view.getUint16( 12, true );
		const body = ArkitWeightsDecoder.HEADER_BYTES + 4 * k;
		const expected = body + ( rotated ? 16 : 0 );
		if ( buffer.byteLength !== expected ) throw new Error( `ArkitWeightsDecoder: frame of ${ k } weights must be ${ expected } bytes, got ${ buffer.byteLength }.` );
		return {
			version,
			flags,
			frameIndex,
			sourceTime,
			sendTime,
			weights: new Float32Array( buffer, ArkitWeightsDecoder.HEADER_BYTES, k ),
			headRotation: rotated ? new Float32Array( buffer, body, 4 ) : null,
		};

	}

}

/**
 * Decoder of ARKit shapes "RTAK" (GET .../arkit/shapes): a 20-byte header (magic, uint32
 * version, V, K, JSON bytes J), the JSON {names, counts, scales}, then per shape its M_k
 * uint32 vertex indices and M_k x 3 int16 deltas (times the shape's scale: mesh units),
 * padded to 4 bytes. Sparse: a vertex a shape leaves out does not move in it.
 */
export class ArkitShapesDecoder {

	static HEADER_BYTES = 20;

	/**
	 * @param {ArrayBuffer} buffer
	 * @returns {{nVertices: number, names: string[], shapes: Array<{vertices: Uint32Array,
	 *   values: Int16Array, scale: number}>}} per shape: vertices (M) and values (M*3, the
	 *   deltas over `scale`) view `buffer`.
	 */
	decode( buffer ) {

		const view = checkedHeader( 'ArkitShapesDecoder', buffer, 'RTAK', ArkitShapesDecoder.HEADER_BYTES );
		const v = view.getUint32( 8, true ), k = view.getUint32( 12, true ), j = view.getUint32( 16, true );
		if ( j % 4 !== 0 || ArkitShapesDecoder.HEADER_BYTES + j > buffer.byteLength ) throw new Error( `ArkitShapesDecoder: a ${ j }-byte JSON header does not fit.` );
		const header = JSON.parse( new TextDecoder().decode( new Uint8Array( buffer, ArkitShapesDecoder.HEADER_BYTES, j ) ) );
		const { names, counts, scales } = header;
		if ( names?.length !== k || counts?.length !== k || scales?.length !== k ) throw new Error( `ArkitShapesDecoder: the header must give ${ k } names, counts and scales.` );
		let at = ArkitShapesDecoder.HEADER_BYTES + j;
		const shapes = counts.map( ( m, s ) => {

			const need = at + 4 * m + paddedUint16Bytes( 3 * m );
			if ( ! ( Number.isInteger( m ) && m >= 0 && m <= v ) || need > buffer.byteLength ) throw new Error( `ArkitShapesDecoder: shape ${ names[ s ] }'s ${ m } vertices do not fit in ${ buffer.byteLength } bytes.` );
			const vertices = new Uint32Array( buffer, at, m );
			const values = new Int16Array( buffer, at + 4 * m, 3 * m );
			at = need;
			for ( let i = 0; i < m; i ++ ) if ( vertices[ i ] >= v ) throw new Error( `ArkitShapesDecoder: shape ${ names[ s ] } names vertex ${ vertices[ i ] } of ${ v }.` );
			return { vertices, values, scale: scales[ s ] };

		} );
		if ( at !== buffer.byteLength ) throw new Error( `ArkitShapesDecoder: ${ buffer.byteLength } bytes, expected ${ at }.` );
		return { nVertices: v, names, shapes };

	}

}
