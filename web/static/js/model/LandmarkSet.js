import { History } from './History.js';

/** More points than anyone places click by click (mediapipe468's 468): such a layout is found on the mesh. */
const MOST_PLACED_BY_HAND = 100;

/**
 * Whether a layout's points are placed by hand, one click each, as the guide and picker
 * ask; a denser layout's are found on the mesh (*Find points*) and only corrected by hand.
 * @param {{n_points: number}|null} layout
 * @returns {boolean}
 */
export function placedByHand( layout ) {

	return ! layout || layout.n_points <= MOST_PLACED_BY_HAND;

}

/**
 * @typedef {{triangle: number[], barycentric: number[]}} SurfacePoint
 *   A point on the mesh: the triangle's three vertex indices and the point's barycentric
 *   weights of them (summing to 1), the server's landmark form.
 * @typedef {{layout: string, points: Array<SurfacePoint|null>}} PickState
 *   One entry per layout point, null while unplaced. States are never mutated, so undo
 *   and redo keep them by reference.
 * @typedef {{name: string, n_points: number, regions: string[],
 *   points: Array<{name: string, region: string, side: string, mirror: number}>}} Layout
 *   A layout as GET /api/layouts gives it.
 * @typedef {{state: PickState, confidence: number[], checkBelow: number}} Found
 *   Points the server found with no clicks and how much to trust each (0..1); a point
 *   under `checkBelow` asks to be checked.
 */

/**
 * The feature points being placed on a face: one surface point (or none yet) per point
 * of a layout, which one is selected, which comes next, the last saved state, and undo
 * and redo of every edit. It knows nothing of the mesh's geometry: the picker (or a
 * restored draft) hands it surface points. Points found by the server come with their
 * confidence: those under its threshold are `flagged` for checking until they are moved
 * (or saved by the user).
 *
 * Dispatches 'change' after any edit, selection, load or save.
 */
export class LandmarkSet extends EventTarget {

	constructor() {

		super();
		/** @type {Map<string, Layout>} */
		this.layouts = new Map();
		/** @type {PickState} */
		this.state = { layout: '', points: [] };
		/** The selected point, -1 for none. */
		this.selected = - 1;

		this._saved = this.state;
		/** @type {Found|null} */
		this._found = null;
		this._flags = { state: null, found: null, flagged: [] }; // `flagged` of the last state asked about
		/** @type {History<{before: PickState, after: PickState}>} */
		this._history = new History();
		this._chosenNext = - 1;
		this._cursor = 0; // where the search for the next unplaced point starts

	}

	/** @param {Layout[]} layouts */
	setLayouts( layouts ) {

		this.layouts = new Map( layouts.map( ( layout ) => [ layout.name, layout ] ) );

	}

	/** The current layout object, or null. */
	get layout() {

		return this.layouts.get( this.state.layout ) || null;

	}

	/** @returns {Array<SurfacePoint|null>} one per layout point. */
	get points() {

		return this.state.points;

	}

	/**
	 * Start over with a layout and its points (from the server), forgetting the history.
	 * @param {string} layoutName
	 * @param {{triangles: number[][], barycentric: number[][]}|{vertex_indices: number[]}|null} landmarks -
	 *   the server's landmark JSON (points on vertices come as vertex indices; found
	 *   points with their `confidence` and `check_below`).
	 */
	load( layoutName, landmarks = null ) {

		const layout = this._layoutNamed( layoutName );
		let points = new Array( layout.n_points ).fill( null );
		if ( landmarks ) {

			points = surfacePoints( landmarks );
			if ( points.length !== layout.n_points ) {

				throw new Error( `LandmarkSet: layout "${ layoutName }" has ${ layout.n_points } points, the landmarks ${ points.length }.` );

			}

		}

		this.state = { layout: layoutName, points };
		this._saved = landmarks ? this.state : { layout: layoutName, points: new Array( layout.n_points ).fill( null ) };
		this._found = landmarks ? foundOf( this.state, landmarks ) : null;
		this._history.clear();
		this.selected = - 1;
		this._resetCursor();
		this._changed();

	}

	/**
	 * Remember points as saved (the 'unsaved' mark clears until the next edit).
	 * @param {PickState} [state] - what was sent, when edits may have followed it.
	 * @param {object|null} [landmarks] - the server's landmark JSON of `state` when it
	 *   was found with no clicks (its confidence flags points); null: saved by the user,
	 *   who has seen them all.
	 */
	markSaved( state = this.state, landmarks = null ) {

		this._saved = state;
		this._found = landmarks ? foundOf( state, landmarks ) : null;
		this._changed();

	}

	/**
	 * Per point, whether it was found with a confidence under the threshold and has not
	 * been moved since: the points to check.
	 * @returns {boolean[]} one per layout point.
	 */
	get flagged() {

		const found = this._found, state = this.state, flags = this._flags;
		if ( flags.state === state && flags.found === found ) return flags.flagged; // markers ask on every stream frame
		const matches = found && found.state.layout === state.layout;
		flags.flagged = state.points.map( ( p, i ) => Boolean( matches && p !== null && found.confidence[ i ] < found.checkBelow && samePoint( p, found.state.points[ i ] ) ) );
		flags.state = state;
		flags.found = found;
		return flags.flagged;

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

	/** Whether some placed point's mirror partner is unplaced (Mirror has work). */
	get canMirror() {

		const layout = this.layout, points = this.state.points;
		return !! layout && layout.points.some( ( p, i ) => points[ i ] && p.mirror !== i && ! points[ p.mirror ] );

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

	// edits (each one undoable)

	/**
	 * Switch layout. Points whose names exist in the new layout carry over; the others
	 * are dropped (undo brings them back).
	 * @param {string} layoutName
	 * @returns {number} how many placed points were dropped.
	 */
	setLayout( layoutName ) {

		const layout = this._layoutNamed( layoutName );
		if ( layoutName === this.state.layout ) return 0;
		const byName = new Map();
		const old = this.layout;
		if ( old ) old.points.forEach( ( p, i ) => this.state.points[ i ] && byName.set( p.name, this.state.points[ i ] ) );
		const points = layout.points.map( ( p ) => byName.get( p.name ) || null );
		const kept = points.filter( Boolean ).length;
		this.selected = - 1;
		this._resetCursor();
		this.commit( { layout: layoutName, points } );
		return byName.size - kept;

	}

	/**
	 * Replace the layout and all points at once (a restored draft).
	 * @param {string} layoutName
	 * @param {Array<SurfacePoint|null>} points - one per layout point.
	 */
	replace( layoutName, points ) {

		const layout = this.layouts.get( layoutName );
		if ( ! layout || points.length !== layout.n_points ) throw new Error( `LandmarkSet: ${ points.length } points do not fit layout "${ layoutName }".` );
		this.selected = - 1;
		this._resetCursor();
		this.commit( { layout: layoutName, points: points.slice() } );

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
		this.commit( this._with( index, point ) );

	}

	/** Delete the selected point; false when none is selected. */
	deleteSelected() {

		const index = this.selected;
		if ( index < 0 || ! this.state.points[ index ] ) return false;
		this.selected = - 1;
		this._chosenNext = index;
		this.commit( this._with( index, null ) );
		return true;

	}

	/** Remove every point; false when none was placed. */
	clear() {

		if ( this.placedCount === 0 ) return false;
		this.selected = - 1;
		this._resetCursor();
		this.commit( { layout: this.state.layout, points: this.state.points.map( () => null ) } );
		return true;

	}

	/**
	 * Make `state` the current one as one undo step.
	 * @param {PickState} state
	 * @param {PickState} [before] - the state the step undoes to (a drag's start; default:
	 *   the current one).
	 */
	commit( state, before = this.state ) {

		this._history.push( { before, after: state } );
		this.state = state;
		this._changed();

	}

	/**
	 * Move point `index` without an undo step (a drag in progress: `commit` its end).
	 * @param {number} index
	 * @param {SurfacePoint} point
	 */
	slide( index, point ) {

		this.state = this._with( index, point );
		this._changed();

	}

	/** Whether there is an edit to undo. */
	get canUndo() {

		return this._history.canUndo;

	}

	/** Whether there is an undone edit to redo. */
	get canRedo() {

		return this._history.canRedo;

	}

	/** Take back the last edit; false when there is none. */
	undo() {

		const step = this._history.undo();
		if ( step ) this._restore( step.before );
		return step !== null;

	}

	/** Make the last undone edit again; false when there is none. */
	redo() {

		const step = this._history.redo();
		if ( step ) this._restore( step.after );
		return step !== null;

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

	_layoutNamed( name ) {

		const layout = this.layouts.get( name );
		if ( ! layout ) throw new Error( `LandmarkSet: unknown layout "${ name }".` );
		return layout;

	}

	_resetCursor() {

		this._chosenNext = - 1;
		this._cursor = 0;

	}

	_with( index, point ) {

		const points = this.state.points.slice();
		points[ index ] = point;
		return { layout: this.state.layout, points };

	}

	_restore( state ) {

		this.state = state;
		if ( this.selected >= state.points.length || ( this.selected >= 0 && ! state.points[ this.selected ] ) ) this.selected = - 1;
		if ( this._chosenNext >= state.points.length ) this._chosenNext = - 1;
		this._changed();

	}

	_changed() {

		this.dispatchEvent( new Event( 'change' ) );

	}

}

/**
 * The found points of a state, when the server's JSON of it has a confidence per point.
 * @param {PickState} state
 * @param {{confidence?: number[], check_below?: number}} landmarks
 * @returns {Found|null}
 */
function foundOf( state, landmarks ) {

	const confidence = landmarks.confidence;
	if ( ! Array.isArray( confidence ) || confidence.length !== state.points.length || typeof landmarks.check_below !== 'number' ) return null;
	return { state, confidence: confidence.slice(), checkBelow: landmarks.check_below };

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

function samePoint( p, q ) {

	if ( p === q ) return true;
	if ( ! p || ! q ) return false;
	return p.triangle.every( ( v, k ) => v === q.triangle[ k ] ) && p.barycentric.every( ( v, k ) => v === q.barycentric[ k ] );

}

function sameState( s, t ) {

	return s.layout === t.layout && s.points.length === t.points.length && s.points.every( ( p, i ) => samePoint( p, t.points[ i ] ) );

}
