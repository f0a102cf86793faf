import * as THREE from 'three';
import { acceleratedRaycast, computeBoundsTree, disposeBoundsTree } from 'three-mesh-bvh';

import { regionColor } from './scene/palette.js';

// three-mesh-bvh's README patch: a mesh whose geometry has a boundsTree raycasts through
// it (milliseconds on 100k+ triangles instead of a scan of every triangle).
THREE.BufferGeometry.prototype.computeBoundsTree = computeBoundsTree;
THREE.BufferGeometry.prototype.disposeBoundsTree = disposeBoundsTree;
THREE.Mesh.prototype.raycast = acceleratedRaycast;

const CLICK_SLOP = 5; // CSS px a click may move and still place a point (more is an orbit)
const GRAB_SLOP = 1.5; // CSS px beyond a marker's drawn radius that still grab it (close neighbours stay clickable)
const SNAP_PX = 3; // CSS px: a click this close to the surface still lands on it
const MARKER_SCALE = 0.0085; // marker radius as a fraction of the mesh's bounding-sphere radius

/**
 * @typedef {{triangle: number[], barycentric: number[]}} SurfacePoint
 *   A point on the mesh: the triangle's three vertex indices and the point's barycentric
 *   weights of them (summing to 1), the server's landmark form.
 * @typedef {{layout: string, points: Array<SurfacePoint|null>}} PickState
 *   One entry per layout point, null while unplaced. States are never mutated, so undo
 *   and redo keep them by reference.
 */

/**
 * Landmark picking on a face mesh: click to place the layout's next point, drag a marker
 * to slide it over the surface, select (Shift+click, or a click once all are placed) and
 * delete, mirror left/right partners, undo and redo every edit. Picking raycasts the rest
 * pose through a three-mesh-bvh bounds tree.
 *
 * Dispatches 'change' after any edit, selection or layout change, and 'hover' (detail:
 * {index}, -1 for none) as the pointer moves over markers.
 */
export class LandmarkPicker extends EventTarget {

	/**
	 * @param {import('./scene/Viewer.js').Viewer} viewer
	 */
	constructor( viewer ) {

		super();
		this.viewer = viewer;
		this.layouts = new Map();
		this.mesh = null;
		/** @type {PickState} */
		this.state = { layout: '', points: [] };
		this.selected = - 1;
		this.hovered = - 1;

		this._saved = this.state;
		this._undo = [];
		this._redo = [];
		this._chosenNext = - 1;
		this._cursor = 0; // where the search for the next unplaced point starts
		this._offsets = null;
		this._gesture = null;
		this._hoverFrame = 0;
		this._hoverEvent = null;
		this._raycaster = new THREE.Raycaster();
		this._raycaster.firstHitOnly = true;

		this.markers = new THREE.Group();
		this.markers.name = 'landmarks';
		this.markers.matrixAutoUpdate = false; // follows the mesh's world matrix
		this._sphere = new THREE.SphereGeometry( 1, 16, 12 );
		this._materials = new Map();
		this._selectedMaterial = new THREE.MeshStandardMaterial( { color: 0xffffff, emissive: 0x666666, roughness: 0.35 } );

		this._onPointerDown = this._pointerDown.bind( this );
		this._onPointerMove = this._pointerMove.bind( this );
		this._onPointerUp = this._pointerUp.bind( this );
		this._onHover = this._hover.bind( this );
		const element = viewer.renderer.domElement;
		// capture on the container runs before OrbitControls' own pointerdown on the canvas,
		// so grabbing a marker can switch the controls off before they start an orbit
		element.parentElement.addEventListener( 'pointerdown', this._onPointerDown, { capture: true } );
		element.addEventListener( 'pointermove', this._onHover );

	}

	/**
	 * @param {Array<{name: string, n_points: number, points: Array<{name: string, region: string, side: string, mirror: number}>}>} layouts
	 */
	setLayouts( layouts ) {

		this.layouts = new Map( layouts.map( ( layout ) => [ layout.name, layout ] ) );

	}

	/** The current layout object, or null. */
	get layout() {

		return this.layouts.get( this.state.layout ) || null;

	}

	get points() {

		return this.state.points;

	}

	/**
	 * Pick on this mesh (its geometry's rest positions); null detaches the picker.
	 * @param {THREE.Mesh|null} mesh
	 */
	setMesh( mesh ) {

		if ( this.mesh ) {

			this.viewer.scene.remove( this.markers );
			this.mesh.geometry.disposeBoundsTree();

		}

		this.mesh = mesh;
		if ( mesh ) {

			// indirect: the bounds tree must not reorder the index buffer that SkinnedFace renders
			mesh.geometry.computeBoundsTree( { indirect: true } );
			if ( ! mesh.geometry.boundingSphere ) mesh.geometry.computeBoundingSphere();
			if ( ! mesh.geometry.boundingBox ) mesh.geometry.computeBoundingBox();
			// beside the mesh, not in it: the viewer's wireframe and framing apply to the face alone
			this.viewer.scene.add( this.markers );

		}

		this._updateMarkers();

	}

	/**
	 * Start over with a layout and its points (from the server), forgetting the history.
	 * @param {string} layoutName
	 * @param {{triangles: number[][], barycentric: number[][]}|{vertex_indices: number[]}|null} landmarks -
	 *   the server's landmark JSON (points on vertices come as vertex indices).
	 */
	load( layoutName, landmarks = null ) {

		const layout = this.layouts.get( layoutName );
		if ( ! layout ) throw new Error( `LandmarkPicker: unknown layout "${ layoutName }".` );
		let points = new Array( layout.n_points ).fill( null );
		if ( landmarks ) {

			points = surfacePoints( landmarks );
			if ( points.length !== layout.n_points ) {

				throw new Error( `LandmarkPicker: layout "${ layoutName }" has ${ layout.n_points } points, the landmarks ${ points.length }.` );

			}

		}

		this.state = { layout: layoutName, points };
		this._saved = landmarks ? this.state : { layout: layoutName, points: new Array( layout.n_points ).fill( null ) };
		this._undo = [];
		this._redo = [];
		this.selected = - 1;
		this._chosenNext = - 1;
		this._cursor = 0;
		this._changed();

	}

	/**
	 * Remember points as saved (the 'unsaved' mark clears until the next edit).
	 * @param {PickState} [state] - what was sent, when edits may have followed it.
	 */
	markSaved( state = this.state ) {

		this._saved = state;
		this._changed();

	}

	/** True when the points differ from the last loaded or saved ones. */
	get dirty() {

		return ! sameState( this.state, this._saved );

	}

	/** Number of placed points. */
	get placedCount() {

		return this.state.points.reduce( ( n, p ) => n + ( p ? 1 : 0 ), 0 );

	}

	/** Index of the point the next click places, -1 when all are placed. */
	get next() {

		const points = this.state.points;
		if ( this._chosenNext >= 0 && ! points[ this._chosenNext ] ) return this._chosenNext;
		for ( let k = 0; k < points.length; k ++ ) {

			const i = ( this._cursor + k ) % points.length;
			if ( ! points[ i ] ) return i;

		}

		return - 1;

	}

	/** Names of the unplaced points, in layout order. */
	missing() {

		const layout = this.layout;
		return layout ? layout.points.filter( ( _, i ) => ! this.state.points[ i ] ).map( ( p ) => p.name ) : [];

	}

	/**
	 * The server's landmark JSON; throws naming the unplaced points when some are.
	 * @returns {{layout: string, triangles: number[][], barycentric: number[][]}}
	 */
	toJSON() {

		const missing = this.missing();
		if ( missing.length ) throw new Error( `${ missing.length } point${ missing.length > 1 ? 's are' : ' is' } not placed yet: ${ missing.join( ', ' ) }` );
		return {
			layout: this.state.layout,
			triangles: this.state.points.map( ( p ) => p.triangle ),
			barycentric: this.state.points.map( ( p ) => p.barycentric ),
		};

	}

	/**
	 * The rest-pose position of a placed point in the mesh's local frame.
	 * @param {number} index
	 * @param {THREE.Vector3} [target]
	 * @returns {THREE.Vector3|null} null when unplaced.
	 */
	position( index, target = new THREE.Vector3() ) {

		const point = this.state.points[ index ];
		return point ? this._surfacePosition( point, target ) : null;

	}

	/**
	 * The world position of a placed marker as drawn (live offsets included): what
	 * `viewer.project` needs to find it on screen.
	 * @param {number} index
	 * @returns {number[]|null} [x, y, z]
	 */
	worldPosition( index ) {

		const marker = this.markers.children[ index ];
		if ( ! marker || ! marker.visible ) return null;
		return marker.getWorldPosition( new THREE.Vector3() ).toArray();

	}

	/**
	 * The point of the face's rest pose under the pointer (what a click there places, or
	 * where a brush paints). A pointer just off the surface (on an eyelid's or the mouth's
	 * edge, at the silhouette) snaps to the front-most hit on the nearest ring of rays
	 * within SNAP_PX, so points on a hole's rim are as easy to reach as any other.
	 * @param {{clientX: number, clientY: number}} event - a pointer position, CSS px.
	 * @returns {{faceIndex: number, local: THREE.Vector3, distance: number}|null} the
	 *   triangle hit, the point in the mesh's local frame and its distance from the camera
	 *   (world units); null off the face or without a mesh.
	 */
	hitFace( event ) {

		if ( ! this.mesh ) return null;
		for ( let r = 0; r <= SNAP_PX; r ++ ) {

			const rays = r === 0 ? 1 : 8 * r;
			let best = null;
			for ( let k = 0; k < rays; k ++ ) {

				const angle = ( 2 * Math.PI * k ) / rays;
				const hit = this._ray( event.clientX + r * Math.cos( angle ), event.clientY + r * Math.sin( angle ) ).intersectObject( this.mesh, false )[ 0 ];
				if ( hit && ( ! best || hit.distance < best.distance ) ) best = hit;

			}

			if ( best ) return { faceIndex: best.faceIndex, local: this.mesh.worldToLocal( best.point.clone() ), distance: best.distance };

		}

		return null;

	}

	// edits (each one undoable)

	/**
	 * Switch layout. Points whose names exist in the new layout carry over; the others
	 * are dropped (undo brings them back).
	 * @param {string} layoutName
	 * @returns {number} how many placed points were dropped.
	 */
	setLayout( layoutName ) {

		const layout = this.layouts.get( layoutName );
		if ( ! layout ) throw new Error( `LandmarkPicker: unknown layout "${ layoutName }".` );
		if ( layoutName === this.state.layout ) return 0;
		const byName = new Map();
		const old = this.layout;
		if ( old ) old.points.forEach( ( p, i ) => this.state.points[ i ] && byName.set( p.name, this.state.points[ i ] ) );
		const points = layout.points.map( ( p ) => byName.get( p.name ) || null );
		const kept = points.filter( Boolean ).length;
		this.selected = - 1;
		this._chosenNext = - 1;
		this._cursor = 0;
		this._commit( { layout: layoutName, points } );
		return byName.size - kept;

	}

	/**
	 * How many placed points `setLayout( layoutName )` would drop.
	 * @param {string} layoutName
	 * @returns {number}
	 */
	droppedBy( layoutName ) {

		const layout = this.layouts.get( layoutName ), old = this.layout;
		if ( ! layout || ! old ) return 0;
		const names = new Set( layout.points.map( ( p ) => p.name ) );
		return old.points.filter( ( p, i ) => this.state.points[ i ] && ! names.has( p.name ) ).length;

	}

	/**
	 * Replace the layout and all points at once (a restored draft).
	 * @param {string} layoutName
	 * @param {Array<SurfacePoint|null>} points - one per layout point.
	 */
	replace( layoutName, points ) {

		const layout = this.layouts.get( layoutName );
		if ( ! layout || points.length !== layout.n_points ) throw new Error( `LandmarkPicker: ${ points.length } points do not fit layout "${ layoutName }".` );
		this.selected = - 1;
		this._chosenNext = - 1;
		this._cursor = 0;
		this._commit( { layout: layoutName, points: points.slice() } );

	}

	/**
	 * Place (or move) point `index` at a surface point and select it.
	 * @param {number} index
	 * @param {SurfacePoint} point
	 */
	place( index, point ) {

		this.selected = index;
		this._cursor = index + 1;
		if ( this._chosenNext === index ) this._chosenNext = - 1;
		this._commit( this._with( index, point ) );

	}

	/** Delete the selected point; false when none is selected. */
	deleteSelected() {

		const index = this.selected;
		if ( index < 0 || ! this.state.points[ index ] ) return false;
		this.selected = - 1;
		this._chosenNext = index;
		this._commit( this._with( index, null ) );
		return true;

	}

	/** Remove every point; false when none was placed. */
	clear() {

		if ( this.placedCount === 0 ) return false;
		this.selected = - 1;
		this._chosenNext = - 1;
		this._cursor = 0;
		this._commit( { layout: this.state.layout, points: this.state.points.map( () => null ) } );
		return true;

	}

	/**
	 * Place every unplaced mirror partner of a placed point at its mirror image across
	 * the face's symmetry plane x = cx, snapped to the closest surface point.
	 * @returns {number} how many points were placed.
	 */
	mirror() {

		const layout = this.layout;
		if ( ! layout || ! this.mesh ) return 0;
		const cx = this.symmetryX();
		const bvh = this.mesh.geometry.boundsTree;
		const points = this.state.points.slice();
		const p = new THREE.Vector3();
		let placed = 0;
		layout.points.forEach( ( info, i ) => {

			const j = info.mirror;
			if ( j === i || j < 0 || ! this.state.points[ i ] || points[ j ] ) return;
			this._surfacePosition( this.state.points[ i ], p );
			p.x = 2 * cx - p.x;
			const hit = bvh.closestPointToPoint( p );
			if ( ! hit ) return;
			points[ j ] = this._surfacePoint( hit.faceIndex, hit.point );
			placed ++;

		} );
		if ( placed ) this._commit( { layout: this.state.layout, points } );
		return placed;

	}

	/**
	 * The x of the face's left/right symmetry plane in the mesh's frame: the median of the
	 * placed midline points and of the midpoints of placed mirror pairs, else the centre
	 * of the mesh's bounding box.
	 * @returns {number}
	 */
	symmetryX() {

		const layout = this.layout;
		const xs = [];
		const a = new THREE.Vector3(), b = new THREE.Vector3();
		if ( layout ) {

			layout.points.forEach( ( info, i ) => {

				if ( ! this.position( i, a ) ) return;
				if ( info.mirror === i ) xs.push( a.x );
				else if ( info.mirror > i && this.position( info.mirror, b ) ) xs.push( ( a.x + b.x ) / 2 );

			} );

		}

		if ( xs.length ) {

			xs.sort( ( u, v ) => u - v );
			const m = xs.length >> 1;
			return xs.length % 2 ? xs[ m ] : ( xs[ m - 1 ] + xs[ m ] ) / 2;

		}

		const box = this.mesh.geometry.boundingBox;
		return ( box.min.x + box.max.x ) / 2;

	}

	get canUndo() {

		return this._undo.length > 0;

	}

	get canRedo() {

		return this._redo.length > 0;

	}

	undo() {

		if ( ! this._undo.length ) return false;
		this._redo.push( this.state );
		this._restore( this._undo.pop() );
		return true;

	}

	redo() {

		if ( ! this._redo.length ) return false;
		this._undo.push( this.state );
		this._restore( this._redo.pop() );
		return true;

	}

	/**
	 * Select a placed point, or make an unplaced one the next to place.
	 * @param {number} index - -1 deselects.
	 */
	select( index ) {

		if ( index >= 0 && ! this.state.points[ index ] ) {

			this._chosenNext = index;
			this.selected = - 1;

		} else {

			this.selected = index;

		}

		this._changed();

	}

	/**
	 * Move the markers with the live feature displacements (a feature point is a joint,
	 * so it moves by exactly its displacement); null puts them back at rest.
	 * @param {Float32Array|null} displacements - (3N) point-major x, y, z in mesh units.
	 */
	setDisplacements( displacements ) {

		this._offsets = displacements && displacements.length === 3 * this.state.points.length ? displacements : null;
		this._updateMarkers();

	}

	dispose() {

		const element = this.viewer.renderer.domElement;
		element.parentElement.removeEventListener( 'pointerdown', this._onPointerDown, { capture: true } );
		element.removeEventListener( 'pointermove', this._onHover );
		this._endGesture();
		cancelAnimationFrame( this._hoverFrame );
		this.setMesh( null );
		this._sphere.dispose();
		this._selectedMaterial.dispose();
		for ( const material of this._materials.values() ) material.dispose();

	}

	// internals

	_with( index, point ) {

		const points = this.state.points.slice();
		points[ index ] = point;
		return { layout: this.state.layout, points };

	}

	_commit( state ) {

		this._undo.push( this.state );
		this._redo.length = 0;
		this.state = state;
		this._changed();

	}

	_restore( state ) {

		this.state = state;
		if ( this.selected >= state.points.length || ( this.selected >= 0 && ! state.points[ this.selected ] ) ) this.selected = - 1;
		if ( this._chosenNext >= state.points.length ) this._chosenNext = - 1;
		this._changed();

	}

	_changed() {

		this._updateMarkers(); // drawn by the viewer's next frame
		this.dispatchEvent( new Event( 'change' ) );

	}

	_surfacePosition( point, target ) {

		const position = this.mesh.geometry.attributes.position;
		const [ a, b, c ] = point.triangle, [ u, v, w ] = point.barycentric;
		return target.set(
			u * position.getX( a ) + v * position.getX( b ) + w * position.getX( c ),
			u * position.getY( a ) + v * position.getY( b ) + w * position.getY( c ),
			u * position.getZ( a ) + v * position.getZ( b ) + w * position.getZ( c ),
		);

	}

	/**
	 * @param {number} faceIndex - triangle index in the geometry's index.
	 * @param {THREE.Vector3} local - a point on that triangle, mesh frame.
	 * @returns {SurfacePoint}
	 */
	_surfacePoint( faceIndex, local ) {

		const geometry = this.mesh.geometry;
		const index = geometry.index, position = geometry.attributes.position;
		const triangle = [ 0, 1, 2 ].map( ( k ) => ( index ? index.getX( 3 * faceIndex + k ) : 3 * faceIndex + k ) );
		const [ a, b, c ] = triangle.map( ( i ) => new THREE.Vector3().fromBufferAttribute( position, i ) );
		const bary = THREE.Triangle.getBarycoord( local, a, b, c, new THREE.Vector3() ) || new THREE.Vector3( 1, 0, 0 );
		return { triangle, barycentric: normalisedWeights( bary.toArray() ) };

	}

	_materialFor( region ) {

		let material = this._materials.get( region );
		if ( ! material ) {

			const color = new THREE.Color( regionColor( region ) );
			material = new THREE.MeshStandardMaterial( { color, emissive: color.clone().multiplyScalar( 0.35 ), roughness: 0.45 } );
			this._materials.set( region, material );

		}

		return material;

	}

	_updateMarkers() {

		const group = this.markers;
		const layout = this.layout;
		const points = this.state.points;
		while ( group.children.length < points.length ) group.add( new THREE.Mesh( this._sphere ) );
		while ( group.children.length > points.length ) group.remove( group.children[ group.children.length - 1 ] );
		if ( ! this.mesh || ! layout ) {

			group.visible = false;
			return;

		}

		group.visible = true;
		this.mesh.updateWorldMatrix( true, false );
		group.matrix.copy( this.mesh.matrixWorld );
		const radius = this.mesh.geometry.boundingSphere.radius * MARKER_SCALE;
		const offsets = this._offsets;
		points.forEach( ( point, i ) => {

			const marker = group.children[ i ];
			marker.visible = point !== null;
			if ( ! point ) return;
			this._surfacePosition( point, marker.position );
			if ( offsets ) marker.position.x += offsets[ 3 * i ], marker.position.y += offsets[ 3 * i + 1 ], marker.position.z += offsets[ 3 * i + 2 ];
			marker.material = i === this.selected ? this._selectedMaterial : this._materialFor( layout.points[ i ].region );
			marker.scale.setScalar( radius * ( i === this.selected ? 1.45 : i === this.hovered ? 1.25 : 1 ) );
			marker.renderOrder = 1;

		} );

	}

	/** The raycaster set to the ray through page point (x, y), CSS px. */
	_ray( x, y ) {

		const rect = this.viewer.renderer.domElement.getBoundingClientRect();
		const ndc = new THREE.Vector2( ( ( x - rect.left ) / rect.width ) * 2 - 1, - ( ( y - rect.top ) / rect.height ) * 2 + 1 );
		this._raycaster.setFromCamera( ndc, this.viewer.camera );
		return this._raycaster;

	}

	/**
	 * The visible marker nearest the pointer within its drawn radius (plus GRAB_SLOP px),
	 * -1 for none. A marker behind the surface under the pointer does not count.
	 */
	_markerAt( event ) {

		if ( ! this.mesh || ! this.markers.visible ) return - 1;
		const rect = this.viewer.renderer.domElement.getBoundingClientRect();
		const camera = this.viewer.camera;
		const world = new THREE.Vector3(), edge = new THREE.Vector3(), right = new THREE.Vector3().setFromMatrixColumn( camera.matrixWorld, 0 );
		let best = - 1, bestD = Infinity;
		this.markers.children.forEach( ( marker, i ) => {

			if ( ! marker.visible ) return;
			marker.getWorldPosition( world );
			const radius = marker.scale.x * this.mesh.matrixWorld.getMaxScaleOnAxis();
			edge.copy( world ).addScaledVector( right, radius ).project( camera );
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

		const hit = this.hitFace( event );
		if ( hit ) {

			const marker = this.markers.children[ best ];
			const distance = marker.getWorldPosition( world ).distanceTo( this._raycaster.ray.origin );
			if ( hit.distance < distance - 3 * marker.scale.x * this.mesh.matrixWorld.getMaxScaleOnAxis() ) return - 1;

		}

		return best;

	}

	_pointerDown( event ) {

		if ( event.button !== 0 || ! this.mesh || ! this.layout || event.target !== this.viewer.renderer.domElement ) return;
		const marker = this._markerAt( event );
		this._gesture = { x: event.clientX, y: event.clientY, marker, moved: false, before: this.state,
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
			if ( gesture.marker >= 0 ) this.selected = gesture.marker;

		}

		if ( gesture.marker < 0 || ! gesture.moved ) return;
		const hit = this.hitFace( event );
		if ( ! hit ) return;
		// slide without a history entry per move: the whole drag is one undo step (on release)
		const points = this.state.points.slice();
		points[ gesture.marker ] = this._surfacePoint( hit.faceIndex, hit.local );
		this.state = { layout: this.state.layout, points };
		this._changed();

	}

	_pointerUp( event ) {

		const gesture = this._gesture;
		if ( ! gesture || event.pointerId !== gesture.pointerId ) return;
		this._endGesture();
		if ( event.type === 'pointercancel' ) return;
		if ( gesture.moved ) {

			// a marker drag is one undo step; any other drag was an orbit
			if ( gesture.marker >= 0 && this.state !== gesture.before ) {

				this._undo.push( gesture.before );
				this._redo.length = 0;
				this._changed();

			}

			return;

		}

		// a click places the next point, even on a marker: on a closed mouth the lower inner
		// lip's points lie on the upper's. With nothing left to place, or with Shift, a
		// click on a marker selects it.
		const next = this.next;
		if ( gesture.marker >= 0 && ( next < 0 || event.shiftKey ) ) {

			this.select( gesture.marker );
			return;

		}

		const hit = this.hitFace( event );
		if ( next >= 0 && hit ) this.place( next, this._surfacePoint( hit.faceIndex, hit.local ) );
		else if ( this.selected >= 0 ) this.select( - 1 );

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
			element.style.cursor = marker >= 0 ? 'grab' : ( this.layout && this.next >= 0 && this.hitFace( e ) ? 'crosshair' : '' );
			if ( marker !== this.hovered ) {

				this.hovered = marker;
				this._updateMarkers();
				this.dispatchEvent( new CustomEvent( 'hover', { detail: { index: marker } } ) );

			}

		} );

	}

}

/**
 * Surface points of the server's landmark JSON.
 * @param {{triangles: number[][], barycentric: number[][]}|{vertex_indices: number[]}} landmarks
 * @returns {SurfacePoint[]}
 */
export function surfacePoints( landmarks ) {

	if ( landmarks.vertex_indices ) return landmarks.vertex_indices.map( ( i ) => ( { triangle: [ i, i, i ], barycentric: [ 1, 0, 0 ] } ) );
	return landmarks.triangles.map( ( triangle, i ) => ( { triangle: triangle.slice(), barycentric: landmarks.barycentric[ i ].slice() } ) );

}

/** Barycentric weights clamped to [0, 1] and renormalised (a hit on an edge may come out a hair negative). */
function normalisedWeights( w ) {

	const clamped = w.map( ( x ) => Math.min( 1, Math.max( 0, x ) ) );
	const sum = clamped[ 0 ] + clamped[ 1 ] + clamped[ 2 ];
	return sum > 0 ? clamped.map( ( x ) => x / sum ) : [ 1, 0, 0 ];

}

function samePoint( p, q ) {

	if ( p === q ) return true;
	if ( ! p || ! q ) return false;
	return p.triangle.every( ( v, k ) => v === q.triangle[ k ] ) && p.barycentric.every( ( v, k ) => v === q.barycentric[ k ] );

}

function sameState( s, t ) {

	return s.layout === t.layout && s.points.length === t.points.length && s.points.every( ( p, i ) => samePoint( p, t.points[ i ] ) );

}
