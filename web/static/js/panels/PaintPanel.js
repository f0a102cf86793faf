import { WeightPainter } from '../tools/WeightPainter.js';
import { $, guarded } from './dom.js';

const RADIUS_RANGE = [ 0.005, 0.5 ]; // brush radius slider ends, in bounding-sphere radii
const RADIUS_STEPS = 1000; // the slider is logarithmic: fine control for small brushes
const SETTINGS_KEY = 'retarget.brush'; // brush settings kept across reloads (radius in face scales, `_faceScale`)
const DEFAULT_RADIUS = 1 / 3; // a new brush's radius, in face scales: a third of the eye-to-eye distance

/**
 * The rig panel's weight painting controls (index.html #paint-*): the Paint weights toggle,
 * feature, brush, radius, strength, set weight, mirror, undo, redo, resets and the save
 * state, driving a `WeightPainter`. While painting, the heat map shows the painted feature.
 */
export class PaintPanel {

	/**
	 * @param {{viewer: object, picker: object, face: object, projectId: string, project: object,
	 *   layouts: object[], errors: {show: function}}} app - the page (main.js).
	 */
	constructor( app ) {

		this.app = app;
		this.painter = new WeightPainter( app.viewer, app.picker );
		this._events = new AbortController();
		this._bind();
		this._update();

	}

	/** Whether pointer drags paint. */
	get active() {

		return this.painter.active;

	}

	/**
	 * Paint the app's face with this rig; null when the project has none (or it changed).
	 * Unsaved strokes of the previous rig are dropped: `flush` first.
	 * @param {{version: number, painted_vertices: number}|null} info - GET .../rig.
	 * @param {object|null} weights - `api.rigWeights`.
	 */
	setRig( info, weights ) {

		const app = this.app;
		const layout = app.layouts.find( ( l ) => l.name === app.project?.landmarks?.layout ) || null;
		const settings = localStorage.getItem( SETTINGS_KEY ); // before setRig's change event stores the current ones
		this.painter.setRig( weights && app.face, app.projectId, info, weights, layout );
		if ( weights && settings ) this._restoreSettings( settings );
		else if ( weights ) this.painter.configure( { radius: DEFAULT_RADIUS * this._faceScale() } );
		const names = [ ...$( 'heatmap-select' ).options ].filter( ( o ) => o.value !== '' );
		$( 'paint-joint' ).replaceChildren( ...names.map( ( o ) => new Option( o.textContent, o.value ) ) );
		this._update();

	}

	/** Save unsaved strokes now; the failure is shown, not thrown. */
	async flush( options ) {

		await this.painter.flush( options );

	}

	/**
	 * @param {KeyboardEvent} event
	 * @returns {boolean} whether painting took the key.
	 */
	key( event ) {

		return this.painter.key( event );

	}

	/** The viewport hint while painting. */
	hint() {

		const painter = this.painter;
		const name = $( 'paint-joint' ).selectedOptions[ 0 ]?.textContent ?? `feature ${ painter.joint }`;
		return `Drag on the face to ${ painter.brush } ${ name } · Ctrl+click picks the nearest feature · [ ] radius · Alt+drag orbits`;

	}

	/** Stop listening; free the painter. */
	dispose() {

		this._events.abort();
		this.painter.dispose();

	}

	_bind() {

		const painter = this.painter, signal = this._events.signal;
		const guard = ( fn ) => guarded( this.app.errors, fn );

		$( 'paint-toggle' ).addEventListener( 'click', () => {

			painter.setActive( ! painter.active );
			if ( painter.active ) this._showHeatmap();

		}, { signal } );
		$( 'paint-joint' ).addEventListener( 'change', ( event ) => painter.setJoint( Number( event.target.value ) ), { signal } );
		$( 'heatmap-select' ).addEventListener( 'change', ( event ) => {

			if ( painter.active && event.target.value !== '' ) painter.setJoint( Number( event.target.value ) );

		}, { signal } );
		for ( const input of document.querySelectorAll( 'input[name="paint-brush"]' ) ) {

			input.addEventListener( 'change', () => painter.configure( { brush: input.value } ), { signal } );

		}

		$( 'paint-radius' ).addEventListener( 'input', ( event ) => painter.configure( { radius: this._radiusOf( Number( event.target.value ) ) } ), { signal } );
		$( 'paint-strength' ).addEventListener( 'input', ( event ) => painter.configure( { strength: Number( event.target.value ) } ), { signal } );
		$( 'paint-value' ).addEventListener( 'input', ( event ) => painter.configure( { value: Number( event.target.value ) } ), { signal } );
		$( 'paint-mirror' ).addEventListener( 'change', ( event ) => painter.configure( { mirror: event.target.checked } ), { signal } );
		$( 'paint-undo' ).addEventListener( 'click', () => painter.undo(), { signal } );
		$( 'paint-redo' ).addEventListener( 'click', () => painter.redo(), { signal } );
		$( 'paint-retry' ).addEventListener( 'click', guard( () => painter.retry() ), { signal } );
		$( 'paint-reset-joint' ).addEventListener( 'click', guard( () => painter.reset( [ painter.joint ] ) ), { signal } );
		$( 'paint-reset-all' ).addEventListener( 'click', guard( () => painter.reset( null ) ), { signal } );
		painter.addEventListener( 'change', () => this._update(), { signal } );
		window.addEventListener( 'beforeunload', () => {

			if ( painter.saveState === 'unsaved' ) painter.flush( { keepalive: true } );

		}, { signal } );

	}

	/** The face's heat map shows the painted feature. */
	_showHeatmap() {

		const face = this.app.face, joint = this.painter.joint;
		if ( ! face || ! face.nJoints ) return;
		face.setHeatmap( joint );
		$( 'heatmap-select' ).value = String( joint );
		this.app.rig?.legend.update(); // the painted weights' range

	}

	_update() {

		const painter = this.painter, rig = painter.rig;
		const toggle = $( 'paint-toggle' );
		toggle.disabled = ! rig;
		toggle.setAttribute( 'aria-pressed', String( painter.active ) );
		toggle.classList.toggle( 'primary', painter.active );
		$( 'paint-panel' ).hidden = ! painter.active;
		$( 'paint-state' ).textContent = rig && rig.painted ? `painted · ${ rig.painted.toLocaleString( 'en' ) } vertices` : '';
		if ( ! rig ) return;

		$( 'paint-joint' ).value = String( painter.joint );
		for ( const input of document.querySelectorAll( 'input[name="paint-brush"]' ) ) input.checked = input.value === painter.brush;
		$( 'paint-value' ).closest( '.row' ).hidden = painter.brush !== 'set';
		$( 'paint-radius' ).value = String( this._sliderOf( painter.radius ) );
		$( 'paint-radius-out' ).textContent = `${ painter.radius.toPrecision( 2 ) } units`;
		$( 'paint-strength' ).value = String( painter.strength );
		$( 'paint-strength-out' ).textContent = painter.strength.toFixed( 2 );
		$( 'paint-value' ).value = String( painter.value );
		$( 'paint-value-out' ).textContent = painter.value.toFixed( 2 );
		$( 'paint-mirror' ).checked = painter.mirror;
		$( 'paint-mirror' ).disabled = ! painter.canMirror;
		$( 'paint-undo' ).disabled = ! painter.canUndo;
		$( 'paint-redo' ).disabled = ! painter.canRedo;

		localStorage.setItem( SETTINGS_KEY, JSON.stringify( {
			brush: painter.brush, strength: painter.strength, value: painter.value, mirror: painter.mirror,
			radius: painter.radius / this._faceScale(),
		} ) );

		const state = painter.saveState;
		const note = $( 'paint-note' );
		note.textContent = {
			saved: rig.painted ? `Saved · ${ rig.painted.toLocaleString( 'en' ) } vertices differ from the automatic rig.` : 'Saved · the automatic rig.',
			unsaved: 'Unsaved strokes…',
			saving: 'Saving…',
			failed: `Not saved: ${ painter.saveError } · your strokes are kept; Retry saves them.`,
		}[ state ];
		note.className = 'note' + ( state === 'failed' ? ' warn' : '' );
		note.dataset.state = state;
		$( 'paint-retry' ).hidden = state !== 'failed';
		if ( painter.active ) this._showHeatmap();

	}

	/**
	 * Brush settings stored by an earlier session.
	 * @param {string|null} text - their JSON.
	 */
	_restoreSettings( text ) {

		try {

			const settings = JSON.parse( text );
			if ( settings ) this.painter.configure( { ...settings, radius: settings.radius * this._faceScale() } );

		} catch ( error ) {

			console.warn( 'retarget: stored brush settings ignored:', error.message );

		}

	}

	/**
	 * The face's scale, mesh units: the distance between the eye centres of its landmarks
	 * (the means of the placed `eye_left*` and `eye_right*` points), so a brush fits a face
	 * whatever its units; without eye points, a third of the bounding-sphere radius.
	 */
	_faceScale() {

		const { layout, points } = this.app.landmarks, picker = this.app.picker;
		const centre = ( side ) => {

			const placed = ( layout?.points ?? [] ).map( ( p, i ) => p.name.startsWith( `eye_${ side }` ) && points[ i ] ? picker.position( i ) : null ).filter( Boolean );
			return placed.length ? placed.reduce( ( sum, p ) => sum.add( p ), placed[ 0 ].clone().setScalar( 0 ) ).divideScalar( placed.length ) : null;

		};

		const left = centre( 'left' ), right = centre( 'right' );
		const distance = left && right ? left.distanceTo( right ) : 0;
		return distance > 0 ? distance : this._boundsRadius() / 3;

	}

	_boundsRadius() {

		return this.app.face?.mesh.geometry.boundingSphere.radius ?? 1;

	}

	_radiusOf( step ) {

		const [ low, high ] = RADIUS_RANGE;
		return this._boundsRadius() * low * ( high / low ) ** ( step / RADIUS_STEPS );

	}

	_sliderOf( radius ) {

		const [ low, high ] = RADIUS_RANGE;
		const t = Math.log( radius / ( this._boundsRadius() * low ) ) / Math.log( high / low );
		return Math.round( Math.min( 1, Math.max( 0, t ) ) * RADIUS_STEPS );

	}

}
