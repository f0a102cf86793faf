import { BufferAttribute, BufferGeometry, Group, Line, LineBasicMaterial, Mesh, MeshBasicMaterial, SphereGeometry, Vector3 } from 'three';

import { redraw } from './Viewer.js';

const HANDLE_SCALE = 0.025; // handle radius as a fraction of the face's bounding-sphere radius
const GRAB_SLOP = 4; // CSS px beyond a handle's drawn radius that still grab it
const COLORS = { origin: 0xff6b5a, insertion: 0xffd24a, centre: 0x6cc4ff };

/**
 * The handles of one muscle being edited, drawn over the face (an origin lies under the
 * skin, so they ignore depth): a linear muscle's origin and insertion joined by a line, a
 * sphincter's centre. A child of the face's mesh, in its model space, so it turns with
 * the head.
 */
export class MuscleHandles {

	/**
	 * @param {import('three').Mesh} face - the face's mesh (its bounding sphere sizes the handles).
	 */
	constructor( face ) {

		this.face = face;
		this.group = new Group();
		this.group.name = 'muscle-handles';
		this._sphere = new SphereGeometry( HANDLE_SCALE * face.geometry.boundingSphere.radius, 12, 8 );
		this._line = new Line( new BufferGeometry().setAttribute( 'position', new BufferAttribute( new Float32Array( 6 ), 3 ) ),
			new LineBasicMaterial( { color: 0xffffff, depthTest: false, transparent: true, opacity: 0.7 } ) );
		this._line.renderOrder = 10;
		this._line.frustumCulled = false;
		/** @type {Map<string, Mesh>} handle name -> its sphere. */
		this.handles = new Map();
		for ( const [ name, color ] of Object.entries( COLORS ) ) {

			const handle = new Mesh( this._sphere, new MeshBasicMaterial( { color, depthTest: false, transparent: true, opacity: 0.9 } ) );
			handle.renderOrder = 11;
			handle.name = name;
			this.handles.set( name, handle );
			this.group.add( handle );

		}

		this.group.add( this._line );
		this.group.visible = false;
		face.add( this.group );

	}

	/**
	 * Show the handles of `points` (model space), or none.
	 * @param {Object<string, number[]>|null} points - {origin, insertion} or {centre}.
	 */
	show( points ) {

		this.group.visible = points !== null;
		for ( const [ name, handle ] of this.handles ) {

			handle.visible = points !== null && name in points;
			if ( handle.visible ) handle.position.fromArray( points[ name ] );

		}

		this._updateLine();
		redraw( this.face );

	}

	/**
	 * Move a handle.
	 * @param {string} name
	 * @param {Vector3} position - model space.
	 */
	set( name, position ) {

		this.handles.get( name ).position.copy( position );
		this._updateLine();
		redraw( this.face );

	}

	/**
	 * The handle under a pointer event, or null.
	 * @param {PointerEvent} event
	 * @param {import('./Viewer.js').Viewer} viewer
	 * @returns {string|null}
	 */
	handleAt( event, viewer ) {

		if ( ! this.group.visible ) return null;
		let best = null, bestD = Infinity;
		const radius = this._sphere.parameters.radius;
		for ( const [ name, handle ] of this.handles ) {

			if ( ! handle.visible ) continue;
			const world = handle.getWorldPosition( new Vector3() );
			const edge = world.clone().addScaledVector( new Vector3().setFromMatrixColumn( viewer.camera.matrixWorld, 0 ), radius * this.face.matrixWorld.getMaxScaleOnAxis() );
			const at = viewer.project( world.toArray() ), rim = viewer.project( edge.toArray() );
			const d = Math.hypot( at.x - event.clientX, at.y - event.clientY );
			if ( d <= GRAB_SLOP + Math.hypot( rim.x - at.x, rim.y - at.y ) && d < bestD ) {

				best = name;
				bestD = d;

			}

		}

		return best;

	}

	/** Take the handles off the face and free them. */
	dispose() {

		this.face.remove( this.group );
		this._sphere.dispose();
		this._line.geometry.dispose();
		this._line.material.dispose();
		for ( const handle of this.handles.values() ) handle.material.dispose();
		redraw( this.face );

	}

	_updateLine() {

		const origin = this.handles.get( 'origin' ), insertion = this.handles.get( 'insertion' );
		this._line.visible = origin.visible && insertion.visible;
		if ( ! this._line.visible ) return;
		const position = this._line.geometry.getAttribute( 'position' );
		position.setXYZ( 0, ...origin.position.toArray() );
		position.setXYZ( 1, ...insertion.position.toArray() );
		position.needsUpdate = true;

	}

}
