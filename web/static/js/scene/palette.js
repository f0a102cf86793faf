/**
 * Colours of the layout regions (server/routers/layouts.py `regions`), shared by the
 * markers on the mesh, the reference face and the region toggles, so one region reads
 * as one colour everywhere; and the heat map's colour of a weight (the legend's), the
 * twin of face.frag's.
 */

const REGION_COLORS = {
	brows: '#e8b04a',
	eyes: '#52b7e8',
	nose: '#b488f0',
	upper_lip: '#f06b8a',
	lower_lip: '#e8547a',
	mouth_corners: '#ff8f5a',
	jaw: '#6cd39a',
	cheeks: '#d4a373',
	forehead: '#a3c45a',
};

const OTHER = '#c8c8c8';

/**
 * @param {string} region
 * @returns {string} CSS hex colour
 */
export function regionColor( region ) {

	return REGION_COLORS[ region ] || OTHER;

}

// Viridis polynomial coefficients (Matt Zucker's fit, CC0), as in web/shaders/face.frag.
const VIRIDIS = [
	[ 0.2777273272234177, 0.005407344544966578, 0.3340998053353061 ],
	[ 0.1050930431085774, 1.404613529898575, 1.384590162594685 ],
	[ - 0.3308618287255563, 0.214847559468213, 0.09509516302823659 ],
	[ - 4.634230498983486, - 5.799100973351585, - 19.33244095627987 ],
	[ 6.228269936347081, 14.17993336680509, 56.69055260068105 ],
	[ 4.776384997670288, - 13.74514537774601, - 65.35303263337234 ],
	[ - 5.435455855934631, 4.645852612178535, 26.3124352495832 ],
];
const NEGATIVE = [ 0.95, 0.16, 0.2 ];

const saturate = ( x ) => Math.min( 1, Math.max( 0, x ) );
const mix = ( a, b, t ) => a.map( ( v, i ) => v + ( b[ i ] - v ) * t );

/**
 * The heat map's colour of a weight: the CPU twin of face.frag's `heatColor` (viridis for
 * 0..1, red from below 0, fading to white above 1), for the legend.
 * @param {number} w
 * @returns {number[]} [r, g, b] sRGB in 0..1
 */
export function heatColor( w ) {

	const t = saturate( w );
	let srgb = [ 0, 1, 2 ].map( ( c ) => VIRIDIS.reduceRight( ( sum, row ) => row[ c ] + t * sum, 0 ) );
	srgb = mix( srgb, NEGATIVE, Math.sqrt( saturate( - w / 0.05 ) ) );
	srgb = mix( srgb, [ 1, 1, 1 ], saturate( ( w - 1 ) / 0.25 ) );
	return srgb.map( saturate );

}
