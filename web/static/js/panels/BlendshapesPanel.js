import { api } from '../net/api.js';
import { PaintedRig } from '../model/PaintedRig.js';
import { ArkitMorphs } from '../scene/ArkitMorphs.js';
import { WeightPainter } from '../tools/WeightPainter.js';
import { $, guarded } from './dom.js';

const SAVE_DELAY_MS = 300; // a gain is saved this long after the last change

/**
 * The Blendshapes panel (index.html #blendshapes-panel): ARKit's 52 blendshapes on the
 * face (issue 16; `retarget.arkit`, made by the server from the saved landmarks, a job
 * with a progress bar under *Generate*), one weight slider per shape that poses the face
 * in the shader as it moves (no server round trip), a gain per shape (what a stream driven
 * by ARKit multiplies the solved weight by), and *fix*: paint a mask on the face that
 * scales that one shape where it moves skin it should not (the rig painter's brushes, a
 * second WeightPainter on a one-joint PaintedRig). Gains, fixes and the rig the shapes are
 * made on are saved with the project (PUT .../arkit). While a source plays driven by
 * ARKit, the sliders follow its weights; it also loads the shapes for the stream's ARKit
 * mode (`load`).
 */
export class BlendshapesPanel {

	/**
	 * @param {import('../App.js').App} app
	 */
	constructor( app ) {

		this.app = app;
		/** The mask brush: the rig painter's class on a shape's fix. */
		this.painter = new WeightPainter( app.viewer, app.picker );
		this.settings = null; // GET .../arkit's settings {rig, gains, masks}
		this.morphs = null; // ArkitMorphs on the face
		this._loading = null; // Promise of the shown face's ArkitMorphs
		this._face = null;
		this._sliders = [];
		this._gains = [];
		this._fixing = - 1; // the shape whose fix is painted, -1: none
		this._timer = 0;
		this._saving = Promise.resolve();
		this._events = new AbortController();
		const signal = this._events.signal, errors = app.errors;
		$( 'arkit-details' ).addEventListener( 'toggle', () => {

			if ( $( 'arkit-details' ).open ) this.load().catch( ( error ) => error.notMade || errors.show( error ) ); // the note says it

		}, { signal } );
		$( 'arkit-generate' ).addEventListener( 'click', guarded( errors, () => this.generate() ), { signal } );
		$( 'arkit-reset' ).addEventListener( 'click', () => {

			for ( const slider of this._sliders ) slider.value = 0;
			this._pose();

		}, { signal } );
		$( 'arkit-fix-done' ).addEventListener( 'click', () => this.fix( - 1 ), { signal } );
		$( 'arkit-fix-clear' ).addEventListener( 'click', guarded( errors, () => this._clearFix() ), { signal } );
		$( 'arkit-fix-undo' ).addEventListener( 'click', () => this.painter.undo(), { signal } );
		$( 'arkit-fix-redo' ).addEventListener( 'click', () => this.painter.redo(), { signal } );
		for ( const input of document.querySelectorAll( 'input[name="arkit-brush"]' ) ) {

			input.addEventListener( 'change', () => this.painter.configure( { brush: input.value } ), { signal } );

		}

		$( 'arkit-radius' ).addEventListener( 'input', () => this.painter.configure( { radius: this._radiusScale() * Number( $( 'arkit-radius' ).value ) } ), { signal } );
		$( 'arkit-strength' ).addEventListener( 'input', () => this.painter.configure( { strength: Number( $( 'arkit-strength' ).value ) } ), { signal } );
		this.painter.addEventListener( 'change', () => this._showFixState(), { signal } );

	}

	/**
	 * The shown project's shapes on its face, fetched once (made by `generate` first).
	 * @returns {Promise<ArkitMorphs>} rejects saying why there are none (no landmarks, not
	 *   made yet, or made for older landmarks).
	 */
	load() {

		const app = this.app;
		if ( ! app.face || ! app.project?.landmarks ) return Promise.reject( new Error( 'ARKit shapes need a mesh with saved landmarks: they are made from them.' ) );
		if ( this._loading === null || this._face !== app.face ) {

			const current = app.ticket(), face = app.face;
			this._face = face;
			const loading = this._fetch( current, face );
			loading.catch( () => {

				if ( this._loading === loading ) this._loading = null; // a later call tries again

			} );
			this._loading = loading;

		}

		return this._loading;

	}

	/** Make the shapes (again) on the chosen rig, with the progress bar; then load them. */
	async generate() {

		const app = this.app, current = app.ticket();
		if ( ! app.project?.landmarks ) throw new Error( 'Save the landmarks first: the ARKit shapes are made from them.' );
		const job = await api.makeArkit( app.projectId, $( 'arkit-rig' ).value );
		await this._follow( job, current );
		if ( ! current() ) return;
		this.clear( { keepSettings: true } );
		await this.load();
		// a source driven by ARKit solves with the shapes it started with: new ones from now
		if ( app.sources.drive === 'arkit' ) app.stream?.send( { type: 'drive', drive: 'arkit' } );

	}

	/**
	 * Follow a played frame's weights (without posing the face again).
	 * @param {ArrayLike<number>} weights - (52)
	 */
	show( weights ) {

		if ( weights.length !== this._sliders.length || this._fixing >= 0 ) return;
		for ( let k = 0; k < weights.length; k ++ ) this._sliders[ k ].value = weights[ k ];

	}

	/**
	 * Paint shape `k`'s fix on the face (-1: stop): the shape is shown at weight 1 at least,
	 * and the brush lowers it (subtract), brings it back (add) or smooths its mask.
	 * @param {number} k
	 */
	fix( k ) {

		this._fixing = - 1;
		this.painter.setTarget( null, null );
		$( 'arkit-fix' ).hidden = k < 0;
		if ( k < 0 || ! this.morphs || ! this.app.face ) return;
		const morphs = this.morphs, face = this.app.face, v = morphs.nVertices;
		const rig = new PaintedRig( { nJoints: 1, nInfluences: 1, indices: new Uint16Array( v ), weights: morphs.mask( k ) }, { version: 0, painted_vertices: 0 } );
		this.painter.setTarget( face, {
			rig,
			show: ( vertices ) => {

				const mask = morphs.mask( k );
				for ( const i of vertices ) mask[ i ] = rig.weights[ i ];
				morphs.update( k, vertices );
				this._pose();

			},
			save: () => this._save(),
		} );
		this._fixing = k;
		if ( Number( this._sliders[ k ].value ) < 1 ) this._sliders[ k ].value = 1;
		this._pose();
		this.painter.configure( { brush: document.querySelector( 'input[name="arkit-brush"]:checked' ).value, strength: Number( $( 'arkit-strength' ).value ) } );
		$( 'arkit-radius' ).value = this.painter.radius / this._radiusScale();
		this.painter.setActive( true );
		$( 'arkit-fix-name' ).textContent = morphs.names[ k ];

	}

	/** Whether a changed gain waits to be saved. */
	get pending() {

		return this._timer !== 0;

	}

	/**
	 * Save the settings now (gains, fixes, rig).
	 * @param {{keepalive?: boolean}} [options] - keepalive: the page is being unloaded.
	 */
	flush( options ) {

		clearTimeout( this._timer );
		this._timer = 0;
		return this._save( options );

	}

	/**
	 * Forget the shapes (another project, new landmarks: made anew on request).
	 * @param {{keepSettings?: boolean}} [options]
	 */
	clear( { keepSettings = false } = {} ) {

		if ( this.pending ) this.flush().catch( ( error ) => this.app.errors.show( error ) );
		this.fix( - 1 );
		this.app.face?.setArkit( null );
		this.morphs?.dispose();
		this.morphs = null;
		this._loading = this._face = null;
		if ( ! keepSettings ) this.settings = null;
		this._sliders = [];
		this._gains = [];
		$( 'arkit-sliders' ).replaceChildren();
		$( 'arkit-note' ).textContent = '';
		$( 'arkit-progress' ).hidden = true;

	}

	dispose() {

		this._events.abort();
		this.painter.dispose();

	}

	async _fetch( current, face ) {

		const app = this.app, id = app.projectId;
		const state = await api.arkit( id );
		if ( ! current() ) throw new Error( 'Another project was opened.' );
		this.settings = state.settings;
		$( 'arkit-rig' ).value = state.settings.rig;
		if ( state.job ) await this._follow( state.job, current );
		else if ( state.state !== 'ready' ) {

			$( 'arkit-note' ).textContent = state.state === 'missing' ? 'No ARKit shapes yet: Generate makes the 52 from the landmarks.' : 'The landmarks, mesh or rig changed since the shapes were made: Generate makes them again.';
			throw Object.assign( new Error( `The ARKit shapes are ${ state.state }: press Generate in the Blendshapes panel first.` ), { notMade: true } );

		}

		const decoded = await api.arkitShapes( id );
		if ( ! current() || app.face !== face ) throw new Error( 'Another face was opened.' );
		const morphs = new ArkitMorphs( decoded, this.settings.masks );
		this.morphs?.dispose();
		this.morphs = morphs;
		face.setArkit( morphs );
		this._build( morphs, state.max_gain );
		return morphs;

	}

	/** Show a running job's progress until it ends; rejects when it fails. */
	async _follow( job, current ) {

		const bar = $( 'arkit-progress' ), note = $( 'arkit-note' ), button = $( 'arkit-generate' );
		bar.hidden = false;
		button.disabled = true;
		try {

			await api.waitJob( job.id, ( { progress } ) => {

				if ( ! current() ) return;
				bar.value = progress;
				note.textContent = `Making the 52 shapes… ${ Math.round( progress * 100 ) }%`;

			}, { what: 'Making the ARKit shapes' } );

		} finally {

			bar.hidden = true;
			button.disabled = false;

		}

	}

	_build( morphs, maxGain ) {

		$( 'arkit-note' ).textContent = `${ morphs.nTargets } ARKit shapes, made from the landmarks. Move a slider to see a shape; its gain scales it in a stream driven by ARKit; Fix paints where it should not move.`;
		const gains = this.settings.gains;
		this._sliders = [];
		this._gains = [];
		const rows = morphs.names.map( ( name, k ) => {

			const row = document.createElement( 'div' ), label = document.createElement( 'span' );
			row.className = 'arkit-shape';
			label.textContent = label.title = name;
			const slider = input( { type: 'range', min: 0, max: 1, step: 0.01, value: 0 }, `${ name } weight` );
			slider.dataset.shape = name;
			slider.addEventListener( 'input', () => this._pose() );
			const gain = input( { type: 'number', min: 0, max: maxGain, step: 0.05, value: gains[ name ] ?? 1 }, `${ name } gain` );
			gain.dataset.gain = name;
			gain.title = `Gain: the stream's ${ name } weight times this (0..${ maxGain })`;
			gain.addEventListener( 'change', () => this._setGain( name, gain ) );
			const fix = document.createElement( 'button' );
			fix.textContent = 'Fix';
			fix.dataset.fix = name;
			fix.title = `Paint where ${ name } should not move the face`;
			fix.addEventListener( 'click', () => this.fix( k ) );
			this._sliders.push( slider );
			this._gains.push( gain );
			row.append( label, slider, gain, fix );
			return row;

		} );
		$( 'arkit-sliders' ).replaceChildren( ...rows );

	}

	_setGain( name, field ) {

		const value = Number( field.value );
		if ( ! ( Number.isFinite( value ) && value >= 0 && value <= Number( field.max ) ) ) {

			field.value = this.settings.gains[ name ] ?? 1;
			this.app.errors.show( `The gain of ${ name } must be between 0 and ${ field.max }.` );
			return;

		}

		this.settings.gains[ name ] = value;
		clearTimeout( this._timer );
		this._timer = setTimeout( () => this.flush().catch( ( error ) => this.app.errors.show( error ) ), SAVE_DELAY_MS );

	}

	/** PUT the settings, one request at a time (the last always wins). */
	_save( { keepalive = false } = {} ) {

		const id = this.app.projectId;
		if ( ! this.settings || ! id ) return this._saving;
		// what is saved is read now: the project may change before the request goes
		const settings = { rig: this.settings.rig, gains: { ...this.settings.gains }, masks: this.morphs ? this.morphs.sparseMasks() : this.settings.masks };
		this._saving = this._saving.catch( () => {} ).then( async () => {

			const answer = await api.putArkit( id, settings, { keepalive } );
			if ( id === this.app.projectId ) this.settings = { ...answer.settings, gains: { ...answer.settings.gains, ...this.settings.gains } };

		} );
		return this._saving;

	}

	/** The fixed shape's mask back to 1 everywhere (saved). */
	async _clearFix() {

		const k = this._fixing;
		if ( k < 0 ) return;
		const mask = this.morphs.mask( k ), changed = [];
		mask.forEach( ( x, v ) => {

			if ( x !== 1 ) changed.push( v );

		} );
		mask.fill( 1 );
		this.morphs.update( k, changed );
		this.fix( k ); // a fresh brush history on the cleared mask
		await this._save();

	}

	_showFixState() {

		$( 'arkit-fix-state' ).textContent = this._fixing < 0 ? '' : this.painter.saveState;

	}

	/** Radius slider units: a thousandth of the face's size. */
	_radiusScale() {

		return ( this.app.face?.mesh.geometry.boundingSphere.radius ?? 1 ) / 1000;

	}

	/** Pose the face by the sliders. */
	_pose() {

		if ( this._sliders.length && this.app.face?.arkit ) this.app.face.setArkitWeights( this._sliders.map( ( slider ) => Number( slider.value ) ) );

	}

}

function input( properties, label ) {

	const element = document.createElement( 'input' );
	Object.assign( element, properties );
	element.setAttribute( 'aria-label', label );
	return element;

}
