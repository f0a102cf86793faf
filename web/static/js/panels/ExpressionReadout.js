import { $ } from './dom.js';

const HISTORY = 300; // frames kept on the strip chart: 5 s at 60 fps
const COLORS = [ '#c8c8c8', '#e8b04a', '#52b7e8', '#b488f0', '#6cd39a', '#e8547a', '#ff8f5a' ];

/**
 * The live expression readout of a stream driven by muscles (index.html
 * #expression-readout, in the Performance panel): the nearest expression, its normalised
 * distance and confidence (Woodward et al. §10, `retarget.muscles.expressions`, read on
 * the server per frame), and a strip chart of the seven distances over the last frames,
 * the curve that dips being the expression shown (the paper's Fig. 12).
 */
export class ExpressionReadout {

	constructor() {

		this._canvas = $( 'expression-chart' );
		this._names = [];
		this._history = null; // Float32Array( HISTORY * E ), a ring of distance rows
		this._count = 0; // rows written in all
		this._drawing = 0; // requestAnimationFrame id, 0 when none is pending

	}

	/**
	 * Show the readout for these expressions, emptied unless they are the ones shown (a
	 * project's muscles were loaded, or played anew after an edit).
	 * @param {string[]} names - (E) expression names, the frames' distance order.
	 */
	setExpressions( names ) {

		if ( names.join() === this._names.join() ) return; // the same muscles played anew: keep the history
		this._names = names;
		this._history = new Float32Array( HISTORY * names.length );
		this._count = 0;
		$( 'expression-legend' ).replaceChildren( ...names.map( ( name, e ) => {

			const item = document.createElement( 'span' );
			const swatch = document.createElement( 'span' );
			swatch.className = 'swatch';
			swatch.style.background = COLORS[ e % COLORS.length ];
			item.append( swatch, name );
			return item;

		} ) );
		this._text( '–', '–', '–' );
		this._draw();

	}

	/**
	 * One contraction frame's reading.
	 * @param {{distances: Float32Array, label: number, confidence: number}} frame
	 */
	push( { distances, label, confidence } ) {

		const e = this._names.length;
		if ( e === 0 || distances.length !== e ) return; // frames of muscles not loaded here
		this._history.set( distances, ( this._count % HISTORY ) * e );
		this._count ++;
		this._text( this._names[ label ] ?? '?', distances[ label ].toFixed( 2 ), `${ Math.round( 100 * confidence ) } %` );
		if ( this._drawing === 0 ) this._drawing = requestAnimationFrame( () => this._draw() );

	}

	/** Show or hide the readout (it reads only frames driven by muscles). */
	setVisible( on ) {

		$( 'expression-readout' ).hidden = ! on;

	}

	/** Free the pending redraw. */
	dispose() {

		cancelAnimationFrame( this._drawing );

	}

	_text( label, distance, confidence ) {

		$( 'expression-label' ).textContent = label;
		$( 'expression-distance' ).textContent = distance;
		$( 'expression-confidence' ).textContent = confidence;

	}

	/** The seven curves, oldest frame on the left, distance 0 at the bottom. */
	_draw() {

		this._drawing = 0;
		const canvas = this._canvas, g = canvas.getContext( '2d' );
		const { width, height } = canvas;
		g.clearRect( 0, 0, width, height );
		const e = this._names.length, n = Math.min( this._count, HISTORY );
		if ( n < 2 ) return;
		const first = this._count - n;
		let top = 1; // distances are normalised: 1 is a typical spread, the scale grows past it
		for ( let i = 0; i < n * e; i ++ ) top = Math.max( top, this._history[ i ] );
		for ( let k = 0; k < e; k ++ ) {

			g.strokeStyle = COLORS[ k % COLORS.length ];
			g.lineWidth = 1.5;
			g.beginPath();
			for ( let i = 0; i < n; i ++ ) {

				const row = ( ( first + i ) % HISTORY ) * e;
				const x = i / ( HISTORY - 1 ) * width, y = height - 2 - this._history[ row + k ] / top * ( height - 4 );
				if ( i === 0 ) g.moveTo( x, y );
				else g.lineTo( x, y );

			}

			g.stroke();

		}

	}

}
