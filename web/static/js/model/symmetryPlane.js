import { Vector3 } from 'three';

/**
 * @typedef {{normal: Vector3, offset: number}} Plane
 *   The plane of points p with normal · p = offset, in the mesh's local frame; `normal`
 *   is a unit vector.
 */

/**
 * The face's left/right symmetry plane from its placed feature points, the one estimate
 * both Mirror (placing missing partners) and mirrored painting use.
 *
 * Its normal is the mean direction between placed mirror partners (each pair's
 * difference, signed to agree with the sum so far), or the mesh's x axis when no pair is
 * placed; its offset along that normal is the median over the placed midline points and
 * the midpoints of placed pairs (a median, so one misplaced point does not tilt the
 * result), or the centre of the mesh's bounding box when none is placed.
 * @param {(index: number, target: Vector3) => Vector3|null} position - a placed point's
 *   position in the mesh's frame, null when unplaced.
 * @param {number[]} mirror - each layout point's mirror partner (itself on the midline).
 * @param {import('three').Box3} box - the mesh's bounding box, mesh frame.
 * @returns {Plane}
 */
export function symmetryPlane( position, mirror, box ) {

	const a = new Vector3(), b = new Vector3(), d = new Vector3();
	const normal = new Vector3();
	const centres = [];
	mirror.forEach( ( m, i ) => {

		if ( m < i || ! position( i, a ) || ! position( m, b ) ) return;
		if ( m !== i ) {

			d.subVectors( a, b );
			normal.addScaledVector( d, normal.dot( d ) < 0 ? - 1 : 1 );

		}

		centres.push( a.clone().add( b ).multiplyScalar( 0.5 ) );

	} );
	if ( normal.lengthSq() === 0 ) normal.set( 1, 0, 0 );
	else normal.normalize();
	const offsets = centres.map( ( c ) => normal.dot( c ) ).sort( ( u, v ) => u - v );
	const m = offsets.length >> 1;
	const offset = offsets.length === 0 ? normal.dot( box.getCenter( new Vector3() ) )
		: offsets.length % 2 ? offsets[ m ] : ( offsets[ m - 1 ] + offsets[ m ] ) / 2;
	return { normal, offset };

}

/**
 * The mirror image of a point across a plane.
 * @param {Plane} plane
 * @param {Vector3} p
 * @returns {Vector3} a new vector, in p's frame.
 */
export function reflect( { normal, offset }, p ) {

	return p.clone().addScaledVector( normal, - 2 * ( normal.dot( p ) - offset ) );

}
