import { Color, DynamicDrawUsage, Group, InstancedMesh, Matrix4, MeshBasicMaterial, MeshStandardMaterial, Quaternion, SphereGeometry, Vector3 } from 'three';

import { regionColor } from './palette.js';
import { redraw } from './Viewer.js';

const MARKER_SCALE = 0.0085; // marker radius as a fraction of the mesh's bounding-sphere radius
const GRAB_SLOP = 1.5; // CSS px beyond a marker's drawn radius that still grab it (close neighbours stay clickable)
const CHECK_COLOR = 0xff2a2a; // no region's colour (palette.js): a point to check reads as such on any of them
const CHECK_SCALE = 2.6; // the halo's radius over its marker's
const SELECTED_SCALE = 1.45, HOVERED_SCALE = 1.25;
const SELECTED_COLOR = new Color( 0xffffff );

/**
 * The feature points drawn on the face: a sphere per placed point in its region's colour
 * (palette.js), the selected one white and larger, the hovered one a little larger, a point
 * to check (found with a low confidence) inside a translucent red halo, moved by the live
 * feature displacements. A group beside the face in the scene (the viewer's wireframe and
 * framing apply to the face alone) that follows the face's world matrix.
 *
 * The spheres are one `InstancedMesh` (`points`, instance i = point i, an unplaced point
 * scaled to nothing) and the halos another (`halos`, one instance per point to check), so
 * a dense layout's 468 points cost two draw calls, not 468 (or 936 with their halos).
 */
export class LandmarkMarkers {

	/**
	 * @param {import('three').Scene} scene - the group is added while a face is shown.
	 */
	constructor( scene ) {

		this.scene = scene;
		/** The markers: `points` and `halos`. */
		this.group = new Group();
		this.group.name = 'landmarks';
		this.group.matrixAutoUpdate = false; // follows the mesh's world matrix
		/** Whether the markers are drawn at all (`setShown`; hidden ones cannot be grabbed). */
		this.shown = true;
		// coarse: a marker is a few pixels wide, and SwiftShader (and weak GPUs) pay per vertex
		// for a dense layout's 468 spheres, instanced or not
		this._sphere = new SphereGeometry( 1, 10, 8 );
		// the region's colour tints the emission as well as the albedo (as a material per
		// region did), so a marker in shadow still reads as its region
		this._material = new MeshStandardMaterial( { color: 0xffffff, emissive: 0xffffff, emissiveIntensity: 0.35, roughness: 0.45 } );
		this._material.onBeforeCompile = ( shader ) => {

			shader.fragmentShader = shader.fragmentShader.replace( '#include <emissivemap_fragment>',
				'#include <emissivemap_fragment>\n\ttotalEmissiveRadiance *= vColor.rgb;' );

		};

		this._material.customProgramCacheKey = () => 'landmark-markers';
		// unlit and without depth writes: a halo never hides its marker or a neighbour
		this._checkMaterial = new MeshBasicMaterial( { color: CHECK_COLOR, transparent: true, opacity: 0.5, depthWrite: false } );
		/** @type {InstancedMesh} one sphere per layout point. */
		this.points = this._instanced( 'points', this._material, 16, 1 );
		/** @type {InstancedMesh} one halo per drawn point to check. */
		this.halos = this._instanced( 'check', this._checkMaterial, 16, 2 );
		this._positions = new Float32Array( 0 ); // (3N) marker centres in the face's model space
		this._radii = new Float32Array( 0 ); // (N) marker radii in model units, 0 for an undrawn point
		this._colors = new Map(); // region -> Color

	}

	/** How many drawn markers carry the halo of a point to check. */
	get flaggedCount() {

		return this.halos.count;

	}

	/** How many points are drawn (placed). */
	get drawnCount() {

		let n = 0;
		for ( const r of this._radii ) if ( r > 0 ) n ++;
		return n;

	}

	/**
	 * Draw the points (at the viewer's next frame).
	 * @param {import('./MeshSurface.js').MeshSurface|null} surface - the face; null hides every marker.
	 * @param {{points: Array<{region: string}>}|null} layout
	 * @param {Array<import('../model/LandmarkSet.js').SurfacePoint|null>} points
	 * @param {{selected: number, hovered: number, offsets: Float32Array|null, flagged?: boolean[]}} show -
	 *   offsets: (3N) live displacements added to the rest positions, or null; flagged:
	 *   per point, whether it asks to be checked.
	 */
	update( surface, layout, points, { selected, hovered, offsets, flagged = null } ) {

		const group = this.group, n = points.length;
		if ( this._radii.length !== n ) {

			this._positions = new Float32Array( 3 * n );
			this._radii = new Float32Array( n );

		}

		if ( ! surface || ! layout ) {

			this._radii.fill( 0 );
			this.points.count = this.halos.count = 0;
			group.visible = false;
			this.scene.remove( group );
			redraw( this.scene );
			return;

		}

		const mesh = surface.mesh;
		this.scene.add( group );
		group.visible = this.shown;
		mesh.updateWorldMatrix( true, false );
		group.matrix.copy( mesh.matrixWorld );
		group.updateMatrixWorld( true );
		const radius = mesh.geometry.boundingSphere.radius * MARKER_SCALE;
		const nFlagged = flagged ? flagged.reduce( ( sum, f, i ) => sum + ( f && points[ i ] ? 1 : 0 ), 0 ) : 0;
		const spheres = this.points = this._fit( this.points, n );
		const halos = this.halos = this._fit( this.halos, nFlagged );
		const at = new Vector3(), scale = new Vector3(), matrix = new Matrix4(), still = new Quaternion();
		let h = 0;
		for ( let i = 0; i < n; i ++ ) {

			const point = points[ i ];
			if ( point ) {

				surface.position( point, at );
				if ( offsets ) at.x += offsets[ 3 * i ], at.y += offsets[ 3 * i + 1 ], at.z += offsets[ 3 * i + 2 ];

			}

			const r = point ? radius * ( i === selected ? SELECTED_SCALE : i === hovered ? HOVERED_SCALE : 1 ) : 0;
			at.toArray( this._positions, 3 * i );
			this._radii[ i ] = r;
			spheres.setMatrixAt( i, matrix.compose( at, still, scale.setScalar( r ) ) );
			spheres.setColorAt( i, i === selected ? SELECTED_COLOR : this._colorFor( layout.points[ i ].region ) );
			if ( point && flagged?.[ i ] ) halos.setMatrixAt( h ++, matrix.compose( at, still, scale.setScalar( r * CHECK_SCALE ) ) );

		}

		spheres.count = n;
		halos.count = h;
		halos.visible = h > 0; // no empty draw call
		spheres.instanceMatrix.needsUpdate = true;
		if ( spheres.instanceColor ) spheres.instanceColor.needsUpdate = true;
		halos.instanceMatrix.needsUpdate = true;
		redraw( this.scene );

	}

	/**
	 * Draw the markers or hide them all (they keep following the face).
	 * @param {boolean} shown
	 */
	setShown( shown ) {

		this.shown = Boolean( shown );
		if ( this.group.parent ) this.group.visible = this.shown;
		redraw( this.scene );

	}

	/**
	 * The world position of a drawn marker.
	 * @param {number} index
	 * @returns {number[]|null} [x, y, z]; null when it is not drawn.
	 */
	worldPosition( index ) {

		if ( ! ( this._radii[ index ] > 0 ) ) return null;
		return this._world( index, new Vector3() ).toArray();

	}

	/**
	 * The drawn marker nearest the pointer within its radius on screen (plus GRAB_SLOP
	 * px), -1 for none. A marker behind the surface under the pointer does not count.
	 * @param {{clientX: number, clientY: number}} event
	 * @param {import('./Viewer.js').Viewer} viewer
	 * @param {import('./MeshSurface.js').MeshSurface} surface
	 * @returns {number}
	 */
	markerAt( event, viewer, surface ) {

		if ( ! this.group.visible ) return - 1;
		const rect = viewer.renderer.domElement.getBoundingClientRect();
		const camera = viewer.camera;
		const scale = surface.mesh.matrixWorld.getMaxScaleOnAxis();
		const world = new Vector3(), edge = new Vector3(), right = new Vector3().setFromMatrixColumn( camera.matrixWorld, 0 );
		let best = - 1, bestD = Infinity;
		for ( let i = 0; i < this._radii.length; i ++ ) {

			if ( ! ( this._radii[ i ] > 0 ) ) continue;
			this._world( i, world );
			edge.copy( world ).addScaledVector( right, this._radii[ i ] * scale ).project( camera );
			world.project( camera );
			if ( world.z > 1 ) continue;
			const x = rect.left + ( world.x + 1 ) / 2 * rect.width, y = rect.top + ( 1 - world.y ) / 2 * rect.height;
			const r = GRAB_SLOP + Math.abs( edge.x - world.x ) / 2 * rect.width;
			const d = Math.hypot( x - event.clientX, y - event.clientY );
			if ( d <= r && d < bestD ) {

				bestD = d;
				best = i;

			}

		}

		if ( best < 0 ) return - 1;

		const hit = surface.hit( event, viewer );
		if ( hit ) {

			const distance = this._world( best, world ).distanceTo( camera.getWorldPosition( edge ) );
			if ( hit.distance < distance - 3 * this._radii[ best ] * scale ) return - 1;

		}

		return best;

	}

	/** Take the markers out of the scene and free their geometry and materials. */
	dispose() {

		this.scene.remove( this.group );
		this.points.dispose();
		this.halos.dispose();
		this._sphere.dispose();
		this._material.dispose();
		this._checkMaterial.dispose();

	}

	_world( index, target ) {

		return target.fromArray( this._positions, 3 * index ).applyMatrix4( this.group.matrixWorld );

	}

	_instanced( name, material, capacity, renderOrder ) {

		const mesh = new InstancedMesh( this._sphere, material, capacity );
		mesh.name = name;
		mesh.count = 0;
		mesh.renderOrder = renderOrder;
		mesh.instanceMatrix.setUsage( DynamicDrawUsage ); // rewritten on every stream frame
		// the instances move with the stream: a bounding sphere computed once would cull them wrongly
		mesh.frustumCulled = false;
		this.group.add( mesh );
		return mesh;

	}

	/** `mesh`, or a larger one in its place when it holds fewer than `n` instances. */
	_fit( mesh, n ) {

		if ( mesh.instanceMatrix.count >= n ) return mesh;
		const grown = this._instanced( mesh.name, mesh.material, Math.max( n, 2 * mesh.instanceMatrix.count, 16 ), mesh.renderOrder );
		this.group.remove( mesh );
		mesh.dispose();
		return grown;

	}

	_colorFor( region ) {

		let color = this._colors.get( region );
		if ( ! color ) {

			color = new Color( regionColor( region ) );
			this._colors.set( region, color );

		}

		return color;

	}

}
