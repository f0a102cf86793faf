import { BufferGeometry, Mesh, Raycaster, Triangle, Vector2, Vector3 } from 'three';
import { acceleratedRaycast, computeBoundsTree, disposeBoundsTree } from 'three-mesh-bvh';

// three-mesh-bvh's README patch: a mesh whose geometry has a boundsTree raycasts through
// it (milliseconds on 100k+ triangles instead of a scan of every triangle).
BufferGeometry.prototype.computeBoundsTree = computeBoundsTree;
BufferGeometry.prototype.disposeBoundsTree = disposeBoundsTree;
Mesh.prototype.raycast = acceleratedRaycast;

const SNAP_PX = 3; // CSS px: a pointer this close to the surface still lands on it

/**
 * The rest surface of a face mesh for pointer work, on a three-mesh-bvh bounds tree: the
 * triangle under the pointer, the closest surface point to a point in space, and
 * conversions between positions and surface points (a triangle and barycentric weights,
 * the server's landmark form). Shared by landmark picking and weight painting.
 */
export class MeshSurface {

	/**
	 * @param {Mesh} mesh - its geometry (indexed; the rest pose) gets a bounds tree, until `dispose`.
	 */
	constructor( mesh ) {

		this.mesh = mesh;
		const geometry = mesh.geometry;
		// indirect: the bounds tree must not reorder the index buffer that SkinnedFace renders
		geometry.computeBoundsTree( { indirect: true } );
		if ( ! geometry.boundingSphere ) geometry.computeBoundingSphere();
		if ( ! geometry.boundingBox ) geometry.computeBoundingBox();
		this._raycaster = new Raycaster();
		this._raycaster.firstHitOnly = true;

	}

	/**
	 * The point of the rest pose under the pointer (what a click there places, or where a
	 * brush paints). A pointer just off the surface (on an eyelid's or the mouth's edge, at
	 * the silhouette) snaps to the front-most hit on the nearest ring of rays within
	 * SNAP_PX, so points on a hole's rim are as easy to reach as any other.
	 * @param {{clientX: number, clientY: number}} event - a pointer position, CSS px.
	 * @param {import('./Viewer.js').Viewer} viewer - its camera and canvas.
	 * @returns {{faceIndex: number, local: Vector3, distance: number}|null} the triangle
	 *   hit, the point in the mesh's local frame and its distance from the camera (world
	 *   units); null off the face.
	 */
	hit( event, viewer ) {

		const rect = viewer.renderer.domElement.getBoundingClientRect();
		for ( let r = 0; r <= SNAP_PX; r ++ ) {

			const rays = r === 0 ? 1 : 8 * r;
			let best = null;
			for ( let k = 0; k < rays; k ++ ) {

				const angle = ( 2 * Math.PI * k ) / rays;
				const x = event.clientX + r * Math.cos( angle ), y = event.clientY + r * Math.sin( angle );
				const ndc = new Vector2( ( ( x - rect.left ) / rect.width ) * 2 - 1, - ( ( y - rect.top ) / rect.height ) * 2 + 1 );
				this._raycaster.setFromCamera( ndc, viewer.camera );
				const hit = this._raycaster.intersectObject( this.mesh, false )[ 0 ];
				if ( hit && ( ! best || hit.distance < best.distance ) ) best = hit;

			}

			if ( best ) return { faceIndex: best.faceIndex, local: this.mesh.worldToLocal( best.point.clone() ), distance: best.distance };

		}

		return null;

	}

	/**
	 * The surface point closest to `point`.
	 * @param {Vector3} point - mesh frame.
	 * @returns {{point: Vector3, faceIndex: number}|null}
	 */
	closest( point ) {

		return this.mesh.geometry.boundsTree.closestPointToPoint( point );

	}

	/**
	 * The rest position of a surface point.
	 * @param {import('../model/LandmarkSet.js').SurfacePoint} point
	 * @param {Vector3} [target]
	 * @returns {Vector3} mesh frame.
	 */
	position( point, target = new Vector3() ) {

		const position = this.mesh.geometry.attributes.position;
		const [ a, b, c ] = point.triangle, [ u, v, w ] = point.barycentric;
		return target.set(
			u * position.getX( a ) + v * position.getX( b ) + w * position.getX( c ),
			u * position.getY( a ) + v * position.getY( b ) + w * position.getY( c ),
			u * position.getZ( a ) + v * position.getZ( b ) + w * position.getZ( c ),
		);

	}

	/**
	 * The surface point of a position on a triangle.
	 * @param {number} faceIndex - triangle index in the geometry's index.
	 * @param {Vector3} local - a point on that triangle, mesh frame.
	 * @returns {import('../model/LandmarkSet.js').SurfacePoint}
	 */
	surfacePoint( faceIndex, local ) {

		const triangle = this.triangle( faceIndex );
		const position = this.mesh.geometry.attributes.position;
		const [ a, b, c ] = triangle.map( ( i ) => new Vector3().fromBufferAttribute( position, i ) );
		const bary = Triangle.getBarycoord( local, a, b, c, new Vector3() ) || new Vector3( 1, 0, 0 );
		return { triangle, barycentric: normalisedWeights( bary.toArray() ) };

	}

	/**
	 * @param {number} faceIndex
	 * @returns {number[]} the triangle's three vertex indices.
	 */
	triangle( faceIndex ) {

		const index = this.mesh.geometry.index;
		return [ 0, 1, 2 ].map( ( k ) => ( index ? index.getX( 3 * faceIndex + k ) : 3 * faceIndex + k ) );

	}

	/** Free the bounds tree. */
	dispose() {

		this.mesh.geometry.disposeBoundsTree();

	}

}

/** Barycentric weights clamped to [0, 1] and renormalised (a hit on an edge may come out a hair negative). */
function normalisedWeights( w ) {

	const clamped = w.map( ( x ) => Math.min( 1, Math.max( 0, x ) ) );
	const sum = clamped[ 0 ] + clamped[ 1 ] + clamped[ 2 ];
	return sum > 0 ? clamped.map( ( x ) => x / sum ) : [ 1, 0, 0 ];

}
