import { Vector3 } from 'three';

import { placedByHand } from '../model/LandmarkSet.js';
import { reflect, symmetryPlane } from '../model/symmetryPlane.js';
import { LandmarkMarkers } from '../scene/LandmarkMarkers.js';
import { MeshSurface } from '../scene/MeshSurface.js';

const CLICK_SLOP = 5; // CSS px a click may move and still place a point (more is an orbit)

/**
 * Landmark picking on a face mesh, the pointer half of the Landmarks panel: click to place
 * the layout's next point, drag a marker to slide it over the surface, select (Shift+click,
 * or a click once all are placed); Mirror places missing left/right partners. The points
 * themselves, their history and selection are a `LandmarkSet` (`landmarks`); the face's
 * surface is a `MeshSurface` (picking on a bounds tree of the rest pose), the markers
 * `LandmarkMarkers`.
 *
 * Dispatches 'hover' (detail: {index}, -1 for none) as the pointer moves over markers.
 * The landmark getters below (state, points, placedCount, dirty, ...) read the set; the
 * end-to-end tests use them through `window.app.picker`.
 */
export class LandmarkPicker extends EventTarget {

	/**
	 * @param {import('../scene/Viewer.js').Viewer} viewer
	 * @param {import('../model/LandmarkSet.js').LandmarkSet} landmarks - what is placed.
	 */
	constructor( viewer, landmarks ) {

		super();
		this.viewer = viewer;
		this.landmarks = landmarks;
		/** The face's surface while a mesh is shown, else null. */
		this.surface = null;
		/** The marker under the pointer, -1 for none. */
		this.hovered = - 1;
		this.markers = new LandmarkMarkers( viewer.scene );

		this._offsets = null;
		this._gesture = null;
		this._hoverFrame = 0;
		this._hoverEvent = null;
		this._onChange = () => this._updateMarkers(); // drawn by the viewer's next frame
		this._onPointerDown = this._pointerDown.bind( this );
		this._onPointerMove = this._pointerMove.bind( this );
		this._onPointerUp = this._pointerUp.bind( this );
		this._onHover = this._hover.bind( this );
		landmarks.addEventListener( 'change', this._onChange );
		const element = viewer.renderer.domElement;
		// capture on the container runs before OrbitControls' own pointerdown on the canvas,
		// so grabbing a marker can switch the controls off before they start an orbit
		element.parentElement.addEventListener( 'pointerdown', this._onPointerDown, { capture: true } );
		element.addEventListener( 'pointermove', this._onHover );

	}

	// the landmarks, as the tests read them

	/** @returns {import('../model/LandmarkSet.js').PickState} */
	get state() {

		return this.landmarks.state;

	}

	/** @returns {Array<import('../model/LandmarkSet.js').SurfacePoint|null>} one per layout point. */
	get points() {

		return this.landmarks.points;

	}

	/** The selected point, -1 for none. */
	get selected() {

		return this.landmarks.selected;

	}

	/** Number of placed points. */
	get placedCount() {

		return this.landmarks.placedCount;

	}

	/** Whether the points differ from the saved ones. */
	get dirty() {

		return this.landmarks.dirty;

	}

	/** Whether there is an edit to undo. */
	get canUndo() {

		return this.landmarks.canUndo;

	}

	/**
	 * Pick on this mesh (its geometry's rest positions); null detaches the picker.
	 * @param {import('three').Mesh|null} mesh
	 */
	setMesh( mesh ) {

		this.surface?.dispose();
		this.surface = mesh ? new MeshSurface( mesh ) : null;
		this._updateMarkers();

	}

	/**
	 * The rest-pose position of a placed point in the mesh's local frame.
	 * @param {number} index
	 * @param {Vector3} [target]
	 * @returns {Vector3|null} null when unplaced (or without a mesh).
	 */
	position( index, target = new Vector3() ) {

		const point = this.landmarks.points[ index ];
		return point && this.surface ? this.surface.position( point, target ) : null;

	}

	/**
	 * The placed point nearest a position at rest.
	 * @param {Vector3} point - mesh frame.
	 * @returns {number} its index; -1 when none is placed.
	 */
	nearest( point ) {

		let best = - 1, bestD = Infinity;
		const p = new Vector3();
		this.landmarks.points.forEach( ( _, i ) => {

			if ( ! this.position( i, p ) ) return;
			const d = p.distanceToSquared( point );
			if ( d < bestD ) {

				bestD = d;
				best = i;

			}

		} );
		return best;

	}

	/**
	 * The world position of a placed marker as drawn (live offsets included): what
	 * `viewer.project` needs to find it on screen.
	 * @param {number} index
	 * @returns {number[]|null} [x, y, z]
	 */
	worldPosition( index ) {

		return this.markers.worldPosition( index );

	}

	/**
	 * The point of the face's rest pose under the pointer (MeshSurface.hit).
	 * @param {{clientX: number, clientY: number}} event
	 * @returns {{faceIndex: number, local: Vector3, distance: number}|null}
	 */
	hitFace( event ) {

		return this.surface ? this.surface.hit( event, this.viewer ) : null;

	}

	/**
	 * The face's left/right symmetry plane from the placed points (symmetryPlane.js), in
	 * the mesh's frame.
	 * @param {number[]} [mirror] - each point's mirror partner; default: the layout's.
	 * @returns {import('../model/symmetryPlane.js').Plane|null} null without a mesh or layout.
	 */
	symmetryPlane( mirror = this.landmarks.layout?.points.map( ( p ) => p.mirror ) ) {

		if ( ! mirror || ! this.surface ) return null;
		return symmetryPlane( ( i, target ) => this.position( i, target ), mirror, this.surface.mesh.geometry.boundingBox );

	}

	/**
	 * Place every unplaced mirror partner of a placed point at its mirror image across the
	 * face's symmetry plane, snapped to the closest surface point; one undo step.
	 * @returns {{placed: number, plane: import('../model/symmetryPlane.js').Plane|null}} how
	 *   many points were placed, across which plane.
	 */
	mirror() {

		const landmarks = this.landmarks, layout = landmarks.layout;
		const plane = this.symmetryPlane();
		if ( ! plane ) return { placed: 0, plane };
		const placed = landmarks.points, points = placed.slice();
		const p = new Vector3();
		let count = 0;
		layout.points.forEach( ( info, i ) => {

			const j = info.mirror;
			if ( j === i || j < 0 || ! placed[ i ] || points[ j ] ) return;
			const hit = this.surface.closest( reflect( plane, this.surface.position( placed[ i ], p ) ) );
			if ( ! hit ) return;
			points[ j ] = this.surface.surfacePoint( hit.faceIndex, hit.point );
			count ++;

		} );
		if ( count ) landmarks.commit( { layout: landmarks.state.layout, points } );
		return { placed: count, plane };

	}

	/**
	 * Move the markers with the live feature displacements (a feature point is a joint,
	 * so it moves by exactly its displacement); null puts them back at rest.
	 * @param {Float32Array|null} displacements - (3N) point-major x, y, z in mesh units.
	 */
	setDisplacements( displacements ) {

		this._offsets = displacements && displacements.length === 3 * this.landmarks.points.length ? displacements : null;
		this._updateMarkers();

	}

	/** Stop listening; free the surface's bounds tree and the markers. */
	dispose() {

		const element = this.viewer.renderer.domElement;
		element.parentElement.removeEventListener( 'pointerdown', this._onPointerDown, { capture: true } );
		element.removeEventListener( 'pointermove', this._onHover );
		this.landmarks.removeEventListener( 'change', this._onChange );
		this._endGesture();
		cancelAnimationFrame( this._hoverFrame );
		this.setMesh( null );
		this.markers.dispose();

	}

	_updateMarkers() {

		this.markers.update( this.surface, this.landmarks.layout, this.landmarks.points,
			{ selected: this.landmarks.selected, hovered: this.hovered, offsets: this._offsets, flagged: this.landmarks.flagged } );

	}

	_markerAt( event ) {

		return this.surface ? this.markers.markerAt( event, this.viewer, this.surface ) : - 1;

	}

	_pointerDown( event ) {

		if ( event.button !== 0 || ! this.surface || ! this.landmarks.layout || event.target !== this.viewer.renderer.domElement ) return;
		const marker = this._markerAt( event );
		this._gesture = { x: event.clientX, y: event.clientY, marker, moved: false, before: this.landmarks.state,
			pointerId: event.pointerId, controls: this.viewer.controls.enabled };
		if ( marker >= 0 ) {

			// maybe a marker drag: the camera must not orbit while it slides
			this.viewer.controls.enabled = false;
			this.viewer.renderer.domElement.style.cursor = 'grabbing';

		}

		window.addEventListener( 'pointermove', this._onPointerMove );
		window.addEventListener( 'pointerup', this._onPointerUp );
		window.addEventListener( 'pointercancel', this._onPointerUp );

	}

	_pointerMove( event ) {

		const gesture = this._gesture;
		if ( ! gesture || event.pointerId !== gesture.pointerId ) return;
		if ( ! gesture.moved && Math.hypot( event.clientX - gesture.x, event.clientY - gesture.y ) > CLICK_SLOP ) {

			gesture.moved = true;
			if ( gesture.marker >= 0 ) this.landmarks.selected = gesture.marker;

		}

		if ( gesture.marker < 0 || ! gesture.moved ) return;
		const hit = this.hitFace( event );
		if ( ! hit ) return;
		// slide without a history entry per move: the whole drag is one undo step (on release)
		this.landmarks.slide( gesture.marker, this.surface.surfacePoint( hit.faceIndex, hit.local ) );

	}

	_pointerUp( event ) {

		const gesture = this._gesture;
		if ( ! gesture || event.pointerId !== gesture.pointerId ) return;
		this._endGesture();
		if ( event.type === 'pointercancel' ) return;
		const landmarks = this.landmarks;
		if ( gesture.moved ) {

			// a marker drag is one undo step; any other drag was an orbit
			if ( gesture.marker >= 0 && landmarks.state !== gesture.before ) landmarks.commit( landmarks.state, gesture.before );
			return;

		}

		// a click places the next point, even on a marker: on a closed mouth the lower inner
		// lip's points lie on the upper's. With nothing left to place, or with Shift, a
		// click on a marker selects it. A dense layout's points are found, not placed: a click
		// there only selects.
		const next = placedByHand( landmarks.layout ) ? landmarks.next : - 1;
		if ( gesture.marker >= 0 && ( next < 0 || event.shiftKey ) ) {

			landmarks.select( gesture.marker );
			return;

		}

		const hit = this.hitFace( event );
		if ( next >= 0 && hit ) landmarks.place( next, this.surface.surfacePoint( hit.faceIndex, hit.local ) );
		else if ( landmarks.selected >= 0 ) landmarks.select( - 1 );

	}

	_endGesture() {

		window.removeEventListener( 'pointermove', this._onPointerMove );
		window.removeEventListener( 'pointerup', this._onPointerUp );
		window.removeEventListener( 'pointercancel', this._onPointerUp );
		if ( this._gesture && this._gesture.marker >= 0 ) {

			this.viewer.controls.enabled = this._gesture.controls;
			this.viewer.renderer.domElement.style.cursor = '';

		}

		this._gesture = null;

	}

	_hover( event ) {

		if ( this._gesture || event.buttons ) return;
		if ( this._hoverFrame ) {

			this._hoverEvent = event;
			return;

		}

		// at most one hover test per animation frame, on the latest pointer position
		this._hoverEvent = event;
		this._hoverFrame = requestAnimationFrame( () => {

			this._hoverFrame = 0;
			const e = this._hoverEvent;
			const marker = this._markerAt( e );
			const element = this.viewer.renderer.domElement;
			element.style.cursor = marker >= 0 ? 'grab' : ( this.landmarks.layout && placedByHand( this.landmarks.layout ) && this.landmarks.next >= 0 && this.hitFace( e ) ? 'crosshair' : '' );
			if ( marker !== this.hovered ) {

				this.hovered = marker;
				this._updateMarkers();
				this.dispatchEvent( new CustomEvent( 'hover', { detail: { index: marker } } ) );

			}

		} );

	}

}
