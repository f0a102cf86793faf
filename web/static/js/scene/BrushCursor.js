import { DoubleSide, Mesh, MeshBasicMaterial, RingGeometry, Triangle, Vector3 } from 'three';

import { redraw } from './Viewer.js';

const RING_INNER = 0.94; // the ring's inner radius, in brush radii

/**
 * The weight brush's cursor: a ring of the brush's radius lying on the surface under the
 * pointer, and a second, blue one at its mirror image while mirrored painting is on.
 * Drawn over the face (no depth test).
 */
export class BrushCursor {

	/**
	 * @param {import('three').Scene} scene - the rings are added to it, hidden.
	 */
	constructor( scene ) {

		this.scene = scene;
		const geometry = new RingGeometry( RING_INNER, 1, 64 );
		this._rings = [ 0xffffff, 0x9ecbff ].map( ( color ) => {

			const ring = new Mesh( geometry, new MeshBasicMaterial( { color, transparent: true, opacity: 0.9, depthTest: false, side: DoubleSide } ) );
			ring.renderOrder = 2;
			ring.visible = false;
			ring.name = 'brush';
			scene.add( ring );
			return ring;

		} );

	}

	/**
	 * Show the rings; a null place hides its ring.
	 * @param {import('./MeshSurface.js').MeshSurface} surface - the face.
	 * @param {number} radius - mesh units.
	 * @param {{point: Vector3, faceIndex: number}|null} at - under the pointer, mesh frame.
	 * @param {{point: Vector3, faceIndex: number}|null} [image] - the mirror image's place.
	 */
	show( surface, radius, at, image = null ) {

		const [ ring, mirrored ] = this._rings;
		this._place( ring, surface, radius, at );
		this._place( mirrored, surface, radius, image );
		redraw( this.scene );

	}

	/** Hide both rings. */
	hide() {

		for ( const ring of this._rings ) ring.visible = false;
		redraw( this.scene );

	}

	/** Take the rings out of the scene and free them. */
	dispose() {

		for ( const ring of this._rings ) {

			this.scene.remove( ring );
			ring.material.dispose();

		}

		this._rings[ 0 ].geometry.dispose();

	}

	_place( ring, surface, radius, at ) {

		ring.visible = false;
		if ( ! at ) return;
		const mesh = surface.mesh;
		mesh.updateWorldMatrix( true, false );
		const position = mesh.geometry.attributes.position;
		const [ a, b, c ] = surface.triangle( at.faceIndex ).map( ( i ) => new Vector3().fromBufferAttribute( position, i ) );
		const normal = new Triangle( a, b, c ).getNormal( new Vector3() ).transformDirection( mesh.matrixWorld );
		ring.position.copy( at.point ).applyMatrix4( mesh.matrixWorld );
		ring.quaternion.setFromUnitVectors( new Vector3( 0, 0, 1 ), normal );
		ring.scale.setScalar( radius * mesh.matrixWorld.getMaxScaleOnAxis() );
		ring.visible = true;

	}

}
