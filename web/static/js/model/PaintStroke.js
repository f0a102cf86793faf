import { jointWeight, setJointWeight } from './weightRows.js';

/**
 * One stroke of the weight brush on a PaintedRig: every dab changes the rows of the
 * vertices within the brush's radius that the surface connects to the triangle under it
 * (MeshNeighbours), so painting the upper lip leaves the lower lip alone, by a smooth
 * falloff from the centre. Rows change by weightRows.js's rule (w_j set, the other
 * influences and the static root rescaled, at most k kept).
 *
 * Strokes do not accumulate (Blender's default): within one stroke a vertex moves toward
 * the brush's target by at most the strength, recomputed from the row the stroke found;
 * the smooth brush does accumulate, pulling w_j toward its 1-ring mean. The stroke keeps
 * each touched vertex's original row, for its undo step.
 */
export class PaintStroke {

	/**
	 * @param {import('./PaintedRig.js').PaintedRig} rig - changed in place.
	 * @param {import('./MeshNeighbours.js').MeshNeighbours} neighbours - the face's adjacency.
	 * @param {Float32Array} positions - (3V) rest positions, mesh units.
	 * @param {import('./BrushSettings.js').BrushSettings} settings - read at every dab.
	 */
	constructor( rig, neighbours, positions, settings ) {

		this.rig = rig;
		this.settings = settings;
		this._neighbours = neighbours;
		this._positions = positions;
		this._original = new Map(); // vertex -> its row when the stroke first touched it
		this._alpha = new Map(); // joint -> (V) the reach each vertex got so far

	}

	/**
	 * One dab.
	 * @param {{x: number, y: number, z: number}} center - on the surface, mesh frame.
	 * @param {number} faceIndex - the triangle under the centre.
	 * @param {number} joint - the feature point painted.
	 * @param {Set<number>} changed - gets the vertices whose rows changed.
	 */
	dab( center, faceIndex, joint, changed ) {

		const rig = this.rig, k = rig.nInfluences, surface = this._neighbours;
		const { brush, radius: r, strength } = this.settings;
		const { vertices, distances } = surface.within( this._positions, center, faceIndex, r );
		if ( brush === 'smooth' ) {

			const targets = vertices.map( ( v, n ) => {

				const a = jointWeight( rig.indices, rig.weights, v, k, joint );
				const mean = surface.mean( v, ( u ) => jointWeight( rig.indices, rig.weights, u, k, joint ) );
				return a + strength * falloff( distances[ n ] / r ) * ( mean - a );

			} );
			vertices.forEach( ( v, n ) => {

				this._remember( v );
				if ( setJointWeight( rig.indices, rig.weights, v, k, joint, targets[ n ] ) ) changed.add( v );

			} );
			return;

		}

		if ( ! this._alpha.has( joint ) ) this._alpha.set( joint, new Float32Array( this._positions.length / 3 ) );
		const alpha = this._alpha.get( joint );
		vertices.forEach( ( v, n ) => {

			const a = strength * falloff( distances[ n ] / r );
			if ( a <= alpha[ v ] ) return;
			alpha[ v ] = a;
			this._remember( v );
			// from the stroke's starting row: a vertex moves by at most the strength per stroke
			const original = this._original.get( v );
			rig.indices.set( original.indices, v * k );
			rig.weights.set( original.weights, v * k );
			for ( const [ j, reached ] of this._alpha ) {

				if ( reached[ v ] > 0 ) setJointWeight( rig.indices, rig.weights, v, k, j, this._target( jointWeight( rig.indices, rig.weights, v, k, j ), reached[ v ] ) );

			}

			changed.add( v );

		} );

	}

	/**
	 * The stroke's undo step so far: the touched vertices and their rows before and after.
	 * @returns {{vertices: Int32Array, before: import('./PaintedRig.js').Rows,
	 *   after: import('./PaintedRig.js').Rows}|null} null when nothing was touched.
	 */
	step() {

		if ( ! this._original.size ) return null;
		const vertices = Int32Array.from( this._original.keys() ).sort();
		const k = this.rig.nInfluences;
		const before = { indices: new Uint16Array( vertices.length * k ), weights: new Float32Array( vertices.length * k ) };
		vertices.forEach( ( v, n ) => {

			const row = this._original.get( v );
			before.indices.set( row.indices, n * k );
			before.weights.set( row.weights, n * k );

		} );
		return { vertices, before, after: this.rig.rows( vertices ) };

	}

	/** The weight a brush of reach `alpha` (0..strength) paints over `a`. */
	_target( a, alpha ) {

		const { brush, value } = this.settings;
		if ( brush === 'add' ) return Math.min( 1, a + alpha );
		if ( brush === 'subtract' ) return Math.max( 0, a - alpha );
		return a + alpha * ( value - a );

	}

	/** Keep vertex v's row as the stroke found it. */
	_remember( v ) {

		if ( this._original.has( v ) ) return;
		const k = this.rig.nInfluences;
		this._original.set( v, { indices: this.rig.indices.slice( v * k, v * k + k ), weights: this.rig.weights.slice( v * k, v * k + k ) } );

	}

}

/** Brush falloff at x = distance / radius: 1 at the centre, 0 from the rim, smooth at both. */
function falloff( x ) {

	const t = 1 - x * x;
	return x >= 1 ? 0 : t * t;

}
