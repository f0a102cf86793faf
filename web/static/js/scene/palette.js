/**
 * Colours of the layout regions (server/routers/layouts.py `regions`), shared by the
 * markers on the mesh, the reference face and the region toggles, so one region reads
 * as one colour everywhere.
 */

const REGION_COLORS = {
	brows: '#e8b04a',
	eyes: '#52b7e8',
	nose: '#b488f0',
	upper_lip: '#f06b8a',
	lower_lip: '#e8547a',
	mouth_corners: '#ff8f5a',
	jaw: '#6cd39a',
};

const OTHER = '#c8c8c8';

/**
 * @param {string} region
 * @returns {string} CSS hex colour
 */
export function regionColor( region ) {

	return REGION_COLORS[ region ] || OTHER;

}
