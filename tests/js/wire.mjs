// The browser's binary codecs (web/static/js/net/wire.js) driven from tests/api/test_wire.py:
//
//   node wire.mjs decode-frames FILE    length-prefixed RTDF frames -> one JSON object each
//   node wire.mjs decode-mesh FILE      length-prefixed RTMA bodies -> one JSON object each
//   node wire.mjs decode-weights FILE   length-prefixed RTSW bodies -> one JSON object each
//   node wire.mjs decode-contractions FILE  length-prefixed RTMC frames -> one JSON object each
//   node wire.mjs decode-morphs FILE    length-prefixed RTMM bodies -> one JSON object each
//   node wire.mjs decode-arkit-weights FILE  length-prefixed RTAW frames -> one JSON object each
//   node wire.mjs decode-arkit-shapes FILE   length-prefixed RTAK bodies -> one JSON object each
//   node wire.mjs encode-points IN OUT  {points, dims, frameIndex, captureTime} -> RTSP bytes
//   node wire.mjs encode-stereo-pair IN OUT  {left, right (byte lists), frameIndex, captureTime} -> RTSJ bytes
//   node wire.mjs encode-edit IN OUT    {version, nJoints, k, vertices, indices, weights} -> RTSE bytes
//
// Length prefixes are uint32 little-endian. Decoders print a JSON list with {error: msg} for
// a refused message; float32 values travel as their bit patterns (uint32) so comparisons
// are exact, and null stands for NaN in encoder input. Encoders exit 3 after printing a
// refusal's message.
import { readFileSync, writeFileSync } from 'node:fs';
import { ArkitShapesDecoder, ArkitWeightsDecoder, ContractionDecoder, MeshArraysDecoder, MuscleMorphsDecoder, PointsEncoder, RigWeightsDecoder, StereoPairEncoder, StreamDecoder, WeightEditEncoder } from '../../web/static/js/net/wire.js';

const bits = ( floats ) => floats ? Array.from( new Uint32Array( floats.buffer, floats.byteOffset, floats.length ) ) : null;

const decoders = {
	'decode-frames': ( buffer ) => {

		const f = new StreamDecoder().decode( buffer );
		return { version: f.version, flags: f.flags, frameIndex: f.frameIndex, count: f.count,
			sourceTime: f.sourceTime, sendTime: f.sendTime, bits: bits( f.displacements ), rotationBits: bits( f.headRotation ) };

	},
	'decode-mesh': ( buffer ) => {

		const { positions, faces, uv, textured } = new MeshArraysDecoder().decode( buffer );
		return { positionBits: bits( positions ), faces: Array.from( faces ), uvBits: bits( uv ), textured };

	},
	'decode-weights': ( buffer ) => {

		const w = new RigWeightsDecoder().decode( buffer );
		return { nJoints: w.nJoints, nInfluences: w.nInfluences, indices: Array.from( w.indices ), weightBits: bits( w.weights ) };

	},
	'decode-contractions': ( buffer ) => {

		const f = new ContractionDecoder().decode( buffer );
		return { flags: f.flags, frameIndex: f.frameIndex, sourceTime: f.sourceTime, sendTime: f.sendTime, label: f.label,
			confidenceBits: bits( Float32Array.of( f.confidence ) ), bits: bits( f.contractions ), distanceBits: bits( f.distances ),
			rotationBits: bits( f.headRotation ) };

	},
	'decode-morphs': ( buffer ) => {

		const m = new MuscleMorphsDecoder().decode( buffer );
		return { nVertices: m.nVertices, nTargets: m.nTargets, header: m.header, targetBits: bits( m.targets ), jawBits: bits( m.jawWeights ) };

	},
	'decode-arkit-weights': ( buffer ) => {

		const f = new ArkitWeightsDecoder().decode( buffer );
		return { flags: f.flags, frameIndex: f.frameIndex, sourceTime: f.sourceTime, sendTime: f.sendTime,
			bits: bits( f.weights ), rotationBits: bits( f.headRotation ) };

	},
	'decode-arkit-shapes': ( buffer ) => {

		const { nVertices, names, shapes } = new ArkitShapesDecoder().decode( buffer );
		return { nVertices, names, shapes: shapes.map( ( s ) => ( { vertices: Array.from( s.vertices ), values: Array.from( s.values ), scale: s.scale } ) ) };

	},
};

const encoders = {
	'encode-points': ( { points, dims, frameIndex, captureTime } ) => new PointsEncoder().encode(
		Float32Array.from( points, ( v ) => ( v === null ? NaN : v ) ), dims, frameIndex, captureTime ),
	'encode-stereo-pair': ( { left, right, frameIndex, captureTime } ) => new StereoPairEncoder().encode(
		Uint8Array.from( left ), Uint8Array.from( right ), frameIndex, captureTime ),
	'encode-edit': ( { version, nJoints, k, vertices, indices, weights } ) => new WeightEditEncoder().encode(
		version, nJoints, k, Int32Array.from( vertices ), { indices: Uint16Array.from( indices ), weights: Float32Array.from( weights ) } ),
};

const [ command, ...files ] = process.argv.slice( 2 );
if ( command in decoders ) {

	const bytes = readFileSync( files[ 0 ] );
	const out = [];
	for ( let at = 0; at < bytes.length; ) {

		const length = bytes.readUInt32LE( at );
		// a fresh ArrayBuffer per message: decoders view it from offset 0
		const message = bytes.buffer.slice( bytes.byteOffset + at + 4, bytes.byteOffset + at + 4 + length );
		at += 4 + length;
		try {

			out.push( decoders[ command ]( message ) );

		} catch ( error ) {

			out.push( { error: error.message } );

		}

	}

	console.log( JSON.stringify( out ) );

} else if ( command in encoders ) {

	try {

		writeFileSync( files[ 1 ], Buffer.from( encoders[ command ]( JSON.parse( readFileSync( files[ 0 ], 'utf8' ) ) ) ) );

	} catch ( error ) {

		console.log( error.message );
		process.exit( 3 );

	}

} else {

	console.error( `wire.mjs: unknown command ${ command }` );
	process.exit( 2 );

}
