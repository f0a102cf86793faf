import { Vector3 } from 'three';

import { ApiError, api } from '../net/api.js';
import { SaveQueue } from '../net/SaveQueue.js';
import { BrushSettings } from '../model/BrushSettings.js';
import { MeshNeighbours } from '../model/MeshNeighbours.js';
import { PaintStroke } from '../model/PaintStroke.js';
import { PaintedRig } from '../model/PaintedRig.js';
import { reflect } from '../model/symmetryPlane.js';
import { BrushCursor } from '../scene/BrushCursor.js';

const SPACING = 0.25; // brush radii between dabs along a stroke

/**
 * Weight painting on a SkinnedFace: pick a feature point (joint) and paint its influence
 * with add, subtract, smooth and set brushes (PaintStroke; the settings and `configure`
 * are BrushSettings'); radius in mesh units, shown as
 * a ring on the surface (BrushCursor); optional left/right mirroring across the face's
 * symmetry plane (the landmarks' one, symmetryPlane.js) onto the mirror joint; undo and
 * redo per stroke; every stroke saved to the server shortly after it ends (SaveQueue).
 *
 * The brush paints a PaintedRig, the page's copy of the rig with its undo history, and
 * uploads only the changed rows to the face, so its heat map and the live pose follow
 * each dab.
 *
 * While active, a left-drag that starts on the face paints; Alt+drag or a drag off the face
 * orbits; Ctrl+click picks the feature point nearest the click. Picking is the landmark
 * picker's (MeshSurface, three-mesh-bvh on the rest pose).
 *
 * The same brushes paint a one-joint mask instead of the rig (`setTarget`: the Blendshapes
 * panel's per-shape fixes), with the target's own display and saving.
 *
 * Dispatches 'change' whenever what a panel shows changes (joint, brush, history, save).
 */
export class WeightPainter extends BrushSettings {

	/**
	 * @param {import('../scene/Viewer.js').Viewer} viewer
	 * @param {import('./LandmarkPicker.js').LandmarkPicker} picker - its surface is the face's.
	 */
	constructor( viewer, picker ) {

		super();
		this.viewer = viewer;
		this.picker = picker;
		/** Whether pointer drags paint. */
		this.active = false;
		/** Joint (feature point index) painted. */
		this.joint = 0;

		this.face = null;
		this.projectId = null;
		/** @type {PaintedRig|null} */
		this.rig = null;
		this._mirrorOf = null; // joint -> its mirror joint, from the layout
		this._target = null; // {show, save} of a mask painted instead of the rig (setTarget)
		this._plane = null; // the face's symmetry plane, mesh frame
		this._saves = new SaveQueue( ( vertices, options ) => this._send( vertices, options ), () => this._changed() );
		this._stroke = null; // {pointerId, last, paint: PaintStroke}
		this._neighbours = null; // the face's MeshNeighbours, built on the first dab
		this._hoverFrame = 0;
		this._hoverEvent = null;
		this._cursor = new BrushCursor( viewer.scene );

		this._onPointerDown = this._pointerDown.bind( this );
		this._onPointerMove = this._pointerMove.bind( this );
		this._onPointerUp = this._pointerUp.bind( this );
		this._onHover = this._hover.bind( this );
		this._onLeave = () => this._cursor.hide();
		// capture on the window runs before the picker's and OrbitControls' own listeners,
		// so a stroke can keep both from starting
		window.addEventListener( 'pointerdown', this._onPointerDown, { capture: true } );
		const canvas = viewer.renderer.domElement;
		canvas.addEventListener( 'pointermove', this._onHover );
		canvas.addEventListener( 'pointerleave', this._onLeave );

	}

	/**
	 * Paint this face's rig; null detaches (unsaved rows are dropped: `flush` first).
	 * @param {import('../scene/SkinnedFace.js').SkinnedFace|null} face
	 * @param {string|null} projectId
	 * @param {{version: number, painted_vertices: number}|null} info - GET .../rig.
	 * @param {{nJoints: number, nInfluences: number, indices: Uint16Array, weights: Float32Array}|null} weights -
	 *   `api.rigWeights`, as given to `face.setRig`; copied.
	 * @param {{points: Array<{mirror: number}>}|null} layout - the landmarks' layout (mirror partners).
	 */
	setRig( face, projectId, info, weights, layout ) {

		this._saves.clear();
		this._endStroke();
		this.face = face;
		this.projectId = projectId;
		this._neighbours = null;
		this._target = null;
		if ( ! face || ! weights ) {

			this.rig = null;
			this._mirrorOf = null;
			this.setActive( false );
			this._changed();
			return;

		}

		this.rig = new PaintedRig( weights, info );
		const mirror = layout && layout.points.length === weights.nJoints ? layout.points.map( ( p ) => p.mirror ) : null;
		this._mirrorOf = mirror;
		this._plane = mirror ? this.picker.symmetryPlane( mirror ) : null;
		if ( this.joint >= weights.nJoints ) this.joint = 0;
		const radius = face.mesh.geometry.boundingSphere.radius;
		if ( ! ( this.radius > radius * 1e-3 && this.radius < radius ) ) this.radius = 0.08 * radius;
		this._changed();

	}

	/**
	 * Paint a mask instead of a rig: `target.rig` is a PaintedRig of one joint and one
	 * influence per vertex (the mask's value), painted with the same brushes, cursor and
	 * undo; each dab calls `target.show( vertices )` and saving `target.save( vertices,
	 * {keepalive} )`. Null detaches (unsaved dabs are dropped: `flush` first).
	 * @param {import('../scene/SkinnedFace.js').SkinnedFace|null} face
	 * @param {{rig: PaintedRig, show: function(ArrayLike<number>): void,
	 *   save: function(ArrayLike<number>, object): Promise<void>}|null} target
	 */
	setTarget( face, target ) {

		this.setRig( target ? face : null, null, null, null, null );
		if ( ! target ) return;
		this._target = target;
		this.rig = target.rig;
		this.joint = 0;
		const radius = face.mesh.geometry.boundingSphere.radius;
		if ( ! ( this.radius > radius * 1e-3 && this.radius < radius ) ) this.radius = 0.08 * radius;
		this._changed();

	}

	/** Whether mirroring is possible (the layout names mirror partners). */
	get canMirror() {

		return this._mirrorOf !== null;

	}

	/** @param {boolean} on - pointer drags on the face paint. */
	setActive( on ) {

		this.active = Boolean( on ) && this.rig !== null;
		if ( ! this.active ) this._cursor.hide();
		this._changed();

	}

	/** @param {number} joint - the feature point to paint. */
	setJoint( joint ) {

		if ( ! this.rig || ! Number.isInteger( joint ) || joint < 0 || joint >= this.rig.nJoints ) {

			throw new RangeError( `WeightPainter.setJoint: ${ joint } is not a joint of the rig.` );

		}

		this.joint = joint;
		this._changed();

	}

	/** 'saved', 'unsaved', 'saving' or 'failed' (the reason in `saveError`). */
	get saveState() {

		return this._saves.state;

	}

	/** The server's reason the last save failed ('' when it did not). */
	get saveError() {

		return this._saves.error;

	}

	/** Whether there is an edit to undo. */
	get canUndo() {

		return Boolean( this.rig?.canUndo );

	}

	/** Whether there is an undone edit to redo. */
	get canRedo() {

		return Boolean( this.rig?.canRedo );

	}

	/** Undo the last stroke or reset; false when there is none (or a stroke is under way). */
	undo() {

		return this._changedRows( this._stroke ? null : this.rig?.undo() );

	}

	/** Redo the last undone stroke or reset; false when there is none. */
	redo() {

		return this._changedRows( this._stroke ? null : this.rig?.redo() );

	}

	/**
	 * Paint joints back to the automatic rig on the server (null: the whole rig) and show
	 * the result; undoable. Unsaved strokes are saved first.
	 * @param {number[]|null} joints
	 */
	async reset( joints ) {

		const rig = this.rig, id = this.projectId;
		if ( ! rig || this._target ) return; // a mask's target resets itself
		await this.flush();
		if ( this._saves.pending ) throw new ApiError( 0, `Cannot reset before the painted weights are saved: ${ this.saveError }` );
		const info = await api.resetRigWeights( id, joints, rig.version );
		const fresh = await api.rigWeights( id );
		if ( rig !== this.rig ) return;
		const vertices = rig.differing( fresh );
		rig.setInfo( info );
		if ( vertices.length ) {

			const step = { vertices, before: rig.rows( vertices ), after: rig.rows( vertices, fresh ) };
			rig.write( vertices, step.after );
			rig.record( step );
			this.face.updateWeights( vertices, rig.indices, rig.weights );

		}

		this._changed();

	}

	/**
	 * Save unsaved strokes now and wait for the answer.
	 * @param {{keepalive?: boolean}} [options] - keepalive: the page is being unloaded.
	 */
	flush( options ) {

		return this._saves.flush( options );

	}

	/** Retry a failed save. */
	retry() {

		return this._saves.retry();

	}

	/**
	 * Keys while active: Ctrl+Z undo, Ctrl+Shift+Z or Ctrl+Y redo, [ and ] shrink and grow
	 * the brush, Ctrl+S saves now; landmark edits (Delete, M) are ignored meanwhile.
	 * @param {KeyboardEvent} event
	 * @returns {boolean} whether the key was taken.
	 */
	key( event ) {

		if ( ! this.active ) return false;
		const key = event.key.toLowerCase(), mod = event.ctrlKey || event.metaKey;
		if ( mod && key === 'z' ) event.shiftKey ? this.redo() : this.undo();
		else if ( mod && key === 'y' ) this.redo();
		else if ( mod && key === 's' ) this.flush();
		else if ( ! mod && ( key === '[' || key === ']' ) ) this.configure( { radius: this.radius * ( key === ']' ? 1.25 : 0.8 ) } );
		else if ( ! mod && [ 'delete', 'backspace', 'm' ].includes( key ) ) return true;
		else return false;
		return true;

	}

	/** Stop listening and free the cursor rings. */
	dispose() {

		window.removeEventListener( 'pointerdown', this._onPointerDown, { capture: true } );
		const canvas = this.viewer.renderer.domElement;
		canvas.removeEventListener( 'pointermove', this._onHover );
		canvas.removeEventListener( 'pointerleave', this._onLeave );
		this._endStroke();
		cancelAnimationFrame( this._hoverFrame );
		this._cursor.dispose();

	}

	// strokes

	_pointerDown( event ) {

		if ( ! this.active || ! this.face || event.button !== 0 || event.altKey || event.target !== this.viewer.renderer.domElement ) return;
		const hit = this.picker.hitFace( event );
		if ( ! hit ) return; // off the face: the camera orbits
		event.stopPropagation();
		event.preventDefault();
		if ( event.ctrlKey || event.metaKey ) {

			const nearest = this.picker.nearest( hit.local );
			if ( nearest >= 0 && nearest < this.rig.nJoints ) this.setJoint( nearest );
			return;

		}

		this._neighbours ??= new MeshNeighbours( this.face.mesh.geometry.index.array, this.face.nVertices );
		const paint = new PaintStroke( this.rig, this._neighbours, this.face.mesh.geometry.attributes.position.array, this );
		this._stroke = { pointerId: event.pointerId, last: hit.local.clone(), paint };
		window.addEventListener( 'pointermove', this._onPointerMove );
		window.addEventListener( 'pointerup', this._onPointerUp );
		window.addEventListener( 'pointercancel', this._onPointerUp );
		this._dabs( hit.local, hit.faceIndex );
		this._showCursor( hit );

	}

	_pointerMove( event ) {

		const stroke = this._stroke;
		if ( ! stroke || event.pointerId !== stroke.pointerId ) return;
		const hit = this.picker.hitFace( event );
		this._showCursor( hit );
		if ( ! hit ) return;
		// dabs every SPACING radii from the last one, on the surface between it and the pointer
		const step = SPACING * this.radius;
		const distance = stroke.last.distanceTo( hit.local );
		if ( distance < step ) return;
		const from = stroke.last.clone(), at = new Vector3();
		const n = Math.floor( distance / step );
		for ( let i = 1; i < n; i ++ ) {

			at.lerpVectors( from, hit.local, i / n );
			const near = this.picker.surface.closest( at );
			if ( near ) this._dabs( near.point, near.faceIndex );

		}

		this._dabs( hit.local, hit.faceIndex );
		stroke.last.copy( hit.local );

	}

	_pointerUp( event ) {

		const stroke = this._stroke;
		if ( ! stroke || event.pointerId !== stroke.pointerId ) return;
		this._endStroke();
		const step = stroke.paint.step();
		if ( ! step ) return;
		this.rig.record( step );
		this._saves.add( step.vertices );

	}

	_endStroke() {

		this._stroke = null;
		window.removeEventListener( 'pointermove', this._onPointerMove );
		window.removeEventListener( 'pointerup', this._onPointerUp );
		window.removeEventListener( 'pointercancel', this._onPointerUp );

	}

	/** One dab at `center` (mesh frame, on triangle `faceIndex`), and its mirror image. */
	_dabs( center, faceIndex ) {

		const changed = new Set(), paint = this._stroke.paint;
		paint.dab( center, faceIndex, this.joint, changed );
		const mirrorJoint = this.mirror && this._mirrorOf ? this._mirrorOf[ this.joint ] : - 1;
		if ( mirrorJoint >= 0 ) {

			const image = this._mirrorImage( center );
			if ( image ) paint.dab( image.point, image.faceIndex, mirrorJoint, changed );

		}

		if ( changed.size ) this._show( Int32Array.from( changed ) );

	}

	/** The surface point at the mirror image of `point` (mesh frame), or null. */
	_mirrorImage( point ) {

		return this.picker.surface.closest( reflect( this._plane, point ) );

	}

	// history and saving

	/**
	 * The rig's rows of `vertices` changed (undo, redo): show and save them.
	 * @param {Int32Array|null|undefined} vertices - nothing changed when absent.
	 * @returns {boolean} whether rows changed.
	 */
	_changedRows( vertices ) {

		if ( ! vertices ) return false;
		this._show( vertices );
		this._saves.add( vertices );
		return true;

	}

	/** Show the painted rows of `vertices` on the face (or the mask's target). */
	_show( vertices ) {

		if ( this._target ) this._target.show( vertices );
		else this.face.updateWeights( vertices, this.rig.indices, this.rig.weights );

	}

	/** Save the rows of `vertices` (the save queue's `send`); the rig takes the new version. */
	async _send( vertices, { keepalive } ) {

		if ( this._target ) return this._target.save( vertices, { keepalive } );
		const rig = this.rig;
		const info = await api.patchRigWeights( this.projectId, rig, vertices, rig.rows( vertices ), { keepalive } );
		if ( rig === this.rig ) rig.setInfo( info );

	}

	// the cursor

	_hover( event ) {

		if ( ! this.active || this._stroke || event.buttons ) return;
		this._hoverEvent = event;
		if ( this._hoverFrame ) return;
		// at most one ray cast per animation frame, on the latest pointer position
		this._hoverFrame = requestAnimationFrame( () => {

			this._hoverFrame = 0;
			if ( this.active && ! this._stroke ) this._showCursor( this.picker.hitFace( this._hoverEvent ) );

		} );

	}

	/** The brush's rings at the hit and at its mirror image; null hides them. */
	_showCursor( hit ) {

		const surface = this.picker.surface;
		if ( ! hit || ! this.face || ! this.active || ! surface ) {

			this._cursor.hide();
			return;

		}

		const image = this.mirror && this._mirrorOf ? this._mirrorImage( hit.local ) : null;
		this._cursor.show( surface, this.radius, { point: hit.local, faceIndex: hit.faceIndex }, image );

	}

	_changed() {

		this.dispatchEvent( new Event( 'change' ) );

	}

}
