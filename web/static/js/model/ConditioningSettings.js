/**
 * The project's conditioning settings, the one owner of them: what the stream gets with
 * every start and `settings` message, what Export retargets with, what the Conditioning
 * form shows. Their JSON is `retarget.sources.conditioning.ConditionSettings`':
 *
 *     {neutral: {mode: 'first_seconds', seconds} | {mode: 'frame', frame},
 *      head_pose: 'remove' | 'keep', apply_rotation, filter: 'none' | 'mean3' | 'one_euro',
 *      one_euro: {region: {min_cutoff, beta}}, gain: {region: gain}}
 *
 * with one gain and cutoff per region of the project's layout (one β for all). Values of
 * regions the layout does not have are kept, for a layout that has them again. Saved with
 * the project (its settings' `conditioning` key) by whoever listens to 'change', which
 * `set` dispatches and `load` does not.
 */
export class ConditioningSettings extends EventTarget {

	constructor() {

		super();
		/** The regions with a gain and cutoff, in the layout's point order. */
		this.regions = [];
		this._reset();

	}

	/**
	 * The regions of the project's layout.
	 * @param {string[]} regions
	 */
	setRegions( regions ) {

		this.regions = regions.slice();

	}

	/**
	 * Start from saved JSON (a project's), or the defaults; no 'change'.
	 * @param {object|null} json - ConditionSettings JSON, as `toJSON` gives it.
	 */
	load( json ) {

		this._reset();
		if ( ! json || typeof json !== 'object' ) return;
		const neutral = json.neutral ?? {};
		if ( neutral.mode === 'frame' || neutral.mode === 'first_seconds' ) {

			this.neutralMode = neutral.mode;
			this.neutralValue = Number( neutral.mode === 'frame' ? neutral.frame : neutral.seconds ) || 0;

		}

		if ( json.head_pose === 'remove' || json.head_pose === 'keep' ) this.headPose = json.head_pose;
		if ( typeof json.apply_rotation === 'boolean' ) this.applyRotation = json.apply_rotation;
		if ( [ 'none', 'mean3', 'one_euro' ].includes( json.filter ) ) this.filter = json.filter;
		for ( const [ region, gain ] of Object.entries( json.gain ?? {} ) ) if ( Number.isFinite( gain ) ) this.gain[ region ] = gain;
		for ( const [ region, oneEuro ] of Object.entries( json.one_euro ?? {} ) ) {

			if ( Number.isFinite( oneEuro?.min_cutoff ) ) this.cutoff[ region ] = oneEuro.min_cutoff;
			if ( Number.isFinite( oneEuro?.beta ) ) this.beta = oneEuro.beta;

		}

	}

	/**
	 * Change some settings; dispatches 'change'.
	 * @param {{neutralMode?: string, neutralValue?: number, headPose?: string,
	 *   applyRotation?: boolean, filter?: string, beta?: number,
	 *   gain?: Object<string, number>, cutoff?: Object<string, number>}} patch - gain and
	 *   cutoff by region, merged.
	 */
	set( patch ) {

		const { gain, cutoff, ...rest } = patch;
		Object.assign( this, rest );
		Object.assign( this.gain, gain );
		Object.assign( this.cutoff, cutoff );
		this.dispatchEvent( new Event( 'change' ) );

	}

	/** @returns {object} ConditionSettings JSON for the layout's regions. */
	toJSON() {

		const oneEuro = {}, gain = {};
		for ( const region of this.regions ) {

			gain[ region ] = this.gain[ region ] ?? 1;
			oneEuro[ region ] = { min_cutoff: this.cutoff[ region ] ?? 1, beta: this.beta };

		}

		const mode = this.neutralMode, value = this.neutralValue;
		return {
			neutral: mode === 'frame' ? { mode, frame: Math.max( 0, Math.round( value ) ) } : { mode, seconds: Math.max( 0, value ) },
			head_pose: this.headPose,
			apply_rotation: this.applyRotation,
			filter: this.filter,
			one_euro: oneEuro,
			gain,
		};

	}

	_reset() {

		/** 'first_seconds' or 'frame'. */
		this.neutralMode = 'first_seconds';
		/** Seconds or a frame number, by the mode. */
		this.neutralValue = 0.5;
		/** 'remove' (rigid head motion out of 3D sources) or 'keep'. */
		this.headPose = 'remove';
		/** Whether the target turns with the performer's head. */
		this.applyRotation = false;
		/** 'none', 'mean3' or 'one_euro'. */
		this.filter = 'one_euro';
		/** The One Euro filter's speed coefficient, every region's. */
		this.beta = 0.05;
		/** @type {Object<string, number>} gain by region (1 when absent). */
		this.gain = {};
		/** @type {Object<string, number>} One Euro minimum cutoff by region, Hz (1 when absent). */
		this.cutoff = {};

	}

}
