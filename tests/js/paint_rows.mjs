// Applies painting ops with the browser's weightRows.js (web/static/js/model/) to the rows in the JSON file argv[2]
// ({k, indices, weights, ops: [[vertex, joint, value], ...]}, indices and weights flat V*k)
// and prints {indices, weights, changed} after all ops.
import { readFileSync } from 'node:fs';
import { setJointWeight } from '../../web/static/js/model/weightRows.js';

const { k, indices, weights, ops } = JSON.parse( readFileSync( process.argv[ 2 ], 'utf8' ) );
const idx = Uint16Array.from( indices ), w = Float32Array.from( weights );
const changed = ops.map( ( [ vertex, joint, value ] ) => setJointWeight( idx, w, vertex, k, joint, value ) );
console.log( JSON.stringify( { indices: Array.from( idx ), weights: Array.from( w ), changed } ) );
