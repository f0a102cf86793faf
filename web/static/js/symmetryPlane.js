import * as THREE from 'three';

/**
 * @typedef {{normal: THREE.Vector3, point: THREE.Vector3}} Plane
 *   A plane in the mesh's local frame: its unit normal and a point on it.
 */

/**
 * The face's left/right symmetry plane from the placed feature points: its normal the
 * mean direction between mirror partners, through the mean of their midpoints and of
 * the midline points; the picker's x = const plane when no pair is placed.
 * @param {import('./LandmarkPicker.js').LandmarkPicker} picker - the placed points.
 * @param {number[]} mirror - each point's mirror partner (itself on the midline).
 * @returns {Plane}
 */
export function symmetryPlane( picker, mirror ) {

	const normal = new THREE.Vector3(), point = new THREE.Vector3();
	const a = new THREE.Vector3(), b = new THREE.Vector3(), d = new THREE.Vector3();
	let midpoints = 0;
	mirror.forEach( ( m, i ) => {

		if ( m < i || ! picker.position( i, a ) || ! picker.position( m, b ) ) return;
		if ( m !== i ) {

			d.subVectors( a, b );
			normal.addScaledVector( d, normal.dot( d ) < 0 ? - 1 : 1 );

		}

		point.add( a ).add( b );
		midpoints += 2;

	} );
	if ( normal.lengthSq() === 0 ) return { normal: new THREE.Vector3( 1, 0, 0 ), point: new THREE.Vector3( picker.symmetryX(), 0, 0 ) };
	return { normal: normal.normalize(), point: point.divideScalar( midpoints ) };

}

/**
 * The mirror image of a point across a plane.
 * @param {Plane} plane
 * @param {THREE.Vector3} p
 * @returns {THREE.Vector3} a new vector, in p's frame.
 */
export function reflect( { normal, point }, p ) {

	const offset = new THREE.Vector3().subVectors( p, point ).dot( normal );
	return p.clone().addScaledVector( normal, - 2 * offset );

}
