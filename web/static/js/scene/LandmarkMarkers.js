import { Color, Group, Mesh, MeshBasicMaterial, MeshStandardMaterial, SphereGeometry, Vector3 } from 'three';

import { regionColor } from './palette.js';
import { redraw } from './Viewer.js';

const MARKER_SCALE = 0.0085; // marker radius as a fraction of the mesh's bounding-sphere radius
const GRAB_SLOP = 1.5; // CSS px beyond a marker's drawn radius that still grab it (close neighbours stay clickable)
const CHECK_COLOR = 0xff2a2a; // no region's colour (palette.js): a point to check reads as such on any of them
const CHECK_SCALE = 2.6; // the halo's radius over its marker's

/**
 * The feature points drawn on the face: one sphere per placed point in its region's
 * colour (palette.js), the selected one white and larger, the hovered one a little larger,
 * a point to check (found with a low confidence) inside a translucent red halo, moved by
 * the live feature displacements. A group beside the face in the scene (the
 * viewer's wireframe and framing apply to the face alone) that follows the face's world
 * matrix.
 */
export class LandmarkMarkers {

	/**
	 * @param {import('three').Scene} scene - the group is added while a face is shown.
	 */
	constructor( scene ) {

		this.scene = scene;
		/** The markers, one child per layout point (hidden while unplaced). */
		this.group = new Group();
		this.group.name = 'landmarks';
		this.group.matrixAutoUpdate = false; // follows the mesh's world matrix
		/** Whether the markers are drawn at all (`setShown`; hidden ones cannot be grabbed). */
		this.shown = true;
		this._sphere = new SphereGeometry( 1, 16, 12 );
		this._materials = new Map();
		this._selectedMaterial = new MeshStandardMaterial( { color: 0xffffff, emissive: 0x666666, roughness: 0.35 } );
		// unlit and without depth writes: a halo never hides its marker or a neighbour
		this._checkMaterial = new MeshBasicMaterial( { color: CHECK_COLOR, transparent: true, opacity: 0.5, depthWrite: false } );

	}

	/** How many drawn markers carry the halo of a point to check. */
	get flaggedCount() {

		return this.group.children.filter( ( marker ) => marker.visible && marker.userData.halo?.visible ).length;

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

		const group = this.group;
		while ( group.children.length < points.length ) group.add( new Mesh( this._sphere ) );
		while ( group.children.length > points.length ) group.remove( group.children[ group.children.length - 1 ] );
		if ( ! surface || ! layout ) {

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
		const radius = mesh.geometry.boundingSphere.radius * MARKER_SCALE;
		points.forEach( ( point, i ) => {

			const marker = group.children[ i ];
			marker.visible = point !== null;
			if ( ! point ) return;
			surface.position( point, marker.position );
			if ( offsets ) marker.position.x += offsets[ 3 * i ], marker.position.y += offsets[ 3 * i + 1 ], marker.position.z += offsets[ 3 * i + 2 ];
			marker.material = i === selected ? this._selectedMaterial : this._materialFor( layout.points[ i ].region );
			marker.scale.setScalar( radius * ( i === selected ? 1.45 : i === hovered ? 1.25 : 1 ) );
			marker.renderOrder = 1;
			this._halo( marker ).visible = Boolean( flagged?.[ i ] );

		} );
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

		const marker = this.group.children[ index ];
		if ( ! marker || ! marker.visible ) return null;
		return marker.getWorldPosition( new Vector3() ).toArray();

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
		this.group.children.forEach( ( marker, i ) => {

			if ( ! marker.visible ) return;
			marker.getWorldPosition( world );
			edge.copy( world ).addScaledVector( right, marker.scale.x * scale ).project( camera );
			world.project( camera );
			if ( world.z > 1 ) return;
			const x = rect.left + ( world.x + 1 ) / 2 * rect.width, y = rect.top + ( 1 - world.y ) / 2 * rect.height;
			const r = GRAB_SLOP + Math.abs( edge.x - world.x ) / 2 * rect.width;
			const d = Math.hypot( x - event.clientX, y - event.clientY );
			if ( d <= r && d < bestD ) {

				bestD = d;
				best = i;

			}

		} );
		if ( best < 0 ) return - 1;

		const hit = surface.hit( event, viewer );
		if ( hit ) {

			const marker = this.group.children[ best ];
			const distance = marker.getWorldPosition( world ).distanceTo( camera.getWorldPosition( edge ) );
			if ( hit.distance < distance - 3 * marker.scale.x * scale ) return - 1;

		}

		return best;

	}

	/** Take the markers out of the scene and free their geometry and materials. */
	dispose() {

		this.scene.remove( this.group );
		this._sphere.dispose();
		this._selectedMaterial.dispose();
		this._checkMaterial.dispose();
		for ( const material of this._materials.values() ) material.dispose();

	}

	_halo( marker ) {

		let halo = marker.userData.halo;
		if ( ! halo ) {

			halo = new Mesh( this._sphere, this._checkMaterial );
			halo.name = 'check';
			halo.scale.setScalar( CHECK_SCALE );
			halo.renderOrder = 2;
			marker.add( halo );
			marker.userData.halo = halo;

		}

		return halo;

	}

	_materialFor( region ) {

		let material = this._materials.get( region );
		if ( ! material ) {

			const color = new Color( regionColor( region ) );
			material = new MeshStandardMaterial( { color, emissive: color.clone().multiplyScalar( 0.35 ), roughness: 0.45 } );
			this._materials.set( region, material );

		}

		return material;

	}

}
