import * as THREE from 'three';

import { ApiError, api } from './net/api.js';
import { MeshNeighbours } from './MeshNeighbours.js';
import { SaveQueue } from './SaveQueue.js';
import { reflect, symmetryPlane } from './symmetryPlane.js';
import { jointWeight, setJointWeight } from './weightRows.js';

export const BRUSHES = [ 'add', 'subtract', 'smooth', 'set' ];
const SPACING = 0.25; // brush radii between dabs along a stroke
const RING_INNER = 0.94; // the cursor ring's inner radius, in brush radii

/**
 * @typedef {{vertices: Int32Array, before: {indices: Uint16Array, weights: Float32Array},
 *   after: {indices: Uint16Array, weights: Float32Array}}} PaintStep
 *   One undo step: the rows (k slots each) of `vertices` before and after a stroke or reset.
 */

/**
 * Weight painting on a SkinnedFace: pick a feature point (joint) and paint its influence
 * with add, subtract, smooth and set brushes; radius in mesh units, shown as a ring on the
 * surface; optional left/right mirroring across the face's symmetry plane onto the mirror
 * joint; undo and redo per stroke; every stroke saved to the server shortly after it ends.
 *
 * The brush works on the rows of the loaded rig (weightRows.js: w_j set, the other
 * influences and the static root rescaled, at most k kept) and uploads only the changed
 * rows to the face, so its heat map and the live pose follow each dab. A brush covers the
 * vertices within its radius that the surface connects to the point under the pointer
 * (MeshNeighbours), so painting the upper lip leaves the lower lip alone. Strokes do not
 * accumulate (Blender's default): within one stroke a vertex moves toward the brush's
 * target by at most the strength; the smooth brush does accumulate, pulling w_j toward
 * its 1-ring mean. Mirroring reflects the brush across the landmarks' symmetry plane
 * (symmetryPlane.js); strokes reach the server through a SaveQueue.
 *
 * While active, a left-drag that starts on the face paints; Alt+drag or a drag off the face
 * orbits; Ctrl+click picks the feature point nearest the click. Picking is the landmark
 * picker's (three-mesh-bvh on the rest pose).
 *
 * Dispatches 'change' whenever what a panel shows changes (joint, brush, history, save).
 */
export class WeightPainter extends EventTarget {

	/**
	 * @param {import('./scene/Viewer.js').Viewer} viewer
	 * @param {import('./LandmarkPicker.js').LandmarkPicker} picker - its mesh is the face's.
	 */
	constructor( viewer, picker ) {

		super();
		this.viewer = viewer;
		this.picker = picker;
		/** Whether pointer drags paint. */
		this.active = false;
		/** Joint (feature point index) painted. */
		this.joint = 0;
		/** One of BRUSHES. */
		this.brush = 'add';
		/** Brush radius, mesh units. */
		this.radius = 1;
		/** How far one stroke moves a weight (add, subtract: by up to this; set, smooth: this fraction of the way). */
		this.strength = 0.5;
		/** The set brush's target weight. */
		this.value = 1;
		/** Also paint the mirror joint at the mirrored point. */
		this.mirror = false;

		this.face = null;
		this.projectId = null;
		/** @type {{nJoints: number, nInfluences: number, indices: Uint16Array, weights: Float32Array, version: number, painted: number}|null} */
		this.rig = null;
		this._mirrorOf = null; // joint -> its mirror joint, from the layout
		this._plane = null; // the face's symmetry plane (symmetryPlane.js), mesh frame
		this._undo = [];
		this._redo = [];
		this._saves = new SaveQueue( ( vertices, options ) => this._send( vertices, options ), () => this._changed() );
		this._stroke = null;
		this._neighbours = null; // the face's MeshNeighbours, built on the first dab
		this._hoverFrame = 0;
		this._hoverEvent = null;

		const ringGeometry = new THREE.RingGeometry( RING_INNER, 1, 64 );
		this._rings = [ 0xffffff, 0x9ecbff ].map( ( color ) => {

			const ring = new THREE.Mesh( ringGeometry, new THREE.MeshBasicMaterial( { color, transparent: true, opacity: 0.9, depthTest: false, side: THREE.DoubleSide } ) );
			ring.renderOrder = 2;
			ring.visible = false;
			ring.name = 'brush';
			viewer.scene.add( ring );
			return ring;

		} );

		this._onPointerDown = this._pointerDown.bind( this );
		this._onPointerMove = this._pointerMove.bind( this );
		this._onPointerUp = this._pointerUp.bind( this );
		this._onHover = this._hover.bind( this );
		this._onLeave = () => this._showRings( null );
		// capture on the window runs before the picker's and OrbitControls' own listeners,
		// so a stroke can keep both from starting
		window.addEventListener( 'pointerdown', this._onPointerDown, { capture: true } );
		const canvas = viewer.renderer.domElement;
		canvas.addEventListener( 'pointermove', this._onHover );
		canvas.addEventListener( 'pointerleave', this._onLeave );

	}

	/**
	 * Paint this face's rig; null detaches (unsaved rows are dropped: `flush` first).
	 * @param {import('./scene/SkinnedFace.js').SkinnedFace|null} face
	 * @param {string|null} projectId
	 * @param {{version: number, painted_vertices: number}|null} info - GET .../rig.
	 * @param {{nJoints: number, nInfluences: number, indices: Uint16Array, weights: Float32Array}|null} weights -
	 *   `api.rigWeights`, as given to `face.setRig`; copied.
	 * @param {{points: Array<{mirror: number}>}|null} layout - the landmarks' layout (mirror partners).
	 */
	setRig( face, projectId, info, weights, layout ) {

		this._saves.clear();
		this._endStroke();
		this._undo = [];
		this._redo = [];
		this.face = face;
		this.projectId = projectId;
		this._neighbours = null;
		if ( ! face || ! weights ) {

			this.rig = null;
			this._mirrorOf = null;
			this.setActive( false );
			this._changed();
			return;

		}

		this.rig = {
			nJoints: weights.nJoints, nInfluences: weights.nInfluences,
			indices: weights.indices.slice(), weights: weights.weights.slice(),
			version: info.version, painted: info.painted_vertices,
		};
		const mirror = layout && layout.points.length === weights.nJoints ? layout.points.map( ( p ) => p.mirror ) : null;
		this._mirrorOf = mirror;
		this._plane = mirror ? symmetryPlane( this.picker, mirror ) : null;
		if ( this.joint >= weights.nJoints ) this.joint = 0;
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
		if ( ! this.active ) this._showRings( null );
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

	/**
	 * Change brush settings.
	 * @param {{brush?: string, radius?: number, strength?: number, value?: number, mirror?: boolean}} settings
	 */
	configure( { brush, radius, strength, value, mirror } ) {

		if ( brush !== undefined ) {

			if ( ! BRUSHES.includes( brush ) ) throw new RangeError( `WeightPainter.configure: brush must be one of ${ BRUSHES.join( ', ' ) }; got ${ brush }.` );
			this.brush = brush;

		}

		if ( radius !== undefined ) this.radius = positive( radius, 'radius' );
		if ( strength !== undefined ) this.strength = unit( strength, 'strength' );
		if ( value !== undefined ) this.value = unit( value, 'value' );
		if ( mirror !== undefined ) this.mirror = Boolean( mirror );
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

	get canUndo() {

		return this._undo.length > 0;

	}

	get canRedo() {

		return this._redo.length > 0;

	}

	/** Undo the last stroke or reset; false when there is none (or a stroke is under way). */
	undo() {

		const step = this._stroke ? null : this._undo.pop();
		if ( ! step ) return false;
		this._redo.push( step );
		this._apply( step.vertices, step.before );
		return true;

	}

	/** Redo the last undone stroke or reset; false when there is none. */
	redo() {

		const step = this._stroke ? null : this._redo.pop();
		if ( ! step ) return false;
		this._undo.push( step );
		this._apply( step.vertices, step.after );
		return true;

	}

	/**
	 * Paint joints back to the automatic rig on the server (null: the whole rig) and show
	 * the result; undoable. Unsaved strokes are saved first.
	 * @param {number[]|null} joints
	 */
	async reset( joints ) {

		const rig = this.rig, id = this.projectId;
		if ( ! rig ) return;
		await this.flush();
		if ( this._saves.pending ) throw new ApiError( 0, `Cannot reset before the painted weights are saved: ${ this.saveError }` );
		const info = await api.resetRigWeights( id, joints, rig.version );
		const fresh = await api.rigWeights( id );
		if ( rig !== this.rig ) return;
		const k = rig.nInfluences, changed = [];
		for ( let v = 0, n = fresh.weights.length / k; v < n; v ++ ) {

			for ( let s = v * k; s < v * k + k; s ++ ) {

				if ( fresh.indices[ s ] !== rig.indices[ s ] || fresh.weights[ s ] !== rig.weights[ s ] ) {

					changed.push( v );
					break;

				}

			}

		}

		rig.version = info.version;
		rig.painted = info.painted_vertices;
		if ( changed.length ) {

			const vertices = Int32Array.from( changed );
			const before = this._rows( vertices );
			const after = this._rows( vertices, fresh );
			this._undo.push( { vertices, before, after } );
			this._redo.length = 0;
			this._write( vertices, after );

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
		for ( const ring of this._rings ) {

			this.viewer.scene.remove( ring );
			ring.material.dispose();

		}

		this._rings[ 0 ].geometry.dispose();

	}

	// strokes

	_pointerDown( event ) {

		if ( ! this.active || ! this.face || event.button !== 0 || event.altKey || event.target !== this.viewer.renderer.domElement ) return;
		const hit = this.picker.hitFace( event );
		if ( ! hit ) return; // off the face: the camera orbits
		event.stopPropagation();
		event.preventDefault();
		if ( event.ctrlKey || event.metaKey ) {

			this.setJoint( this._nearestJoint( hit.local ) );
			return;

		}

		this._stroke = { pointerId: event.pointerId, last: hit.local.clone(), original: new Map(), alpha: new Map() };
		window.addEventListener( 'pointermove', this._onPointerMove );
		window.addEventListener( 'pointerup', this._onPointerUp );
		window.addEventListener( 'pointercancel', this._onPointerUp );
		this._dabs( hit.local, hit.faceIndex );
		this._showRings( hit );

	}

	_pointerMove( event ) {

		const stroke = this._stroke;
		if ( ! stroke || event.pointerId !== stroke.pointerId ) return;
		const hit = this.picker.hitFace( event );
		this._showRings( hit );
		if ( ! hit ) return;
		// dabs every SPACING radii from the last one, on the surface between it and the pointer
		const step = SPACING * this.radius;
		const distance = stroke.last.distanceTo( hit.local );
		if ( distance < step ) return;
		const bvh = this.face.mesh.geometry.boundsTree;
		const from = stroke.last.clone(), at = new THREE.Vector3();
		const n = Math.floor( distance / step );
		for ( let i = 1; i < n; i ++ ) {

			at.lerpVectors( from, hit.local, i / n );
			const near = bvh.closestPointToPoint( at );
			if ( near ) this._dabs( near.point, near.faceIndex );

		}

		this._dabs( hit.local, hit.faceIndex );
		stroke.last.copy( hit.local );

	}

	_pointerUp( event ) {

		const stroke = this._stroke;
		if ( ! stroke || event.pointerId !== stroke.pointerId ) return;
		this._endStroke();
		if ( ! stroke.original.size ) return;
		const vertices = Int32Array.from( stroke.original.keys() ).sort();
		const k = this.rig.nInfluences;
		const before = { indices: new Uint16Array( vertices.length * k ), weights: new Float32Array( vertices.length * k ) };
		vertices.forEach( ( v, n ) => {

			const row = stroke.original.get( v );
			before.indices.set( row.indices, n * k );
			before.weights.set( row.weights, n * k );

		} );
		this._undo.push( { vertices, before, after: this._rows( vertices ) } );
		this._redo.length = 0;
		this._saves.add( vertices );

	}

	_endStroke() {

		this._stroke = null;
		window.removeEventListener( 'pointermove', this._onPointerMove );
		window.removeEventListener( 'pointerup', this._onPointerUp );
		window.removeEventListener( 'pointercancel', this._onPointerUp );

	}

	/** One dab at `center` (mesh frame, on triangle `faceIndex`), and its mirror image. */
	_dabs( center, faceIndex ) {

		const changed = new Set();
		this._dab( center, faceIndex, this.joint, changed );
		const mirrorJoint = this.mirror && this._mirrorOf ? this._mirrorOf[ this.joint ] : - 1;
		if ( mirrorJoint >= 0 ) {

			const image = reflect( this._plane, center );
			const near = this.face.mesh.geometry.boundsTree.closestPointToPoint( image );
			if ( near ) this._dab( near.point, near.faceIndex, mirrorJoint, changed );

		}

		if ( changed.size ) this.face.updateWeights( Int32Array.from( changed ), this.rig.indices, this.rig.weights );

	}

	_dab( center, faceIndex, joint, changed ) {

		const stroke = this._stroke, rig = this.rig, k = rig.nInfluences, surface = this._surface();
		const { vertices, distances } = surface.within( this.face.mesh.geometry.attributes.position.array, center, faceIndex, this.radius );
		const r = this.radius;
		if ( this.brush === 'smooth' ) {

			const targets = vertices.map( ( v, n ) => {

				const a = jointWeight( rig.indices, rig.weights, v, k, joint );
				const mean = surface.mean( v, ( u ) => jointWeight( rig.indices, rig.weights, u, k, joint ) );
				return a + this.strength * falloff( distances[ n ] / r ) * ( mean - a );

			} );
			vertices.forEach( ( v, n ) => {

				this._remember( v );
				if ( setJointWeight( rig.indices, rig.weights, v, k, joint, targets[ n ] ) ) changed.add( v );

			} );
			return;

		}

		if ( ! stroke.alpha.has( joint ) ) stroke.alpha.set( joint, new Float32Array( this.face.nVertices ) );
		const alpha = stroke.alpha.get( joint );
		vertices.forEach( ( v, n ) => {

			const a = this.strength * falloff( distances[ n ] / r );
			if ( a <= alpha[ v ] ) return;
			alpha[ v ] = a;
			this._remember( v );
			// from the stroke's starting row: a vertex moves by at most the strength per stroke
			const original = stroke.original.get( v );
			rig.indices.set( original.indices, v * k );
			rig.weights.set( original.weights, v * k );
			for ( const [ j, reached ] of stroke.alpha ) {

				if ( reached[ v ] > 0 ) setJointWeight( rig.indices, rig.weights, v, k, j, this._target( jointWeight( rig.indices, rig.weights, v, k, j ), reached[ v ] ) );

			}

			changed.add( v );

		} );

	}

	/** The weight a brush of reach `alpha` (0..strength) paints over `a`. */
	_target( a, alpha ) {

		if ( this.brush === 'add' ) return Math.min( 1, a + alpha );
		if ( this.brush === 'subtract' ) return Math.max( 0, a - alpha );
		return a + alpha * ( this.value - a );

	}

	/** Keep vertex v's row as the stroke found it. */
	_remember( v ) {

		const original = this._stroke.original;
		if ( original.has( v ) ) return;
		const k = this.rig.nInfluences;
		original.set( v, { indices: this.rig.indices.slice( v * k, v * k + k ), weights: this.rig.weights.slice( v * k, v * k + k ) } );

	}

	/** The face's MeshNeighbours, built on first use. */
	_surface() {

		this._neighbours ??= new MeshNeighbours( this.face.mesh.geometry.index.array, this.face.nVertices );
		return this._neighbours;

	}

	_nearestJoint( point ) {

		let best = this.joint, bestD = Infinity;
		const p = new THREE.Vector3();
		for ( let j = 0; j < this.rig.nJoints; j ++ ) {

			if ( ! this.picker.position( j, p ) ) continue;
			const d = p.distanceToSquared( point );
			if ( d < bestD ) {

				bestD = d;
				best = j;

			}

		}

		return best;

	}

	// history and saving

	/** Rows (k slots each) of `vertices` from `source` (default: the painted rig). */
	_rows( vertices, source = this.rig ) {

		const k = this.rig.nInfluences;
		const rows = { indices: new Uint16Array( vertices.length * k ), weights: new Float32Array( vertices.length * k ) };
		vertices.forEach( ( v, n ) => {

			rows.indices.set( source.indices.subarray( v * k, v * k + k ), n * k );
			rows.weights.set( source.weights.subarray( v * k, v * k + k ), n * k );

		} );
		return rows;

	}

	/** Put rows into the rig and the face. */
	_write( vertices, rows ) {

		const k = this.rig.nInfluences;
		vertices.forEach( ( v, n ) => {

			this.rig.indices.set( rows.indices.subarray( n * k, n * k + k ), v * k );
			this.rig.weights.set( rows.weights.subarray( n * k, n * k + k ), v * k );

		} );
		this.face.updateWeights( vertices, this.rig.indices, this.rig.weights );

	}

	_apply( vertices, rows ) {

		this._write( vertices, rows );
		this._saves.add( vertices );

	}

	/** Save the rows of `vertices` (the save queue's `send`); the rig takes the new version. */
	async _send( vertices, { keepalive } ) {

		const rig = this.rig;
		const info = await api.patchRigWeights( this.projectId, rig, vertices, this._rows( vertices ), { keepalive } );
		if ( rig === this.rig ) {

			rig.version = info.version;
			rig.painted = info.painted_vertices;

		}

	}

	// the cursor

	_hover( event ) {

		if ( ! this.active || this._stroke || event.buttons ) return;
		this._hoverEvent = event;
		if ( this._hoverFrame ) return;
		// at most one ray cast per animation frame, on the latest pointer position
		this._hoverFrame = requestAnimationFrame( () => {

			this._hoverFrame = 0;
			if ( this.active && ! this._stroke ) this._showRings( this.picker.hitFace( this._hoverEvent ) );

		} );

	}

	/** Rings of the brush's radius on the surface at the hit and at its mirror image; null hides them. */
	_showRings( hit ) {

		const [ ring, image ] = this._rings;
		ring.visible = image.visible = false;
		if ( ! hit || ! this.face || ! this.active ) return;
		this._placeRing( ring, hit.local, hit.faceIndex );
		if ( this.mirror && this._mirrorOf ) {

			const near = this.face.mesh.geometry.boundsTree.closestPointToPoint( reflect( this._plane, hit.local ) );
			if ( near ) this._placeRing( image, near.point, near.faceIndex );

		}

	}

	_placeRing( ring, local, faceIndex ) {

		const mesh = this.face.mesh;
		mesh.updateWorldMatrix( true, false );
		const position = mesh.geometry.attributes.position, index = mesh.geometry.index;
		const [ a, b, c ] = [ 0, 1, 2 ].map( ( k ) => new THREE.Vector3().fromBufferAttribute( position, index.getX( 3 * faceIndex + k ) ) );
		const normal = new THREE.Triangle( a, b, c ).getNormal( new THREE.Vector3() ).transformDirection( mesh.matrixWorld );
		ring.position.copy( local ).applyMatrix4( mesh.matrixWorld );
		ring.quaternion.setFromUnitVectors( new THREE.Vector3( 0, 0, 1 ), normal );
		ring.scale.setScalar( this.radius * mesh.matrixWorld.getMaxScaleOnAxis() );
		ring.visible = true;

	}

	_changed() {

		this.dispatchEvent( new Event( 'change' ) );

	}

}

/** Brush falloff at x = distance / radius: 1 at the centre, 0 from the rim, smooth at both. */
function falloff( x ) {

	const t = 1 - x * x;
	return x >= 1 ? 0 : t * t;

}

function positive( x, name ) {

	if ( ! ( Number.isFinite( x ) && x > 0 ) ) throw new RangeError( `WeightPainter.configure: ${ name } must be a positive number; got ${ x }.` );
	return x;

}

function unit( x, name ) {

	if ( ! ( Number.isFinite( x ) && x >= 0 && x <= 1 ) ) throw new RangeError( `WeightPainter.configure: ${ name } must be in [0, 1]; got ${ x }.` );
	return x;

}
