// Validates the glTF/GLB file in argv[2] with the Khronos glTF Validator (npm
// gltf-validator from web/node_modules) and prints its report as JSON on stdout.
import { readFileSync } from 'node:fs';
import { createRequire } from 'node:module';

const require = createRequire( new URL( '../../web/package.json', import.meta.url ) );
const validator = require( 'gltf-validator' );

const report = await validator.validateBytes( new Uint8Array( readFileSync( process.argv[ 2 ] ) ), {
	uri: process.argv[ 2 ],
	maxIssues: 0, // report every issue
} );
process.stdout.write( JSON.stringify( report ) );
