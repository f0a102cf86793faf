import { Plane, Raycaster, Vector2, Vector3 } from 'three';

/**
 * Dragging a muscle's handles (MuscleHandles) in the view: a handle slides in the plane
 * through it that faces the camera (an origin lies under the skin, off any surface), and
 * dispatches 'change' ({name, position: [x, y, z] in the face's model space}) when it is
 * let go. While a handle is held, neither the landmark picker nor the orbit controls see
 * the pointer.
 */
export class MuscleEditor extends EventTarget {

	/**
	 * @param {import('../scene/Viewer.js').Viewer} viewer
	 */
	constructor( viewer ) {

		super();
		this.viewer = viewer;
		/** @type {import('../scene/MuscleHandles.js').MuscleHandles|null} the handles that can be dragged. */
		this.handles = null;
		this._gesture = null;
		this._onPointerDown = this._pointerDown.bind( this );
		this._onPointerMove = this._pointerMove.bind( this );
		this._onPointerUp = this._pointerUp.bind( this );
		// capture above the landmark picker's (on the canvas's container): a grabbed handle
		// is this tool's alone
		this._root = viewer.renderer.domElement.parentElement.parentElement;
		this._root.addEventListener( 'pointerdown', this._onPointerDown, { capture: true } );

	}

	/** Stop listening. */
	dispose() {

		this._root.removeEventListener( 'pointerdown', this._onPointerDown, { capture: true } );
		this._end();

	}

	_pointerDown( event ) {

		const canvas = this.viewer.renderer.domElement;
		if ( event.button !== 0 || this.handles === null || event.target !== canvas ) return;
		const name = this.handles.handleAt( event, this.viewer );
		if ( name === null ) return;
		event.stopPropagation();
		event.preventDefault();
		const at = this.handles.handles.get( name ).getWorldPosition( new Vector3() );
		const facing = this.viewer.camera.getWorldDirection( new Vector3() );
		this._gesture = { name, pointerId: event.pointerId, plane: new Plane().setFromNormalAndCoplanarPoint( facing, at ), moved: false };
		canvas.style.cursor = 'grabbing';
		window.addEventListener( 'pointermove', this._onPointerMove );
		window.addEventListener( 'pointerup', this._onPointerUp );
		window.addEventListener( 'pointercancel', this._onPointerUp );

	}

	_pointerMove( event ) {

		const gesture = this._gesture;
		if ( ! gesture || event.pointerId !== gesture.pointerId ) return;
		const rect = this.viewer.renderer.domElement.getBoundingClientRect();
		const ndc = new Vector2( ( event.clientX - rect.left ) / rect.width * 2 - 1, 1 - ( event.clientY - rect.top ) / rect.height * 2 );
		const ray = new Raycaster();
		ray.setFromCamera( ndc, this.viewer.camera );
		const world = ray.ray.intersectPlane( gesture.plane, new Vector3() );
		if ( world === null ) return;
		this.handles.set( gesture.name, this.handles.face.worldToLocal( world ) );
		gesture.moved = true;

	}

	_pointerUp( event ) {

		const gesture = this._gesture;
		if ( ! gesture || event.pointerId !== gesture.pointerId ) return;
		this._end();
		if ( event.type === 'pointercancel' || ! gesture.moved ) return;
		const position = this.handles.handles.get( gesture.name ).position.toArray();
		this.dispatchEvent( new CustomEvent( 'change', { detail: { name: gesture.name, position } } ) );

	}

	_end() {

		this._gesture = null;
		this.viewer.renderer.domElement.style.cursor = '';
		window.removeEventListener( 'pointermove', this._onPointerMove );
		window.removeEventListener( 'pointerup', this._onPointerUp );
		window.removeEventListener( 'pointercancel', this._onPointerUp );

	}

}
