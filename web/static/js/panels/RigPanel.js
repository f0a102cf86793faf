import { ApiError, api } from '../net/api.js';
import { $, guarded, option } from './dom.js';
import { HeatmapLegend } from './HeatmapLegend.js';

// the bar's share of the server's job; the rest is loading the rig onto the face
const SERVER_SHARE = 0.95;

/**
 * The Rig panel (index.html #rig-panel): the deformer and *Compute* (a server job, its
 * progress in the bar, full once the rig is on the face), the rig's badge, and the heat
 * map of one feature's weights with its legend (HeatmapLegend).
 * Weight painting is its own panel (PaintPanel) inside it.
 */
export class RigPanel {

	/**
	 * @param {import('../App.js').App} app
	 */
	constructor( app ) {

		this.app = app;
		/** GET /api/projects/{id}/rig of the shown project, or null. */
		this.info = null;
		this._job = null; // AbortController of the rig job being followed
		this.legend = new HeatmapLegend( app );
		this._events = new AbortController();
		this._bind();

	}

	/**
	 * The rig methods the server offers.
	 * @param {{rig_methods: string[], default_rig_method: string}} info - GET /api/info.
	 */
	setMethods( info ) {

		const methods = $( 'rig-method' );
		methods.replaceChildren( ...info.rig_methods.map( ( m ) => option( m, m ) ) );
		methods.value = info.default_rig_method;

	}

	/**
	 * The heat map's features: the saved landmarks' points (the rig's joints).
	 * @param {object|null} project
	 * @param {{n_points: number, points: Array<{name: string}>}|null} layout - the saved landmarks' layout.
	 */
	setJoints( project, layout ) {

		const heatmap = $( 'heatmap-select' );
		const n = project?.landmarks?.n_points;
		const names = ! n ? [] : layout && layout.n_points === n ? layout.points.map( ( p ) => p.name ) : Array.from( { length: n }, ( _, j ) => `feature ${ j }` );
		heatmap.replaceChildren( option( '', 'off' ), ...names.map( ( name, j ) => option( String( j ), `${ j } · ${ name }` ) ) );
		heatmap.disabled = ! this.app.face?.nJoints;
		this.legend.update();

	}

	/**
	 * Load the project's rig onto the face and the painter.
	 * @param {() => boolean} current - false once another project is being opened.
	 */
	async load( current ) {

		const app = this.app, id = app.projectId;
		const [ info, weights ] = await Promise.all( [ api.rig( id ), api.rigWeights( id ) ] );
		if ( ! current() || ! app.face ) return;
		app.face.setRig( weights );
		app.face.setHeatmap( null );
		$( 'heatmap-select' ).value = '';
		$( 'heatmap-select' ).disabled = false;
		this.info = info;
		this.update();
		app.paint.setRig( info, weights );
		this.legend.update();

	}

	/** The project's rig is gone (another project, new landmarks): stop following its job. */
	clear() {

		this._job?.abort();
		this._job = null;
		this.info = null;
		$( 'rig-progress' ).value = 0;
		$( 'rig-message' ).textContent = '';
		$( 'heat-legend' ).hidden = true;

	}

	/** The rig badge: method, joints and influences, or 'none'. */
	update() {

		const project = this.app.project;
		const info = project?.rig ? this.info : null;
		$( 'rig-info' ).textContent = info ? `${ info.method } · ${ info.n_joints } joints · k ${ info.n_influences }` : project?.mesh ? 'none' : '';
		$( 'rig-info' ).className = 'badge' + ( info ? ' good' : '' );
		if ( info ) $( 'rig-method' ).value = info.method;

	}

	/** Compute the rig with the chosen method (saving the landmarks on screen first) and load it. */
	async compute() {

		const app = this.app;
		if ( ! app.project?.mesh ) throw new ApiError( 0, 'Upload a mesh first.' );
		if ( app.landmarks.dirty || ! app.project.landmarks ) {

			// the rig is built from the saved landmarks: save the ones on screen first
			await app.marks.save();

		}

		const id = app.projectId, current = app.ticket();
		const method = $( 'rig-method' ).value;
		const bar = $( 'rig-progress' ), message = $( 'rig-message' ), button = $( 'rig-button' );
		button.disabled = true;
		bar.value = 0;
		message.textContent = `Starting ${ method }…`;
		const t0 = performance.now();
		this._job?.abort(); // a newer rig replaces the one followed so far
		const follow = this._job = new AbortController();
		try {

			const started = await api.startRig( id, method );
			let job;
			try {

				job = await api.waitJob( started.id, ( { progress, detail } ) => {

					bar.value = SERVER_SHARE * progress;
					message.textContent = `${ Math.round( progress * 100 ) }% · ${ detail || method }`;

				}, { what: `Rig (${ method })`, signal: follow.signal } );

			} catch ( error ) {

				if ( follow.signal.aborted ) return; // another project, or another rig
				bar.value = 0;
				message.textContent = 'Failed.';
				throw error;

			}

			if ( ! current() ) return;
			app.project = await api.project( id );
			await this.load( current );
			app.live.update();
			// full only now: a full bar means the rig is on the face and plays
			bar.value = 1;
			message.textContent = `${ job.detail || 'done' } · ${ ( ( performance.now() - t0 ) / 1000 ).toFixed( 1 ) } s`;

		} finally {

			if ( current() ) button.disabled = false;

		}

	}

	/** Stop listening. */
	dispose() {

		this._events.abort();
		this._job?.abort();

	}

	_bind() {

		const signal = this._events.signal;
		$( 'rig-button' ).addEventListener( 'click', guarded( this.app.errors, () => this.compute() ), { signal } );
		$( 'heatmap-select' ).addEventListener( 'change', ( event ) => {

			this.app.face?.setHeatmap( event.target.value === '' ? null : Number( event.target.value ) );
			this.legend.update();

		}, { signal } );

	}

}
