import { regionColor } from '../scene/palette.js';
import { faceSketch } from './faceSketch.js';

const MARGIN = 14; // CSS px around the drawing
const HIT_RADIUS = 9; // CSS px: how close a click must be to pick a point

/**
 * The reference face of a landmark layout, drawn front-on in a small canvas as you see a
 * person facing you (the face's right on your left): a sketch of the face behind it all
 * (outline, eyes, lips: faceSketch.js), the face's contours (consecutive points of one
 * feature joined), the placed points filled in their region's colour, the next point
 * ringed and named above it. Clicking a point dispatches 'pick' with its index, so the
 * user can choose which point to place next.
 */
export class LayoutGuide extends EventTarget {

	/**
	 * @param {HTMLCanvasElement} canvas - drawn at its CSS size times devicePixelRatio.
	 */
	constructor( canvas ) {

		super();
		this.canvas = canvas;
		this.layout = null;
		this.state = { placed: [], next: - 1, selected: - 1 };
		this._screen = []; // [x, y] CSS px per point
		this._contours = [];
		this._sketch = [];
		/** The sketch as last drawn: [{name, path}], path (K, 2) CSS px (for tests). */
		this.sketch = [];

		this._onClick = ( event ) => {

			const index = this._pointAt( event );
			if ( index >= 0 ) this.dispatchEvent( new CustomEvent( 'pick', { detail: { index } } ) );

		};

		this._onMove = ( event ) => {

			const index = this._pointAt( event );
			canvas.title = index >= 0 ? this.layout.points[ index ].name : 'Reference face: click a point to place it next';

		};

		canvas.addEventListener( 'click', this._onClick );
		canvas.addEventListener( 'pointermove', this._onMove );
		this._resize = new ResizeObserver( () => this.draw() );
		this._resize.observe( canvas );

	}

	/**
	 * @param {{points: Array<{name: string, region: string, side: string, reference: number[]}>}|null} layout
	 */
	setLayout( layout ) {

		this.layout = layout;
		this._contours = layout ? contours( layout.points ) : [];
		this._sketch = layout ? faceSketch( layout.points ) : [];
		this.draw();

	}

	/**
	 * @param {{placed: boolean[], next: number, selected: number}} state - per-point placed
	 *   flags, the index of the next point (-1: none) and of the selected one (-1: none).
	 */
	update( state ) {

		this.state = state;
		this.draw();

	}

	/** Draw the reference face at the canvas's current size. */
	draw() {

		const canvas = this.canvas;
		const width = canvas.clientWidth, height = canvas.clientHeight;
		if ( width === 0 || height === 0 ) return;
		const dpr = window.devicePixelRatio || 1;
		if ( canvas.width !== Math.round( width * dpr ) || canvas.height !== Math.round( height * dpr ) ) {

			canvas.width = Math.round( width * dpr );
			canvas.height = Math.round( height * dpr );

		}

		const ctx = canvas.getContext( '2d' );
		ctx.setTransform( dpr, 0, 0, dpr, 0, 0 );
		ctx.clearRect( 0, 0, width, height );
		if ( ! this.layout ) return;

		const points = this.layout.points;
		const sketched = this._sketch.flatMap( ( shape ) => shape.path );
		const fitted = fit( [ ...points.map( ( p ) => p.reference ), ...sketched ], width, height );
		this._screen = fitted.slice( 0, points.length );
		let at = points.length;
		this.sketch = this._sketch.map( ( { name, path } ) => ( { name, path: fitted.slice( at, at += path.length ) } ) );
		const { placed, next, selected } = this.state;
		const xy = this._screen;

		ctx.lineJoin = ctx.lineCap = 'round';
		for ( const { name, path } of this.sketch ) {

			const lips = name === 'lips';
			ctx.beginPath();
			path.forEach( ( [ x, y ], k ) => ( k ? ctx.lineTo( x, y ) : ctx.moveTo( x, y ) ) );
			ctx.closePath();
			ctx.fillStyle = lips ? withAlpha( regionColor( 'upper_lip' ), 0.16 ) : 'rgba(255, 255, 255, 0.04)';
			ctx.fill();
			ctx.strokeStyle = 'rgba(176, 182, 190, 0.45)';
			ctx.lineWidth = name === 'face' ? 1.5 : 1;
			ctx.stroke();

		}

		ctx.lineWidth = 1.25;
		for ( const { indices, closed } of this._contours ) {

			ctx.strokeStyle = withAlpha( regionColor( points[ indices[ 0 ] ].region ), 0.38 );
			ctx.beginPath();
			indices.forEach( ( i, k ) => ( k ? ctx.lineTo( xy[ i ][ 0 ], xy[ i ][ 1 ] ) : ctx.moveTo( xy[ i ][ 0 ], xy[ i ][ 1 ] ) ) );
			if ( closed ) ctx.closePath();
			ctx.stroke();

		}

		const radius = points.length > 40 ? 2.6 : 3.4;
		points.forEach( ( point, i ) => {

			const [ x, y ] = xy[ i ];
			const color = regionColor( point.region );
			ctx.beginPath();
			ctx.arc( x, y, radius, 0, 2 * Math.PI );
			if ( placed[ i ] ) {

				ctx.fillStyle = color;
				ctx.fill();

			} else {

				ctx.fillStyle = '#1e1f22';
				ctx.fill();
				ctx.strokeStyle = '#6f747b';
				ctx.lineWidth = 1;
				ctx.stroke();

			}

		} );

		if ( selected >= 0 ) ring( ctx, xy[ selected ], radius + 3, '#ffffff', 1.5 );
		if ( next >= 0 ) {

			ring( ctx, xy[ next ], radius + 4.5, '#ffd54a', 2 );
			ctx.fillStyle = '#ffd54a';
			ctx.beginPath();
			ctx.arc( xy[ next ][ 0 ], xy[ next ][ 1 ], radius, 0, 2 * Math.PI );
			ctx.fill();
			label( ctx, points[ next ].name, xy[ next ], radius + 10, width );

		}

	}

	/** Stop listening and observing the canvas. */
	dispose() {

		this.canvas.removeEventListener( 'click', this._onClick );
		this.canvas.removeEventListener( 'pointermove', this._onMove );
		this._resize.disconnect();

	}

	_pointAt( event ) {

		const rect = this.canvas.getBoundingClientRect();
		const x = event.clientX - rect.left, y = event.clientY - rect.top;
		let best = - 1, bestD = HIT_RADIUS * HIT_RADIUS;
		this._screen.forEach( ( [ px, py ], i ) => {

			const d = ( px - x ) ** 2 + ( py - y ) ** 2;
			if ( d < bestD ) {

				bestD = d;
				best = i;

			}

		} );
		return best;

	}

}

/**
 * Canvas positions of reference points seen from the front (x right, y up), fitted into
 * the canvas with the same scale on both axes.
 * @param {number[][]} references - (N, 2 or 3) positions, +y up, the face looking down +z.
 * @returns {number[][]} (N, 2) CSS px.
 */
function fit( references, width, height ) {

	let x0 = Infinity, x1 = - Infinity, y0 = Infinity, y1 = - Infinity;
	for ( const [ x, y ] of references ) {

		x0 = Math.min( x0, x ); x1 = Math.max( x1, x );
		y0 = Math.min( y0, y ); y1 = Math.max( y1, y );

	}

	const scale = Math.min( ( width - 2 * MARGIN ) / ( x1 - x0 || 1 ), ( height - 2 * MARGIN ) / ( y1 - y0 || 1 ) );
	const cx = width / 2, cy = height / 2, mx = ( x0 + x1 ) / 2, my = ( y0 + y1 ) / 2;
	return references.map( ( [ x, y ] ) => [ cx + ( x - mx ) * scale, cy - ( y - my ) * scale ] );

}

/**
 * The face's contour lines: runs of consecutive points that belong to one feature. A
 * feature is a region on one side (both brows are 'brows' but two lines; midline points
 * join either side, so the jaw runs through the chin); the lips are one feature with
 * the inner lip apart from the outer. Eyes and lips close into loops.
 * @param {Array<{name: string, region: string, side: string}>} points
 * @returns {Array<{indices: number[], closed: boolean}>}
 */
function contours( points ) {

	const feature = ( p ) => {

		if ( /lip|mouth/.test( p.region ) ) return /(^|_)inner(_|$)/.test( p.name ) ? 'lips_inner' : 'lips';
		return p.region;

	};

	const runs = [];
	let run = null;
	points.forEach( ( p, i ) => {

		const last = run && points[ run.indices[ run.indices.length - 1 ] ];
		const joins = run && run.feature === feature( p ) && ( p.side === 'center' || last.side === 'center' || p.side === last.side );
		if ( joins ) {

			run.indices.push( i );

		} else {

			run = { feature: feature( p ), indices: [ i ] };
			runs.push( run );

		}

	} );

	return runs.filter( ( r ) => r.indices.length > 1 ).map( ( r ) => ( {
		indices: r.indices,
		closed: r.indices.length > 2 && ( r.feature === 'eyes' || r.feature.startsWith( 'lips' ) ),
	} ) );

}

/** `text` centred above the point at (x, y) (below it near the top), inside the canvas. */
function label( ctx, text, [ x, y ], gap, width ) {

	ctx.font = '10px ui-monospace, Menlo, Consolas, monospace';
	const w = ctx.measureText( text ).width;
	const tx = Math.min( Math.max( 2, x - w / 2 ), width - w - 2 );
	const ty = y - gap - 6 > 2 ? y - gap : y + gap;
	ctx.fillStyle = 'rgba(30, 31, 34, 0.8)';
	ctx.fillRect( tx - 2, ty - 7, w + 4, 13 );
	ctx.fillStyle = '#ffd54a';
	ctx.textBaseline = 'middle';
	ctx.fillText( text, tx, ty );

}

function ring( ctx, [ x, y ], radius, color, width ) {

	ctx.beginPath();
	ctx.arc( x, y, radius, 0, 2 * Math.PI );
	ctx.strokeStyle = color;
	ctx.lineWidth = width;
	ctx.stroke();

}

function withAlpha( hex, alpha ) {

	const n = parseInt( hex.slice( 1 ), 16 );
	return `rgba(${ n >> 16 }, ${ ( n >> 8 ) & 255 }, ${ n & 255 }, ${ alpha })`;

}
