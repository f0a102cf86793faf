/**
 * A face's virtual muscles as the page plays them (server/wire.py's RTMM, from
 * GET /api/projects/{id}/muscles/played; `retarget.muscles.morphs.MuscleMorphs`): morph
 * targets (the muscles', then the correctives of the muscles the jaw crosses) and a jaw
 * joint, and the rule from a contraction vector to their weights. The
 * shader (web/shaders/muscles.glsl) does the rest.
 */
export class PlayedMuscles {

	/**
	 * @param {{nVertices: number, nTargets: number, header: object, targets: Float32Array,
	 *   jawWeights: Float32Array}} decoded - MuscleMorphsDecoder's result (viewed, not copied).
	 */
	constructor( { nVertices, nTargets, header, targets, jawWeights } ) {

		const { names, dofs, high, corrective_of: correctiveOf, limits, jaw_limits: jawLimits, jaw_pivot: pivot, jaw_axis: axis, expressions } = header;
		if ( names.length !== nTargets || high.length + correctiveOf.length !== nTargets || high.length + 1 !== dofs.length || limits.length !== dofs.length ) {

			throw new RangeError( `PlayedMuscles: ${ nTargets } targets need as many names and muscles plus correctives, ${ dofs.length } dofs one more than the muscles and as many limits; got ${ names.length } names, ${ high.length } muscles, ${ correctiveOf.length } correctives and ${ limits.length } limits.` );

		}

		/** Vertex count V. */
		this.nVertices = nVertices;
		/** Morph target count T: the M muscles', then the correctives. */
		this.nTargets = nTargets;
		/** (T) target names; a corrective's is `<muscle>*jaw`. */
		this.names = names;
		/** (D) dof names, the muscles' then "jaw"; a contraction vector's order. */
		this.dofs = dofs;
		/** (D) [low, high] per dof: contractions, the jaw's in radians. */
		this.limits = limits;
		/** (M) the contraction that a muscle target's weight 1 stands for. */
		this.high = Float32Array.from( high );
		/** (C) the muscle of each corrective target (targets M..T-1). */
		this.correctiveOf = Uint32Array.from( correctiveOf );
		/** The jaw angle that a corrective's jaw factor 1 stands for, radians. */
		this.jawHigh = jawLimits[ 1 ];
		/** Hinge point and unit axis of the jaw joint, mesh units. */
		this.jawPivot = pivot;
		this.jawAxis = axis;
		/** (E) expression names, a contraction frame's label and distances order. */
		this.expressions = expressions;
		/** (T*V*3) target-major displacements at weight 1, mesh units. */
		this.targets = targets;
		/** (V) each vertex's weight on the jaw joint. */
		this.jawWeights = jawWeights;

	}

	/**
	 * Morph weights of a pose (`MuscleMorphs.weights` and `corrective_weights`): a
	 * muscle's c_m / high_m (negative opens an eye wide), a corrective's its muscle's
	 * weight times jaw / jawHigh.
	 * @param {ArrayLike<number>} contractions - (D) the dofs' values.
	 * @param {Float32Array} [out] - (T) written and returned.
	 * @returns {Float32Array}
	 */
	weights( contractions, out = new Float32Array( this.nTargets ) ) {

		this._check( contractions );
		const m = this.high.length, jaw = contractions[ m ] / this.jawHigh;
		for ( let t = 0; t < m; t ++ ) out[ t ] = contractions[ t ] / this.high[ t ];
		for ( let k = 0; k < this.correctiveOf.length; k ++ ) out[ m + k ] = out[ this.correctiveOf[ k ] ] * jaw;
		return out;

	}

	/**
	 * @param {ArrayLike<number>} contractions - (D)
	 * @returns {number} the jaw angle, radians (the last dof).
	 */
	jawAngle( contractions ) {

		this._check( contractions );
		return contractions[ this.dofs.length - 1 ];

	}

	_check( contractions ) {

		if ( contractions.length !== this.dofs.length ) throw new RangeError( `PlayedMuscles: a pose has ${ this.dofs.length } contractions (${ this.dofs.join( ', ' ) }); got ${ contractions.length }.` );

	}

}
