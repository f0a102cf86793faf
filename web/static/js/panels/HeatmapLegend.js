import { heatColor } from '../scene/palette.js';
import { $ } from './dom.js';

/**
 * The heat map's legend under its chooser (index.html #heat-legend): a colour bar from the
 * shown feature's lowest weight to its highest, in the heat map's own colours
 * (palette.js `heatColor`, face.frag's twin), the two values, and what a negative weight
 * means. Hidden while the heat map is off.
 */
export class HeatmapLegend {

	/**
	 * @param {{paint: {painter: {rig: {nInfluences: number, indices: Uint16Array, weights: Float32Array}|null}}}} app -
	 *   the rig's weights as painted so far (`app.paint.painter.rig`).
	 */
	constructor( app ) {

		this.app = app;

	}

	/** Show the legend of the feature the heat map shows (#heatmap-select), or hide it. */
	update() {

		const value = $( 'heatmap-select' ).value;
		const rig = this.app.paint?.painter.rig ?? null;
		const box = $( 'heat-legend' );
		box.hidden = value === '' || ! rig;
		if ( box.hidden ) return;
		const [ low, high ] = weightRange( rig, Number( value ) );
		$( 'heat-min' ).textContent = low.toFixed( 3 );
		$( 'heat-max' ).textContent = high.toFixed( 3 );
		this._drawBar( low, high );

	}

	_drawBar( low, high ) {

		const canvas = $( 'heat-bar' );
		const context = canvas.getContext( '2d' );
		const image = context.createImageData( canvas.width, 1 );
		for ( let x = 0; x < canvas.width; x ++ ) {

			const rgb = heatColor( low + ( high - low ) * x / ( canvas.width - 1 ) );
			image.data.set( [ ...rgb.map( ( c ) => Math.round( 255 * c ) ), 255 ], 4 * x );

		}

		for ( let y = 0; y < canvas.height; y ++ ) context.putImageData( image, 0, y );

	}

}

/**
 * The lowest and highest weight of `joint` over the vertices (0 for a vertex it does not
 * influence).
 * @param {{nInfluences: number, indices: Uint16Array, weights: Float32Array}} rig - (V, k) rows.
 * @param {number} joint
 * @returns {[number, number]}
 */
function weightRange( rig, joint ) {

	const k = rig.nInfluences, n = rig.indices.length / k;
	let low = Infinity, high = - Infinity, influenced = 0;
	for ( let v = 0; v < n; v ++ ) {

		for ( let s = v * k; s < v * k + k; s ++ ) {

			if ( rig.indices[ s ] !== joint || rig.weights[ s ] === 0 ) continue;
			const w = rig.weights[ s ];
			if ( w < low ) low = w;
			if ( w > high ) high = w;
			influenced ++;
			break;

		}

	}

	if ( influenced < n ) {

		low = Math.min( low, 0 );
		high = Math.max( high, 0 );

	}

	return [ low, high ];

}
