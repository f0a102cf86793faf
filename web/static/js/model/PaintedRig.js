import { History } from './History.js';

/**
 * @typedef {{indices: Uint16Array, weights: Float32Array}} Rows
 *   Rows of skin weights, k slots each, row-major: joint indices and their weights.
 * @typedef {{vertices: Int32Array, before: Rows, after: Rows}} PaintStep
 *   One undo step: the rows of `vertices` before and after a stroke or reset.
 */

/**
 * The rig being painted: a copy of the server's skin weights (GET .../rig/weights) that
 * strokes change in place, with the rig version the server knows them by, how many
 * vertices differ from the automatic rig, and the undo history of strokes and resets.
 * Vertex v's influences are slots v*k .. v*k+k-1 (weightRows.js's form).
 */
export class PaintedRig {

	/**
	 * @param {{nJoints: number, nInfluences: number, indices: Uint16Array, weights: Float32Array}} weights -
	 *   `api.rigWeights`; copied.
	 * @param {{version: number, painted_vertices: number}} info - GET .../rig.
	 */
	constructor( weights, info ) {

		/** Joint (feature point) count N. */
		this.nJoints = weights.nJoints;
		/** Influences per vertex k. */
		this.nInfluences = weights.nInfluences;
		/** (V*k) joint indices. */
		this.indices = weights.indices.slice();
		/** (V*k) weights. */
		this.weights = weights.weights.slice();
		/** The server's version of these weights (an edit on another version is refused). */
		this.version = info.version;
		/** Vertices whose rows differ from the automatic rig's. */
		this.painted = info.painted_vertices;
		/** @type {History<PaintStep>} */
		this._history = new History();

	}

	/** Whether there is an edit to undo. */
	get canUndo() {

		return this._history.canUndo;

	}

	/** Whether there is an undone edit to redo. */
	get canRedo() {

		return this._history.canRedo;

	}

	/**
	 * Remember an edit whose rows are already in the rig, as one undo step.
	 * @param {PaintStep} step
	 */
	record( step ) {

		this._history.push( step );

	}

	/**
	 * Put back the rows of the last step.
	 * @returns {Int32Array|null} the vertices whose rows changed; null when there was no step.
	 */
	undo() {

		const step = this._history.undo();
		if ( step ) this.write( step.vertices, step.before );
		return step ? step.vertices : null;

	}

	/**
	 * Make the last undone step again.
	 * @returns {Int32Array|null} the vertices whose rows changed; null when there was no step.
	 */
	redo() {

		const step = this._history.redo();
		if ( step ) this.write( step.vertices, step.after );
		return step ? step.vertices : null;

	}

	/**
	 * Take the server's answer to an edit or reset.
	 * @param {{version: number, painted_vertices: number}} info - GET .../rig.
	 */
	setInfo( info ) {

		this.version = info.version;
		this.painted = info.painted_vertices;

	}

	/**
	 * The rows of `vertices`, copied.
	 * @param {ArrayLike<number>} vertices
	 * @param {{indices: Uint16Array, weights: Float32Array}} [source] - (V*k) arrays to read;
	 *   default: this rig's.
	 * @returns {Rows} (R*k) each.
	 */
	rows( vertices, source = this ) {

		const k = this.nInfluences;
		const rows = { indices: new Uint16Array( vertices.length * k ), weights: new Float32Array( vertices.length * k ) };
		for ( let n = 0; n < vertices.length; n ++ ) {

			const v = vertices[ n ];
			rows.indices.set( source.indices.subarray( v * k, v * k + k ), n * k );
			rows.weights.set( source.weights.subarray( v * k, v * k + k ), n * k );

		}

		return rows;

	}

	/**
	 * Put rows into the rig.
	 * @param {ArrayLike<number>} vertices - (R)
	 * @param {Rows} rows - (R*k) each, in the order of `vertices`.
	 */
	write( vertices, rows ) {

		const k = this.nInfluences;
		for ( let n = 0; n < vertices.length; n ++ ) {

			const v = vertices[ n ];
			this.indices.set( rows.indices.subarray( n * k, n * k + k ), v * k );
			this.weights.set( rows.weights.subarray( n * k, n * k + k ), v * k );

		}

	}

	/**
	 * The vertices whose rows differ in `other` (slot by slot).
	 * @param {{indices: Uint16Array, weights: Float32Array}} other - (V*k) arrays of the same rig.
	 * @returns {Int32Array} ascending.
	 */
	differing( other ) {

		const k = this.nInfluences, changed = [];
		for ( let v = 0, n = other.weights.length / k; v < n; v ++ ) {

			for ( let s = v * k; s < v * k + k; s ++ ) {

				if ( other.indices[ s ] !== this.indices[ s ] || other.weights[ s ] !== this.weights[ s ] ) {

					changed.push( v );
					break;

				}

			}

		}

		return Int32Array.from( changed );

	}

}
