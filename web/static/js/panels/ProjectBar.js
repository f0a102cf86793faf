import { api } from '../net/api.js';
import { ask } from './ask.js';
import { $, guarded, option } from './dom.js';

/**
 * The project bar (index.html #bar): choose a project, rename it, make a new one, delete
 * it; the address's `#p=<id>` follows the shown project, and changing it opens another.
 */
export class ProjectBar {

	/**
	 * @param {import('../App.js').App} app
	 */
	constructor( app ) {

		this.app = app;
		this._events = new AbortController();
		this._bind();

	}

	/**
	 * List the projects in the chooser.
	 * @param {object[]} projects - GET /api/projects.
	 * @param {string|null} current - the one shown.
	 */
	setProjects( projects, current ) {

		const select = $( 'project-select' );
		select.replaceChildren( ...projects.map( ( p ) => option( p.id, p.name ) ) );
		if ( current ) select.value = current;

	}

	/**
	 * The project being opened: chosen in the list, named by the address.
	 * @param {string|null} id - null: none (the address loses its `#p=`).
	 */
	select( id ) {

		if ( id === null ) {

			history.replaceState( null, '', location.pathname );
			return;

		}

		$( 'project-select' ).value = id;
		history.replaceState( null, '', `#p=${ encodeURIComponent( id ) }` );

	}

	/**
	 * Show a project's name (null: none, the controls disabled).
	 * @param {object|null} project
	 */
	show( project ) {

		$( 'project-name' ).value = project ? project.name : '';
		$( 'project-name' ).disabled = ! project;
		$( 'delete-project' ).disabled = ! project;

	}

	/** Stop listening. */
	dispose() {

		this._events.abort();

	}

	async _newProject() {

		const app = this.app, button = $( 'new-project' );
		if ( button.disabled ) return null;
		// one project per press: a double click's second click finds the button disabled
		// (the server also keeps names unique, for two windows pressing at once)
		button.disabled = true;
		try {

			const taken = new Set( app.projects.map( ( p ) => p.name ) );
			let n = 1;
			while ( taken.has( `Untitled ${ n }` ) ) n ++;
			const project = await api.createProject( `Untitled ${ n }` );
			await app.refreshProjects();
			if ( await app.openProject( project.id ) ) {

				$( 'project-name' ).focus();
				$( 'project-name' ).select();

			}

			return project;

		} finally {

			button.disabled = false;

		}

	}

	async _rename() {

		const app = this.app, input = $( 'project-name' );
		const name = input.value.trim();
		if ( ! app.project || ! name || name === app.project.name ) {

			input.value = app.project ? app.project.name : '';
			return;

		}

		try {

			app.project = await api.patchProject( app.project.id, { name } );
			input.value = app.project.name; // the server's: another project's name gets a " (2)"
			await app.refreshProjects();

		} catch ( error ) {

			input.value = app.project.name;
			app.errors.show( error );

		}

	}

	async _delete() {

		const app = this.app;
		if ( ! app.project ) return;
		const answer = await ask( `Delete the project "${ app.project.name }" with its mesh, landmarks and rig? This cannot be undone.`, { ok: 'Delete' } );
		if ( answer !== 'ok' ) return;
		await api.deleteProject( app.project.id );
		await app.forgetProject();

	}

	_bind() {

		const signal = this._events.signal, guard = ( fn ) => guarded( this.app.errors, fn );
		$( 'project-select' ).addEventListener( 'change', guard( async ( event ) => {

			const id = event.target.value;
			if ( ! await this.app.openProject( id ) && this.app.projectId !== id ) event.target.value = this.app.projectId;

		} ), { signal } );
		$( 'new-project' ).addEventListener( 'click', guard( () => this._newProject() ), { signal } );
		$( 'delete-project' ).addEventListener( 'click', guard( () => this._delete() ), { signal } );
		$( 'project-name' ).addEventListener( 'change', guard( () => this._rename() ), { signal } );
		$( 'project-name' ).addEventListener( 'keydown', ( event ) => {

			if ( event.key === 'Enter' ) event.target.blur();
			if ( event.key === 'Escape' ) {

				event.target.value = this.app.project?.name ?? '';
				event.target.blur();

			}

		}, { signal } );
		window.addEventListener( 'hashchange', guard( () => {

			const id = projectFromHash();
			if ( id && id !== this.app.projectId ) return this.app.openProject( id );

		} ), { signal } );

	}

}

/** The project id in the address (`#p=<id>`), or null. */
export function projectFromHash() {

	const match = /(?:^#|&)p=([^&]+)/.exec( location.hash );
	return match ? decodeURIComponent( match[ 1 ] ) : null;

}
