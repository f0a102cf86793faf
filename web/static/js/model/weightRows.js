/**
 * One joint's weight in a row of sparse skin weights, and the painting rule that sets it:
 * the JavaScript twin of retarget/weights/painting.py `with_weight` followed by its top-k
 * (tests/unit/test_painting.py runs both on the same rows).
 *
 * Rows are the server's form (GET /api/projects/{id}/rig/weights): vertex v's influences
 * are slots v*k .. v*k+k-1 of `indices` (joint) and `weights`; a slot of weight 0 is free.
 * The rest of a row's 1 belongs to the static root joint, which painting treats as one
 * more influence: raising w_j scales the others and the root by the same factor, lowering
 * it hands the freed weight to the others' and the root's non-negative parts in
 * proportion (for a non-negative row both are `others * (1 - b) / (1 - a)`, Blender's and
 * Maya's normalisation). A row that would get more than k influences keeps the k largest
 * |w|, scaled to keep the row's sum.
 */

/**
 * @param {Uint16Array} indices - (V*k) joint indices.
 * @param {Float32Array} weights - (V*k) weights.
 * @param {number} row - vertex index.
 * @param {number} k - influences per vertex.
 * @param {number} joint
 * @returns {number} the joint's weight at the vertex (summed over its slots; 0 if none).
 */
export function jointWeight( indices, weights, row, k, joint ) {

	let w = 0;
	for ( let s = row * k, end = s + k; s < end; s ++ ) if ( indices[ s ] === joint ) w += weights[ s ];
	return w;

}

/**
 * Paint `joint` to `value` at vertex `row`, rescaling the row's other influences.
 * @param {Uint16Array} indices - (V*k) joint indices, changed in place.
 * @param {Float32Array} weights - (V*k) weights, changed in place.
 * @param {number} row - vertex index.
 * @param {number} k - influences per vertex.
 * @param {number} joint
 * @param {number} value - the joint's new weight, in [0, 1].
 * @returns {boolean} whether the row changed.
 */
export function setJointWeight( indices, weights, row, k, joint, value ) {

	const start = row * k, end = start + k;
	let slot = - 1, a = 0, total = 0, room = 0;
	for ( let s = start; s < end; s ++ ) {

		const w = weights[ s ];
		total += w;
		if ( indices[ s ] === joint && slot < 0 ) {

			slot = s;
			a = w;

		} else if ( indices[ s ] === joint ) {

			a += w; // a joint listed twice: fold it into its first slot
			weights[ s ] = 0;

		} else if ( w > 0 ) {

			room += w;

		}

	}

	const b = Math.min( 1, Math.max( 0, value ) );
	if ( b === a ) return false;
	room += Math.max( 0, 1 - total );

	if ( b > a ) {

		const keep = 1 - ( b - a ) / ( 1 - a );
		for ( let s = start; s < end; s ++ ) if ( s !== slot ) weights[ s ] *= keep;

	} else {

		const t = ( a - b ) / a;
		for ( let s = start; s < end; s ++ ) {

			if ( s === slot ) continue;
			const w = weights[ s ];
			weights[ s ] = ( 1 - t ) * w + ( room > 0 && w > 0 ? t * w / room : 0 );

		}

	}

	if ( slot < 0 ) slot = freeSlot( weights, start, end );
	if ( slot >= 0 ) {

		indices[ slot ] = joint;
		weights[ slot ] = b;
		return true;

	}

	// k + 1 influences: the smallest |w| goes (perhaps the joint itself), the rest scale to keep the sum
	let smallest = start, sum = b;
	for ( let s = start; s < end; s ++ ) {

		sum += weights[ s ];
		if ( Math.abs( weights[ s ] ) < Math.abs( weights[ smallest ] ) ) smallest = s;

	}

	if ( Math.abs( b ) < Math.abs( weights[ smallest ] ) ) {

		rescale( weights, start, end, sum - b, sum );
		return true;

	}

	const kept = sum - weights[ smallest ];
	indices[ smallest ] = joint;
	weights[ smallest ] = b;
	rescale( weights, start, end, kept, sum );
	return true;

}

/** A slot of weight 0 in [start, end), or -1. */
function freeSlot( weights, start, end ) {

	for ( let s = start; s < end; s ++ ) if ( weights[ s ] === 0 ) return s;
	return - 1;

}

/** Scale slots [start, end) from summing to `kept` to summing to `sum`. */
function rescale( weights, start, end, kept, sum ) {

	if ( Math.abs( kept ) <= 1e-12 ) return;
	const f = sum / kept;
	for ( let s = start; s < end; s ++ ) weights[ s ] *= f;

}
