import { api } from '../net/api.js';
import { $ } from './dom.js';
import { MeshUnits } from './MeshUnits.js';

/**
 * The Export panel (index.html #export-panel): download the project as a glTF binary
 * (GET /api/projects/{id}/export.glb: mesh, landmarks and the rig in use, with the chosen
 * takes as animations, retargeted with the project's conditioning settings and region
 * mask, the same objects the stream plays with: `app.conditioning`, `app.regions`; driven
 * as the Performance panel's *Drive by* says: the rig, or the muscles as morph targets and
 * a jaw joint), and import such a file as a new project, which is then opened. *Batch
 * manifest* downloads the project and all its takes with the conditioning settings as a
 * zip for `retarget batch` (GET /api/projects/{id}/manifest.zip). *Units*: metres (the
 * default, the mesh scaled from its unit, which `MeshUnits` shows and changes beside the
 * mesh info) or the mesh's own numbers (`units=keep`). *Rig as*: exact, or a four-joint skin
 * fitted to the takes (`form=skin`; its error, from the X-Retarget-Fit header, is shown
 * after the download); *Keys at* a rate and *reduce to* a key tolerance in millimetres.
 *
 * The panel holds no maths: the server retargets and writes the file. Refusals show the
 * server's reason in the panel's note and the page's error banner.
 */
export class ExportPanel {

	/**
	 * @param {import('../App.js').App} app
	 */
	constructor( app ) {

		this.app = app;
		this.takes = [];
		this._chosen = new Set(); // take ids ticked, kept across refreshes of the list
		this._events = new AbortController();
		this.meshUnits = new MeshUnits( app );
		this._bind();

	}

	/** The project changed: list its takes (none ticked). */
	async setProject( project ) {

		this.takes = [];
		this._chosen.clear();
		this.meshUnits.setProject( project );
		this._note( '' );
		this._render();
		if ( project ) await this.refresh();

	}

	/** Fetch the project's takes again. */
	async refresh() {

		const id = this.app.projectId;
		if ( ! id ) return;
		const takes = await api.takes( id );
		if ( id !== this.app.projectId ) return;
		this.showTakes( takes );

	}

	/**
	 * List these takes (the Performance panel's list, whenever it changes: a take added,
	 * renamed, trimmed or deleted), ticks kept for the takes still there.
	 * @param {object[]} takes - GET .../takes of the shown project.
	 */
	showTakes( takes ) {

		this.takes = takes;
		this._render();

	}

	/**
	 * Download the current project as .glb with the ticked takes (or all of them).
	 * @returns {Promise<{filename: string, size: number}|null>} what was saved; null on a
	 *   refusal, which is shown.
	 */
	async exportGltf() {

		const id = this.app.projectId;
		if ( ! id ) return null;
		const all = $( 'export-all' ).checked;
		const takes = all ? 'all' : this.takes.filter( ( t ) => this._chosen.has( t.id ) ).map( ( t ) => t.id ).join( ',' );
		const count = all ? this.takes.length : takes.split( ',' ).filter( Boolean ).length;
		const button = $( 'export-gltf' );
		button.disabled = true;
		this._note( count ? `Retargeting ${ count } take${ count > 1 ? 's' : '' } and writing the glTF…` : 'Writing the glTF…' );
		try {

			const { blob, filename, fit } = await api.exportGltf( id, { takes, settings: this.app.conditioning.toJSON(), regions: this.app.regions.movingRegions(), drive: this.app.sources.drive, units: $( 'export-units' ).value, ...this._keys() } );
			this._save( blob, filename );
			this._note( `Saved ${ filename } (${ ( blob.size / 2 ** 20 ).toFixed( 1 ) } MiB${ count ? `, ${ count } animation${ count > 1 ? 's' : '' }` : '' }).${ fitNote( fit ) }` );
			return { filename, size: blob.size };

		} catch ( error ) {

			this._refused( error );
			return null;

		} finally {

			button.disabled = false;

		}

	}

	/** The panel's choice of rig form, key rate and key tolerance, as `api.exportGltf` takes them. */
	_keys() {

		const tolerance = Number( $( 'export-key-tolerance' ).value );
		return { form: $( 'export-form' ).value, rate: $( 'export-rate' ).value,
			keyTolerance: Number.isFinite( tolerance ) && tolerance > 0 ? tolerance : 0 };

	}

	/**
	 * Download the current project and all its takes as a batch manifest zip (the takes
	 * with the Performance panel's conditioning), to run with `retarget batch`.
	 * @returns {Promise<{filename: string, size: number}|null>} what was saved; null on a
	 *   refusal (no takes, no rig), which is shown.
	 */
	async exportManifest() {

		const id = this.app.projectId;
		if ( ! id ) return null;
		const button = $( 'export-manifest' );
		button.disabled = true;
		this._note( 'Writing the batch manifest…' );
		try {

			const { blob, filename } = await api.exportManifest( id, { settings: this.app.conditioning.toJSON() } );
			this._save( blob, filename );
			this._note( `Saved ${ filename } (${ ( blob.size / 2 ** 20 ).toFixed( 1 ) } MiB): run it with "retarget batch ${ filename } --out DIR".` );
			return { filename, size: blob.size };

		} catch ( error ) {

			this._refused( error );
			return null;

		} finally {

			button.disabled = false;

		}

	}

	/**
	 * Import a .glb exported by this app as a new project and open it.
	 * @param {File} file
	 * @returns {Promise<object|null>} the server's answer {project, deformation, animations};
	 *   null on a refusal, which is shown.
	 */
	async importGltf( file ) {

		this._note( `Importing ${ file.name }…` );
		try {

			const answer = await api.importProject( file, ( fraction ) => this._note( `Uploading ${ file.name }… ${ Math.round( 100 * fraction ) } %` ) );
			await this.app.refreshProjects();
			await this.app.openProject( answer.project.id );
			const animations = answer.animations.length;
			this._note( `Imported "${ answer.project.name }": mesh, landmarks and rig (${ answer.deformation === 'skin' ? 'glTF skin' : 'morph targets' }).` +
				( animations ? ` Its ${ animations } animation${ animations > 1 ? 's were' : ' was' } not imported: an animation holds the face's own motion, not a performer's points, so it cannot be a take.` : '' ) );
			return answer;

		} catch ( error ) {

			this._refused( error );
			return null;

		}

	}

	/** Stop listening. */
	dispose() {

		this._events.abort();
		this.meshUnits.dispose();

	}

	_bind() {

		const signal = this._events.signal;
		$( 'export-gltf' ).addEventListener( 'click', () => this.exportGltf(), { signal } );
		$( 'export-manifest' ).addEventListener( 'click', () => this.exportManifest(), { signal } );
		$( 'export-all' ).addEventListener( 'change', () => this._render(), { signal } );
		$( 'export-takes' ).addEventListener( 'change', ( event ) => {

			const id = event.target.dataset.take;
			if ( ! id ) return;
			if ( event.target.checked ) this._chosen.add( id );
			else this._chosen.delete( id );

		}, { signal } );
		$( 'import-file' ).addEventListener( 'change', async ( event ) => {

			const file = event.target.files[ 0 ];
			event.target.value = '';
			if ( file ) await this.importGltf( file );

		}, { signal } );

	}

	_render() {

		const all = $( 'export-all' ).checked;
		const known = new Set( this.takes.map( ( t ) => t.id ) );
		for ( const id of this._chosen ) if ( ! known.has( id ) ) this._chosen.delete( id );
		$( 'export-takes' ).replaceChildren( ...this.takes.map( ( take ) => {

			const label = document.createElement( 'label' );
			label.className = 'toggle';
			label.title = `${ take.n_frames } frames, ${ take.duration.toFixed( 2 ) } s`;
			const box = document.createElement( 'input' );
			box.type = 'checkbox';
			box.dataset.take = take.id;
			box.checked = all || this._chosen.has( take.id );
			box.disabled = all;
			label.append( box, take.name );
			return label;

		} ) );
		$( 'export-none' ).hidden = this.takes.length > 0;

	}

	_save( blob, filename ) {

		const link = document.createElement( 'a' );
		link.href = URL.createObjectURL( blob );
		link.download = filename;
		document.body.append( link );
		link.click();
		link.remove();
		setTimeout( () => URL.revokeObjectURL( link.href ), 0 );

	}

	_note( text, warn = false ) {

		const note = $( 'export-note' );
		note.textContent = text;
		note.className = 'note' + ( warn ? ' warn' : '' );

	}

	_refused( error ) {

		this._note( error.detail ?? error.message, true );
		this.app.errors.show( error );

	}

}

/**
 * What the export note says of a skin fit (`extras.retarget.fit`), or ''.
 * @param {object|null} fit
 */
function fitNote( fit ) {

	if ( ! fit ) return '';
	if ( fit.rms_relative === undefined ) return ' The rig is a four-joint skin (no take to measure its error on).';
	return ` The rig is a four-joint skin: ${ ( 100 * fit.rms_relative ).toFixed( 1 ) } % RMS error (${ fit.rms_mm.toFixed( 2 ) } mm), worst vertex ${ fit.worst_vertex_mm.toFixed( 2 ) } mm.`;

}
