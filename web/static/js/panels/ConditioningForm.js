import { $ } from './dom.js';
import { regionColor } from '../scene/palette.js';

/**
 * The Conditioning form of the Performance panel (index.html #conditioning): the neutral
 * (first seconds or a frame), head-motion removal and whether the target turns with the
 * head, the jitter filter and its β, a gain and cutoff per region. A view of the page's
 * ConditioningSettings (`app.conditioning`), which it shows (`render`) and changes as the
 * user edits a field (on 'change', as the stream was always told).
 */
export class ConditioningForm {

	/**
	 * @param {import('../model/ConditioningSettings.js').ConditioningSettings} settings
	 */
	constructor( settings ) {

		this.settings = settings;
		this._events = new AbortController();
		$( 'conditioning' ).addEventListener( 'change', () => this._edited(), { signal: this._events.signal } );

	}

	/** Show the settings, with a row per region. */
	render() {

		const s = this.settings;
		$( 'neutral-mode' ).value = s.neutralMode;
		$( 'neutral-value' ).value = String( s.neutralValue );
		$( 'head-remove' ).checked = s.headPose === 'remove';
		$( 'head-apply' ).checked = s.applyRotation;
		$( 'filter' ).value = s.filter;
		$( 'oe-beta' ).value = String( s.beta );
		const table = $( 'gain-table' );
		table.querySelectorAll( 'tr[data-region]' ).forEach( ( r ) => r.remove() );
		for ( const region of s.regions ) {

			const row = document.createElement( 'tr' );
			row.dataset.region = region;
			row.innerHTML = `<td><span class="swatch"></span>${ region.replace( /_/g, ' ' ) }</td>
				<td><input class="gain" type="range" min="0" max="2" step="0.05" title="Gain: 1 = as performed"></td>
				<td><input class="cutoff" type="number" min="0.01" max="30" step="0.1" title="One Euro minimum cutoff (Hz): lower = smoother at rest"></td>`;
			row.querySelector( '.swatch' ).style.background = regionColor( region );
			row.querySelector( '.gain' ).value = s.gain[ region ] ?? 1;
			row.querySelector( '.cutoff' ).value = s.cutoff[ region ] ?? 1;
			table.append( row );

		}

	}

	/** Stop listening. */
	dispose() {

		this._events.abort();

	}

	/** A field changed: the settings take every field's value. */
	_edited() {

		const gain = {}, cutoff = {};
		for ( const row of $( 'gain-table' ).querySelectorAll( 'tr[data-region]' ) ) {

			gain[ row.dataset.region ] = Number( row.querySelector( '.gain' ).value );
			cutoff[ row.dataset.region ] = Number( row.querySelector( '.cutoff' ).value );

		}

		this.settings.set( {
			neutralMode: $( 'neutral-mode' ).value,
			neutralValue: Number( $( 'neutral-value' ).value ),
			headPose: $( 'head-remove' ).checked ? 'remove' : 'keep',
			applyRotation: $( 'head-apply' ).checked,
			filter: $( 'filter' ).value,
			beta: Number( $( 'oe-beta' ).value ),
			gain,
			cutoff,
		} );

	}

}
