// Encodes the points JSON in argv[2] ({points: [...], dims, frameIndex, captureTime}, null
// for NaN) with the browser's PointsEncoder and writes the bytes to argv[3].
import { readFileSync, writeFileSync } from 'node:fs';
import { PointsEncoder } from '../../web/static/js/PointsEncoder.js';

const { points, dims, frameIndex, captureTime } = JSON.parse( readFileSync( process.argv[ 2 ], 'utf8' ) );
const values = Float32Array.from( points, ( v ) => ( v === null ? NaN : v ) );
try {

	writeFileSync( process.argv[ 3 ], Buffer.from( new PointsEncoder().encode( values, dims, frameIndex, captureTime ) ) );

} catch ( error ) {

	console.log( error.message );
	process.exit( 3 );

}
