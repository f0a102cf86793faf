/**
 * Custom layouts in the page (retarget/custom_layouts.py has the spec): the spec made from
 * a take's markers and the user's choices, and stand-in guide positions for the points of
 * a custom layout saved with none, so the landmark guide can show which one comes next.
 */

/** The regions a point may belong to (retarget.layouts.REGIONS). */
export const REGIONS = [ 'brows', 'eyes', 'nose', 'upper_lip', 'lower_lip', 'mouth_corners', 'jaw', 'cheeks', 'forehead' ];

/** The subject's sides (retarget.layouts.SIDES). */
export const SIDES = [ 'right', 'center', 'left' ];

// Where each region sits on a face seen front-on (cm, x toward the subject's left, +y up),
// for a point of the subject's left; the right side mirrors it, the midline is x = 0.
const SPOTS = {
	brows: [ 3.0, 4.6 ], eyes: [ 3.0, 3.2 ], nose: [ 1.0, 0.6 ], upper_lip: [ 1.1, - 2.3 ],
	mouth_corners: [ 2.4, - 2.8 ], lower_lip: [ 1.1, - 3.4 ], jaw: [ 4.2, - 5.6 ],
	cheeks: [ 4.0, - 0.4 ], forehead: [ 2.6, 7.0 ],
};

/**
 * The layout with a guide position for every point that has none: its region's spot on
 * its side, points sharing a spot spread apart. Layouts whose points all have one are
 * answered as they are.
 * @param {{points: Array<{region: string, side: string, reference: number[]|null}>}} layout
 * @returns {object}
 */
export function withGuidePositions( layout ) {

	if ( layout.points.every( ( p ) => p.reference ) ) return layout;
	const seen = new Map();
	const points = layout.points.map( ( p ) => {

		if ( p.reference ) return p;
		const key = `${ p.region } ${ p.side }`;
		const k = seen.get( key ) ?? 0;
		seen.set( key, k + 1 );
		const [ x, y ] = SPOTS[ p.region ] ?? [ 0, 0 ];
		const sign = p.side === 'right' ? - 1 : p.side === 'left' ? 1 : 0;
		// side points step outwards, midline points downwards
		const reference = sign ? [ sign * ( x + 0.8 * k ), y, 0 ] : [ 0, y - 0.6 * k, 0 ];
		return { ...p, reference };

	} );
	return { ...layout, points };

}

/**
 * A layout spec (what PUT /api/projects/{id}/layouts/{name} takes) from the rows the user
 * filled in: a partner is named on both rows (the last choice wins for the pair).
 * Rows that all carry a `reference` (where each marker sat on the take's frames, from the
 * server) keep it, so later videos of the same markers are named by place.
 * @param {Array<{name: string, region: string, side: string, mirror: string, anchor: boolean,
 *   reference: number[]|null}>} rows
 * @param {string} description
 * @returns {{description: string, points: object[]}}
 */
export function layoutSpec( rows, description ) {

	const partner = new Map();
	for ( const row of rows ) {

		if ( row.mirror && row.mirror !== row.name ) {

			partner.set( row.name, row.mirror );
			partner.set( row.mirror, row.name );

		}

	}

	const placed = rows.every( ( row ) => Array.isArray( row.reference ) );
	const points = rows.map( ( row ) => {

		const point = { name: row.name, region: row.region, side: row.side };
		if ( partner.has( row.name ) ) point.mirror = partner.get( row.name );
		if ( row.anchor ) point.anchor = true;
		if ( placed ) point.reference = row.reference;
		return point;

	} );
	return { description, points };

}
