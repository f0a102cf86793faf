import { api } from '../net/api.js';
import { PlayedMuscles } from '../model/PlayedMuscles.js';
import { $ } from './dom.js';

/**
 * The Muscles panel (index.html #muscles-panel): the face's 21 virtual muscles and jaw
 * (Woodward et al. §4, placed by the server from the saved landmarks), one slider per dof
 * that poses the face in the shader as it moves (no server round trip), so each muscle's
 * action can be seen; while a source plays driven by muscles the sliders follow its
 * contractions. It also loads the muscles for the stream's muscle mode (`load`).
 */
export class MusclesPanel {

	/**
	 * @param {import('../App.js').App} app
	 */
	constructor( app ) {

		this.app = app;
		this._loading = null; // Promise of the shown project's PlayedMuscles
		this._face = null; // the SkinnedFace they were loaded onto
		this._sliders = [];
		this._events = new AbortController();
		const signal = this._events.signal;
		$( 'muscle-dofs' ).addEventListener( 'toggle', () => {

			if ( $( 'muscle-dofs' ).open ) this.load().catch( ( error ) => this.app.errors.show( error ) );

		}, { signal } );
		$( 'muscles-reset' ).addEventListener( 'click', () => {

			for ( const slider of this._sliders ) slider.value = 0;
			this._pose();

		}, { signal } );

	}

	/**
	 * The shown project's muscles on its face, fetched once (placed by the server from
	 * the saved landmarks the first time).
	 * @returns {Promise<PlayedMuscles>} rejects when the project has no face or landmarks.
	 */
	load() {

		const app = this.app;
		if ( ! app.face || ! app.project?.landmarks ) return Promise.reject( new Error( 'Muscles need a mesh with saved landmarks: they are placed from them.' ) );
		if ( this._loading === null || this._face !== app.face ) {

			const current = app.ticket(), face = app.face;
			this._face = face;
			$( 'muscles-note' ).textContent = 'Placing the muscles…';
			const loading = api.musclesPlayed( app.projectId ).then( ( decoded ) => {

				const muscles = new PlayedMuscles( decoded );
				if ( current() && app.face === face && this._loading === loading ) { // not cleared meanwhile

					face.setMuscles( muscles );
					this._build( muscles );
					app.sources.expressions.setExpressions( muscles.expressions );

				}

				return muscles;

			} );
			loading.catch( () => {

				if ( this._loading !== loading ) return;
				this._loading = null; // a later call tries again
				$( 'muscles-note' ).textContent = '';

			} );
			this._loading = loading;

		}

		return this._loading;

	}

	/**
	 * Follow a played frame's contractions (without posing the face again).
	 * @param {ArrayLike<number>} contractions - (D)
	 */
	show( contractions ) {

		if ( contractions.length !== this._sliders.length ) return;
		for ( let d = 0; d < contractions.length; d ++ ) this._sliders[ d ].value = contractions[ d ];

	}

	/** Forget the muscles (another project, or new landmarks: placed anew). */
	clear() {

		this._loading = this._face = null;
		this._sliders = [];
		this.app.face?.setMuscles( null );
		this.app.sources.expressions.setExpressions( [] ); // the old muscles' readings
		$( 'muscle-sliders' ).replaceChildren();
		$( 'muscles-note' ).textContent = '';

	}

	dispose() {

		this._events.abort();

	}

	_build( muscles ) {

		$( 'muscles-note' ).textContent = `${ muscles.dofs.length - 1 } muscles and the jaw, placed from the landmarks. Move a slider to see its action.`;
		this._sliders = muscles.dofs.map( ( name, d ) => {

			const [ low, high ] = muscles.limits[ d ];
			const slider = document.createElement( 'input' );
			Object.assign( slider, { type: 'range', min: low, max: high, step: ( high - low ) / 200, value: 0 } );
			slider.dataset.dof = name;
			slider.setAttribute( 'aria-label', name.replace( /_/g, ' ' ) );
			slider.addEventListener( 'input', () => this._pose() );
			return slider;

		} );
		$( 'muscle-sliders' ).replaceChildren( ...this._sliders.map( ( slider ) => {

			const label = document.createElement( 'label' ), name = document.createElement( 'span' );
			label.className = 'muscle';
			name.textContent = name.title = slider.dataset.dof.replace( /_/g, ' ' );
			label.append( name, slider );
			return label;

		} ) );

	}

	/** Pose the face by the sliders. */
	_pose() {

		if ( this._sliders.length ) this.app.face?.setContractions( this._sliders.map( ( slider ) => Number( slider.value ) ) );

	}

}
