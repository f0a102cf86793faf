/** The weight brushes: raise toward 1, lower toward 0, blend with neighbours, move toward a value. */
export const BRUSHES = [ 'add', 'subtract', 'smooth', 'set' ];

/**
 * The weight brush's settings, checked as they are set. Dispatches 'change' after
 * `configure`. The WeightPainter is one (it adds the rig, the cursor and pointer input).
 */
export class BrushSettings extends EventTarget {

	constructor() {

		super();
		/** One of BRUSHES. */
		this.brush = 'add';
		/** Brush radius, mesh units. */
		this.radius = 1;
		/** How far one stroke moves a weight (add, subtract: by up to this; set, smooth: this fraction of the way). */
		this.strength = 0.5;
		/** The set brush's target weight. */
		this.value = 1;
		/** Also paint the mirror joint at the mirrored point. */
		this.mirror = false;

	}

	/**
	 * Change brush settings.
	 * @param {{brush?: string, radius?: number, strength?: number, value?: number, mirror?: boolean}} settings
	 */
	configure( { brush, radius, strength, value, mirror } ) {

		const name = this.constructor.name;
		if ( brush !== undefined ) {

			if ( ! BRUSHES.includes( brush ) ) throw new RangeError( `${ name }.configure: brush must be one of ${ BRUSHES.join( ', ' ) }; got ${ brush }.` );
			this.brush = brush;

		}

		if ( radius !== undefined ) this.radius = positive( radius, `${ name }.configure: radius` );
		if ( strength !== undefined ) this.strength = unit( strength, `${ name }.configure: strength` );
		if ( value !== undefined ) this.value = unit( value, `${ name }.configure: value` );
		if ( mirror !== undefined ) this.mirror = Boolean( mirror );
		this.dispatchEvent( new Event( 'change' ) );

	}

}

function positive( x, what ) {

	if ( ! ( Number.isFinite( x ) && x > 0 ) ) throw new RangeError( `${ what } must be a positive number; got ${ x }.` );
	return x;

}

function unit( x, what ) {

	if ( ! ( Number.isFinite( x ) && x >= 0 && x <= 1 ) ) throw new RangeError( `${ what } must be in [0, 1]; got ${ x }.` );
	return x;

}
