import { withGuidePositions } from './model/customLayout.js';
import { api } from './net/api.js';
import { DEFAULT_LAYOUT } from './panels/LandmarksPanel.js';
import { projectFromHash } from './panels/ProjectBar.js';
import { $ } from './panels/dom.js';
import { SkinnedFace } from './scene/SkinnedFace.js';

/**
 * The page's state and its project's life: which project is shown, its face, the layouts
 * and limits the server knows; opening a project loads its mesh onto a SkinnedFace, its
 * landmarks, rig, takes and stream into the panels, and closing it takes them out again.
 * The panels (main.js builds them and hands them over with `setPanels`) draw and edit;
 * the models they share live here: `landmarks` (LandmarkSet), `conditioning`
 * (ConditioningSettings) and `regions` (RegionMask), the last two saved with the project
 * (`projectSettings`).
 *
 * One App per page, `window.app` for the end-to-end tests: {viewer, face, stream,
 * projectId, picker, paint, sources, errors, ready, animation}.
 */
export class App {

	/**
	 * @param {object} parts
	 * @param {import('./scene/Viewer.js').Viewer} parts.viewer
	 * @param {import('./panels/ErrorBanner.js').ErrorBanner} parts.errors
	 * @param {import('./model/LandmarkSet.js').LandmarkSet} parts.landmarks
	 * @param {import('./tools/LandmarkPicker.js').LandmarkPicker} parts.picker
	 * @param {import('./model/ConditioningSettings.js').ConditioningSettings} parts.conditioning
	 * @param {import('./model/RegionMask.js').RegionMask} parts.regions
	 * @param {import('./net/ProjectSettings.js').ProjectSettings} parts.projectSettings
	 */
	constructor( { viewer, errors, landmarks, picker, conditioning, regions, projectSettings } ) {

		this.viewer = viewer;
		this.errors = errors;
		this.landmarks = landmarks;
		this.picker = picker;
		this.conditioning = conditioning;
		this.regions = regions;
		this.projectSettings = projectSettings;
		/** @type {SkinnedFace|null} */
		this.face = null;
		this.projectId = null;
		this.project = null;
		this.projects = [];
		this.layouts = [];
		this.info = null; // GET /api/info: upload limits, mesh formats, rig methods
		/** Settles once the page (or the project being opened) is shown. */
		this.ready = Promise.resolve();
		/** Settles once what follows the last upload (`animateUpload`) has ended, however. */
		this.animation = Promise.resolve();
		this._open = 0; // bumps on every project switch: late answers for an old project are dropped

	}

	/**
	 * The panels, each a view of part of the page.
	 * @param {{bar: object, upload: object, marks: object, customLayout: object, rig: object, mouth: object,
	 *   paint: object, muscles: object, blendshapes: object, sources: object, live: object,
	 *   exports: object}} panels
	 */
	setPanels( panels ) {

		Object.assign( this, panels );

	}

	/** The project's stream (the Live panel's), or null. */
	get stream() {

		return this.live?.stream ?? null;

	}

	/** Whether a source is playing on the stream. */
	get streaming() {

		return this.live?.streaming ?? false;

	}

	/**
	 * A check that the project shown now is still the one shown when it was made.
	 * @returns {() => boolean}
	 */
	ticket() {

		const ticket = this._open;
		return () => ticket === this._open;

	}

	/** Load what the server knows and show the project the address names (or the first). */
	async start() {

		const done = this._busy();
		try {

			[ this.info, this.layouts ] = await Promise.all( [ api.info(), api.layouts() ] );
			this.rig.setMethods( this.info );
			this.upload.setInfo( this.info );
			this.landmarks.setLayouts( this.layouts );
			this.marks.setLayouts( this.layouts );
			await this.refreshProjects();
			const wanted = projectFromHash();
			const id = this.projects.some( ( p ) => p.id === wanted ) ? wanted : this.projects[ 0 ]?.id;
			if ( wanted && id !== wanted ) this.errors.show( `There is no project with id ${ wanted }; showing ${ this.projects.find( ( p ) => p.id === id )?.name || 'none' } instead.` );
			if ( id ) await this.openProject( id, { force: true } );
			else this._showProject( null );

		} catch ( error ) {

			this.errors.show( error );

		} finally {

			done();

		}

	}

	/**
	 * The layouts a project can use: the built-in ones and its custom ones (those saved
	 * with no reference positions get stand-ins for the guide, `withGuidePositions`).
	 * @param {string} id
	 */
	async loadLayouts( id ) {

		const layouts = ( await api.projectLayouts( id ) ).map( withGuidePositions );
		if ( id !== this.projectId ) return;
		this.layouts = layouts;
		this.landmarks.setLayouts( layouts );
		this.marks.setLayouts( layouts );

	}

	/** List the projects again. */
	async refreshProjects() {

		this.projects = await api.projects();
		this.bar.setProjects( this.projects, this.projectId );

	}

	/**
	 * Show a project: its mesh, landmarks (or the unsaved draft), rig and stream.
	 * @param {string} id
	 * @param {{force?: boolean}} [options] - force: reload even if it is the current one.
	 * @returns {Promise<boolean>} false when the switch was cancelled.
	 */
	async openProject( id, { force = false } = {} ) {

		if ( id === this.projectId && ! force ) return true;
		const done = this._busy();
		const ticket = ++ this._open, current = () => ticket === this._open;
		try {

			await this.projectSettings.flush(); // the old project's draft and settings
			await this.paint.flush();
			this.closeProject();
			this.projectId = id;
			this.bar.select( id );
			const project = await api.project( id );
			if ( ! current() ) return false;
			this.project = project;
			this._showProject( project );
			if ( project.mesh ) {

				$( 'hint' ).textContent = 'Loading the mesh…';
				const arrays = await api.meshArrays( id );
				const face = await SkinnedFace.create( arrays );
				if ( arrays.textured ) face.setTexture( await api.meshTexture( id ) );
				if ( ! current() ) {

					face.dispose();
					return false;

				}

				this.face = face;
				this.viewer.setObject( face.mesh );
				this.viewer.setWireframe( $( 'wireframe' ).checked );
				this.showSurface( { reset: true } );
				this.picker.setMesh( face.mesh );
				$( 'mesh-info' ).textContent = meshInfo( project.mesh, arrays.positions );

			}

			this.regions.load( project.settings?.held_regions ?? null );
			await this.loadLayouts( id );
			if ( ! current() ) return false;
			await this.customLayout.setProject();
			await this.marks.load( project, current );
			if ( ! current() ) return false;
			this._showSavedLandmarks( project );
			if ( project.rig && this.face ) await this.rig.load( current );
			if ( ! current() ) return false;
			this.live.update();
			if ( project.landmarks ) this.live.connect();
			await this.sources.setProject( project );
			await this.exports.setProject( project );
			await this.mouth.load( project, current );
			return true;

		} catch ( error ) {

			if ( current() ) this.errors.show( error );
			return false;

		} finally {

			if ( current() ) {

				this.updateHint();
				this.live.update();
				done();

			}

		}

	}

	/**
	 * Draw the face with its texture or plain shaded, as the Texture / Shaded switch says;
	 * the switch shows only for a face with a texture.
	 * @param {{reset?: boolean}} [options] - reset: back to the default, the texture.
	 */
	showSurface( { reset = false } = {} ) {

		const textured = this.face?.hasTexture ?? false;
		$( 'surface-switch' ).hidden = ! textured;
		if ( reset ) $( 'surface-texture' ).checked = true;
		this.face?.setTextured( $( 'surface-texture' ).checked );

	}

	/** Drop everything of the current project from the page (not from the server). */
	closeProject() {

		this.projectSettings.cancel(); // what was not sent belongs to this project
		this.rig.clear();
		this.mouth.clear();
		this.muscles.clear();
		this.blendshapes.clear();
		this.live.close();
		this.sources.stopWebcam();
		this.exports.setProject( null );
		this.picker.setMesh( null );
		this.picker.setDisplacements( null );
		this.paint.setRig( null, null );
		if ( this.face ) {

			this.viewer.setObject( null );
			this.face.dispose();
			this.face = null;

		}

		this.project = null;
		$( 'mesh-info' ).textContent = '';
		$( 'surface-switch' ).hidden = true;
		this.marks.clear();

	}

	/** The shown project was deleted: show the first one left, or none. */
	async forgetProject() {

		this.landmarks.load( this.landmarks.state.layout || DEFAULT_LAYOUT ); // nothing left to save
		this.closeProject();
		this.projectId = null;
		await this.refreshProjects();
		if ( this.projects.length ) {

			await this.openProject( this.projects[ 0 ].id );

		} else {

			this.bar.select( null );
			this._showProject( null );
			this.live.update();

		}

	}

	/**
	 * A mesh was uploaded into the shown project: its points are found, the face rigged and
	 * the built-in demo played, with no click (each step only while the user has not taken
	 * over: placed, moved or chosen anything, or started a source). A failure shows in the
	 * error banner (no face on the mesh is only a note in the Landmarks panel).
	 * @returns {Promise<void>} `animation`, which never rejects.
	 */
	animateUpload() {

		this.animation = this._animate( { auto: true } ).catch( ( error ) => this.errors.show( error ) );
		return this.animation;

	}

	/**
	 * The user switched to a layout whose points are found, not placed (mediapipe468): as
	 * after an upload, they are found (replacing the points shown, undoably), the face
	 * rigged and the demo played, with no click.
	 * @returns {Promise<void>} `animation`, which never rejects.
	 */
	animateFound() {

		this.animation = this._animate( { confirmed: true } ).catch( ( error ) => this.errors.show( error ) );
		return this.animation;

	}

	async _animate( findOptions ) {

		const current = this.ticket();
		if ( ! await this.marks.find( findOptions ) || ! current() ) return;
		const found = this.landmarks.state;
		await this.rig.compute();
		if ( ! current() || this.landmarks.state !== found || this.streaming || ! this.project?.rig ) return;
		if ( $( 'source-select' ).value === 'demo' ) await this.live.play();

	}

	/** New landmarks were saved: the old rig is gone and the stream drives the new points. */
	landmarksSaved() {

		this.rig.info = null;
		this.face?.setRig( null );
		this.face?.setHeatmap( null );
		this.paint.setRig( null, null );
		this.muscles.clear(); // placed anew from the new landmarks
		this.blendshapes.clear(); // stale: made anew on request
		this._showSavedLandmarks( this.project );
		this.mouth.load( this.project, this.ticket() ).catch( ( error ) => this.errors.show( error ) );
		this.rig.update();
		this.live.connect();
		this.live.update();

	}

	/** The landmarks changed (or were saved): their panel, the hint and the Live note show it. */
	showLandmarks() {

		this.marks.update();
		this.updateHint();
		this.live.update();

	}

	/** The viewport's hint: what a click or drag does now. */
	updateHint( hovered = this.picker.hovered ) {

		let text = '';
		if ( ! this.project ) text = 'Create a project to start.';
		else if ( ! this.face ) text = '';
		else if ( this.paint.active ) text = this.paint.hint();
		else text = this.marks.hint( hovered );
		$( 'hint' ).textContent = text;

	}

	/** `ready` pends until the returned function is called. */
	_busy() {

		let resolve;
		this.ready = new Promise( ( r ) => ( resolve = r ) );
		return resolve;

	}

	_showProject( project ) {

		this.bar.show( project );
		$( 'empty-hint' ).hidden = ! project || !! project.mesh;
		if ( ! project ) this.viewer.setObject( null );
		this.rig.update();

	}

	/** The heat-map features, the region toggles and the conditioning's rows follow the saved landmarks (the rig's joints, the stream's points). */
	_showSavedLandmarks( project ) {

		const layout = this.layouts.find( ( l ) => l.name === project?.landmarks?.layout ) || this.landmarks.layout;
		this.rig.setJoints( project, layout );
		this.live.setLayout( layout );
		this.sources.setLayout( layout );

	}

}

/**
 * "name.obj · 8,430 vertices · 16,416 triangles · 16.2 × 22.0 × 12.4 units": the mesh keeps
 * its own units, so its size is shown for the user to judge them.
 * @param {{filename: string, n_vertices: number, n_faces: number}} mesh
 * @param {Float32Array} positions - (3V)
 */
function meshInfo( mesh, positions ) {

	const min = [ Infinity, Infinity, Infinity ], max = [ - Infinity, - Infinity, - Infinity ];
	for ( let i = 0; i < positions.length; i += 3 ) {

		for ( let k = 0; k < 3; k ++ ) {

			const v = positions[ i + k ];
			if ( v < min[ k ] ) min[ k ] = v;
			if ( v > max[ k ] ) max[ k ] = v;

		}

	}

	const size = max.map( ( m, k ) => ( m - min[ k ] ).toPrecision( 3 ) ).join( ' × ' );
	const n = ( x ) => x.toLocaleString( 'en' );
	return `${ mesh.filename } · ${ n( mesh.n_vertices ) } vertices · ${ n( mesh.n_faces ) } triangles · ${ size } units`;

}
