// Decodes length-prefixed frames (uint32 LE length + frame bytes) from the file in argv[2]
// with the browser's StreamDecoder and prints one JSON object per frame, or {"error": msg}.
import { readFileSync } from 'node:fs';
import { StreamDecoder } from '../../web/static/js/StreamDecoder.js';

const bytes = readFileSync( process.argv[ 2 ] );
const decoder = new StreamDecoder();
const out = [];
for ( let at = 0; at < bytes.length; ) {

	const length = bytes.readUInt32LE( at );
	const frame = bytes.buffer.slice( bytes.byteOffset + at + 4, bytes.byteOffset + at + 4 + length );
	at += 4 + length;
	try {

		const f = decoder.decode( frame );
		// float32 values travel as their bit patterns so the comparison is exact
		const bits = Array.from( new Uint32Array( f.displacements.buffer, f.displacements.byteOffset, f.displacements.length ) );
		const rotationBits = f.headRotation ? Array.from( new Uint32Array( f.headRotation.buffer, f.headRotation.byteOffset, 4 ) ) : null;
		out.push( { version: f.version, flags: f.flags, frameIndex: f.frameIndex, count: f.count,
			sourceTime: f.sourceTime, sendTime: f.sendTime, bits, rotationBits } );

	} catch ( error ) {

		out.push( { error: error.message } );

	}

}

console.log( JSON.stringify( out ) );
