/**
 * A sketch of a face around a layout's reference points, for the landmark guide: the
 * face's outline, an almond per eye and the outer lips' shape, so that a layout of a few
 * dozen points (dutreve21/22, ibug51) reads as a face rather than as loose dots. Drawn
 * behind the points; what the layout's own contours already show is not drawn again
 * (ibug68's jaw line, ibug51's eye rings).
 *
 * Everything is in the reference's front view: x to the viewer's right (the face's left),
 * y up, the units of the reference points.
 */

const OUTLINE_STEPS = 64;
const EYE_STEPS = 12;

/**
 * @param {Array<{name: string, region: string, side: string, reference: number[]}>} points
 * @returns {Array<{name: string, path: number[][]}>} closed paths (K, 2): 'face',
 *   'eye_right', 'eye_left' (the face's sides), 'lips'; a shape the points cannot place
 *   is left out.
 */
export function faceSketch( points ) {

	if ( points.length < 3 ) return [];
	const xy = ( p ) => [ p.reference[ 0 ], p.reference[ 1 ] ];
	const of = ( test ) => points.filter( test ).map( xy );
	const all = points.map( xy );
	const shapes = [];

	const jaw = of( ( p ) => p.region === 'jaw' );
	if ( jaw.length < 3 ) shapes.push( { name: 'face', path: outline( all, jaw ) } );

	for ( const side of [ 'right', 'left' ] ) {

		const eye = of( ( p ) => p.region === 'eyes' && p.side === side );
		// four or more points close into the eye's own ring (LayoutGuide's contours)
		if ( eye.length === 0 || eye.length >= 4 ) continue;
		const brow = of( ( p ) => p.region === 'brows' && p.side === side );
		shapes.push( { name: `eye_${ side }`, path: almond( eye, brow, all ) } );

	}

	const lips = of( ( p ) => /lip|mouth/.test( p.region ) && ! /(^|_)inner(_|$)/.test( p.name ) );
	if ( lips.length >= 3 ) shapes.push( { name: 'lips', path: aroundCentre( lips ) } );
	return shapes;

}

/**
 * An egg-shaped outline around the points: a forehead above the brows, the widest at the
 * eyes, narrowing to the chin (the lowest jaw point when the layout has one).
 */
function outline( all, jaw ) {

	const { x0, x1, y0, y1 } = bounds( all );
	const width = x1 - x0, height = y1 - y0;
	const cx = ( x0 + x1 ) / 2;
	const eyeLevel = y1 - 0.25 * height;
	const top = y1 + 0.35 * height;
	const chin = jaw.length ? Math.min( ...jaw.map( ( p ) => p[ 1 ] ) ) : y0 - 0.3 * height;
	const halfWidth = 0.62 * width;
	const path = [];
	for ( let i = 0; i < OUTLINE_STEPS; i ++ ) {

		const t = 2 * Math.PI * i / OUTLINE_STEPS;
		const s = Math.sin( t ), c = Math.cos( t );
		// below the eyes the sides draw in towards the chin
		const taper = s < 0 ? 1 - 0.35 * s * s : 1;
		path.push( [ cx + halfWidth * c * taper, eyeLevel + ( s > 0 ? top - eyeLevel : eyeLevel - chin ) * s ] );

	}

	return path;

}

/** An almond under the brow of one side, through the height of that eye's points. */
function almond( eye, brow, all ) {

	const eyeBox = bounds( eye );
	const ey = ( eyeBox.y0 + eyeBox.y1 ) / 2;
	let ex, width;
	if ( brow.length >= 2 ) {

		const browBox = bounds( brow );
		ex = ( browBox.x0 + browBox.x1 ) / 2;
		width = 0.8 * ( browBox.x1 - browBox.x0 );

	} else {

		ex = ( eyeBox.x0 + eyeBox.x1 ) / 2;
		const span = bounds( all );
		width = 0.22 * ( span.x1 - span.x0 );

	}

	const height = Math.max( 0.3 * width, 1.3 * ( eyeBox.y1 - eyeBox.y0 ) );
	const path = [];
	for ( let i = 0; i <= EYE_STEPS; i ++ ) {

		const s = i / EYE_STEPS;
		path.push( [ ex - width / 2 + width * s, ey + 0.5 * height * Math.sin( Math.PI * s ) ] );

	}

	for ( let i = EYE_STEPS - 1; i > 0; i -- ) {

		const s = i / EYE_STEPS;
		path.push( [ ex - width / 2 + width * s, ey - 0.4 * height * Math.sin( Math.PI * s ) ] );

	}

	return path;

}

/** The points in order of their angle around their centre: a loop through them all. */
function aroundCentre( pts ) {

	const cx = pts.reduce( ( sum, p ) => sum + p[ 0 ], 0 ) / pts.length;
	const cy = pts.reduce( ( sum, p ) => sum + p[ 1 ], 0 ) / pts.length;
	const angle = ( p ) => Math.atan2( p[ 1 ] - cy, p[ 0 ] - cx );
	return [ ...pts ].sort( ( a, b ) => angle( a ) - angle( b ) );

}

function bounds( pts ) {

	let x0 = Infinity, x1 = - Infinity, y0 = Infinity, y1 = - Infinity;
	for ( const [ x, y ] of pts ) {

		x0 = Math.min( x0, x ); x1 = Math.max( x1, x );
		y0 = Math.min( y0, y ); y1 = Math.max( y1, y );

	}

	return { x0, x1, y0, y1 };

}
