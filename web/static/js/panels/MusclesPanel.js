import { api } from '../net/api.js';
import { PlayedMuscles } from '../model/PlayedMuscles.js';
import { MuscleHandles } from '../scene/MuscleHandles.js';
import { MuscleEditor } from '../tools/MuscleEditor.js';
import { $, guarded, option } from './dom.js';

/**
 * The Muscles panel (index.html #muscles-panel): the face's 21 virtual muscles and jaw
 * (Woodward et al. §4, placed by the server from the saved landmarks), one slider per dof
 * that poses the face in the shader as it moves (no server round trip), so each muscle's
 * action can be seen; while a source plays driven by muscles the sliders follow its
 * contractions. It also loads the muscles for the stream's muscle mode (`load`).
 *
 * A muscle chosen under *Edit* shows its handles on the view (MuscleHandles): dragging
 * one (MuscleEditor) or scaling its zone saves the muscles as the user's
 * (PUT .../muscles) and plays them again at the sliders' pose.
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
		this.editor = new MuscleEditor( app.viewer );
		this._handles = null; // MuscleHandles on the face while a muscle is edited
		this._geometry = null; // GET .../muscles' JSON, which edits change and PUT saves
		this._zone = null; // the edited muscle's zone when chosen, which the Zone slider scales
		this._events = new AbortController();
		const signal = this._events.signal;
		const errors = app.errors;
		$( 'muscle-edit' ).addEventListener( 'change', guarded( errors, () => this.edit( $( 'muscle-edit' ).value || null ) ), { signal } );
		$( 'muscle-zone' ).addEventListener( 'change', guarded( errors, () => this._scaleZone( Number( $( 'muscle-zone' ).value ) ) ), { signal } );
		this.editor.addEventListener( 'change', guarded( errors, ( event ) => this._move( event.detail ) ), { signal } );
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

	/**
	 * Show the handles of muscle `name` for dragging (null: none).
	 * @param {string|null} name - one of the muscles' names.
	 */
	async edit( name ) {

		$( 'muscle-edit' ).value = name ?? '';
		this._showHandles( null );
		if ( name === null ) return;
		const current = this.app.ticket();
		await this.load();
		const geometry = this._geometry ?? await api.muscles( this.app.projectId );
		if ( ! current() || $( 'muscle-edit' ).value !== name ) return;
		this._geometry = geometry;
		this._showHandles( name );

	}

	/** Forget the muscles (another project, or new landmarks: placed anew). */
	clear() {

		this._showHandles( null );
		this._geometry = null;
		$( 'muscle-edit' ).replaceChildren( option( '', 'none' ) );
		this._loading = this._face = null;
		this._sliders = [];
		this.app.face?.setMuscles( null );
		this.app.sources.expressions.setExpressions( [] ); // the old muscles' readings
		$( 'muscle-sliders' ).replaceChildren();
		$( 'muscles-note' ).textContent = '';

	}

	dispose() {

		this._events.abort();
		this.editor.dispose();
		this._showHandles( null );

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
		const editing = $( 'muscle-edit' ).value;
		$( 'muscle-edit' ).replaceChildren( option( '', 'none' ), ...muscles.dofs.slice( 0, - 1 ).map( ( name ) => option( name, name.replace( /_/g, ' ' ) ) ) );
		$( 'muscle-edit' ).value = muscles.dofs.includes( editing ) ? editing : '';
		$( 'muscle-sliders' ).replaceChildren( ...this._sliders.map( ( slider ) => {

			const label = document.createElement( 'label' ), name = document.createElement( 'span' );
			label.className = 'muscle';
			name.textContent = name.title = slider.dataset.dof.replace( /_/g, ' ' );
			label.append( name, slider );
			return label;

		} ) );

	}

	/** The edited muscle's handles on the face (null: none), and the Zone slider for it. */
	_showHandles( name ) {

		this._handles?.dispose();
		this._handles = this.editor.handles = null;
		const zone = $( 'muscle-zone' );
		zone.value = 1;
		zone.disabled = true;
		const muscle = name === null ? null : this._geometry?.muscles.find( ( m ) => m.name === name );
		if ( ! muscle || ! this.app.face ) return;
		this._handles = this.editor.handles = new MuscleHandles( this.app.face.mesh );
		this._handles.show( muscle.kind === 'linear' ? { origin: muscle.origin, insertion: muscle.insertion } : { centre: muscle.centre } );
		this._zone = muscle.kind === 'linear' ? { rs: muscle.rs, rf: muscle.rf } : { radii: [ ...muscle.radii ] };
		zone.disabled = false;

	}

	/** A handle was let go: the muscle's point moves there. */
	async _move( { name, position } ) {

		this._geometry.muscles.find( ( m ) => m.name === $( 'muscle-edit' ).value )[ name ] = position;
		await this._save();

	}

	/** The Zone slider: the edited muscle's zone at `scale` times its size when chosen. */
	async _scaleZone( scale ) {

		const muscle = this._geometry.muscles.find( ( m ) => m.name === $( 'muscle-edit' ).value );
		if ( 'rs' in this._zone ) Object.assign( muscle, { rs: this._zone.rs * scale, rf: this._zone.rf * scale } );
		else muscle.radii = this._zone.radii.map( ( r ) => r * scale );
		await this._save();

	}

	/**
	 * Save the edited muscles as the user's and play them again at the sliders' pose; a
	 * refused edit (the server says why) goes back to the saved muscles.
	 */
	async _save() {

		const app = this.app, current = app.ticket(), name = $( 'muscle-edit' ).value;
		const pose = this._sliders.map( ( slider ) => Number( slider.value ) );
		try {

			this._geometry = await api.putMuscles( app.projectId, this._geometry );

		} catch ( error ) {

			this._geometry = await api.muscles( app.projectId );
			if ( current() ) this._showHandles( name );
			throw error;

		}

		if ( ! current() ) return;
		this._loading = null; // the played form follows the new geometry
		await this.load();
		pose.forEach( ( value, d ) => {

			this._sliders[ d ].value = value;

		} );
		this._pose();
		$( 'muscles-note' ).textContent = `Saved ${ name.replace( /_/g, ' ' ) } (your muscles: new landmarks no longer place them anew).`;

	}

	/** Pose the face by the sliders. */
	_pose() {

		if ( this._sliders.length ) this.app.face?.setContractions( this._sliders.map( ( slider ) => Number( slider.value ) ) );

	}

}
