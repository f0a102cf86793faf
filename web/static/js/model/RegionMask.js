/**
 * Which regions of the face move (partial retargeting, Dutreve §4), the one owner of the
 * Live panel's region toggles: the stream's `mask` and Export's `regions` are both
 * `movingRegions()`. Held regions are kept by name (the project settings'
 * `held_regions` key), so a region a new layout adds moves until it is held.
 *
 * Dispatches 'change' from `setMoving`, not from `load`.
 */
export class RegionMask extends EventTarget {

	constructor() {

		super();
		/** The layout's regions that have points, in the layout's order. */
		this.regions = [];
		/** @type {Set<string>} the regions held at rest. */
		this.held = new Set();

	}

	/**
	 * The regions of the project's layout.
	 * @param {string[]} regions
	 */
	setRegions( regions ) {

		this.regions = regions.slice();

	}

	/**
	 * Start from saved held regions (a project's); no 'change'.
	 * @param {string[]|null} held - null or absent: every region moves.
	 */
	load( held ) {

		this.held = new Set( Array.isArray( held ) ? held.filter( ( r ) => typeof r === 'string' ) : [] );

	}

	/**
	 * @param {string} region
	 * @returns {boolean} whether it moves.
	 */
	moves( region ) {

		return ! this.held.has( region );

	}

	/**
	 * Let a region move or hold it at rest; dispatches 'change'.
	 * @param {string} region
	 * @param {boolean} on - whether it moves.
	 */
	setMoving( region, on ) {

		if ( on ) this.held.delete( region );
		else this.held.add( region );
		this.dispatchEvent( new Event( 'change' ) );

	}

	/**
	 * The regions that move, or null when all of the layout's (or none: the server then
	 * moves the whole face) do.
	 * @returns {string[]|null}
	 */
	movingRegions() {

		const moving = this.regions.filter( ( r ) => this.moves( r ) );
		return moving.length && moving.length < this.regions.length ? moving : null;

	}

	/** @returns {string[]|null} what is saved: the held regions, null when none is held. */
	toJSON() {

		return this.held.size ? [ ...this.held ] : null;

	}

}
