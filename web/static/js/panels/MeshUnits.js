import { $ } from './dom.js';

/**
 * The mesh's unit beside the mesh info in the header (index.html #mesh-units): what the
 * mesh's numbers are in (m, cm, mm, in), guessed by the server from the mesh's size at upload
 * (`retarget.units.guess_units`: a face is about 0.2 m across) and stored in the project's
 * settings as `mesh_units`, with the guess as `mesh_units_guess` ({unit, size}). Changing the
 * select saves it (PATCH, through `app.projectSettings`); the glTF export scales from it to
 * metres. A project saved before units were recorded shows "guess": the export guesses.
 *
 * No maths here: the guess is the server's, the select only says which unit to use.
 */
export class MeshUnits {

	/**
	 * @param {import('../App.js').App} app
	 */
	constructor( app ) {

		this.app = app;
		this._events = new AbortController();
		$( 'mesh-units' ).addEventListener( 'change', () => this._changed(), { signal: this._events.signal } );

	}

	/**
	 * Show the unit of `project` (hidden without a project or mesh).
	 * @param {object|null} project - GET /api/projects/{id}.
	 */
	setProject( project ) {

		$( 'mesh-units-group' ).hidden = ! project?.mesh;
		if ( ! project?.mesh ) return;
		$( 'mesh-units' ).value = project.settings?.mesh_units ?? '';
		this._showGuess( project.settings ?? {} );

	}

	/** The unit chosen: 'm', 'cm', 'mm', 'in', or null (guess at export). */
	get unit() {

		return $( 'mesh-units' ).value || null;

	}

	/** Stop listening. */
	dispose() {

		this._events.abort();

	}

	_changed() {

		const app = this.app, unit = this.unit;
		if ( ! app.projectId ) return;
		app.projectSettings.schedule( app.projectId, 'mesh_units', () => unit, 0 );
		this._showGuess( { ...app.project?.settings, mesh_units: unit } );

	}

	_showGuess( settings ) {

		const guess = settings.mesh_units_guess;
		const note = $( 'mesh-units-note' );
		if ( ! settings.mesh_units ) note.textContent = '(guessed from its size at export)';
		else if ( guess && guess.unit === settings.mesh_units ) note.textContent = `(guessed: ${ guess.size.toPrecision( 3 ) } across)`;
		else if ( guess ) note.textContent = `(guessed ${ guess.unit })`;
		else note.textContent = '';

	}

}
