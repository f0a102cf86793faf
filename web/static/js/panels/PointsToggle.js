import { $ } from './dom.js';

/**
 * The view's *Show points* box (index.html #show-points): the feature points are drawn on
 * the face while nothing plays and hidden while a source plays (the face's motion is then
 * what the user watches); once the user ticks or unticks the box, the box alone decides,
 * playing or not.
 */
export class PointsToggle {

	/**
	 * @param {{markers: import('../scene/LandmarkMarkers.js').LandmarkMarkers}} picker - whose markers it shows.
	 */
	constructor( picker ) {

		this.picker = picker;
		/** Whether the user chose; then playing no longer hides or shows the points. */
		this.chosen = false;
		this._events = new AbortController();
		$( 'show-points' ).addEventListener( 'change', () => {

			this.chosen = true;
			this._apply();

		}, { signal: this._events.signal } );
		this._apply();

	}

	/**
	 * A source started or stopped playing.
	 * @param {boolean} playing
	 */
	setPlaying( playing ) {

		if ( this.chosen ) return;
		$( 'show-points' ).checked = ! playing;
		this._apply();

	}

	/** Stop listening. */
	dispose() {

		this._events.abort();

	}

	_apply() {

		this.picker.markers.setShown( $( 'show-points' ).checked );

	}

}
