import { api } from '../net/api.js';
import { $, guarded } from './dom.js';

/**
 * Joined lips (index.html #mouth-box, in the Rig panel): most scanned and sculpted heads
 * have their lips in one surface, which stretches instead of opening. When the saved
 * landmarks find the lips joined (GET .../mesh/lips) the box says so and offers *Open
 * mouth* (the server cuts the mesh along the lip contact line: a new mesh revision, the
 * original vertices first); after that, *Undo open mouth* goes back to the mesh as it was.
 * Either way the face is reloaded and, if it had a rig, rigged again with the same method.
 */
export class MouthPanel {

	/**
	 * @param {import('../App.js').App} app
	 */
	constructor( app ) {

		this.app = app;
		this._events = new AbortController();
		this._bind();

	}

	/**
	 * Show whether the project's lips are joined, or that its mouth was opened.
	 * @param {object|null} project - GET /api/projects/{id}.
	 * @param {() => boolean} current - false once another project is being opened.
	 */
	async load( project, current ) {

		this.clear();
		if ( ! project?.mesh || ! project.landmarks ) return;
		const lips = await api.lips( project.id );
		if ( ! current() ) return;
		const opened = project.previous_mesh;
		const n = ( x ) => x.toLocaleString( 'en' );
		$( 'mouth-note' ).textContent = lips.joined ? lips.detail
			: opened ? `The mouth was opened: the lip line's vertices were duplicated (${ n( opened.n_vertices ) } → ${ n( project.mesh.n_vertices ) } vertices).`
				: '';
		$( 'open-mouth' ).hidden = ! lips.joined;
		$( 'undo-open-mouth' ).hidden = ! opened;
		$( 'mouth-box' ).hidden = ! lips.joined && ! opened;

	}

	/** Hide the box (another project, no landmarks). */
	clear() {

		$( 'mouth-box' ).hidden = true;
		$( 'mouth-note' ).textContent = '';

	}

	/** Cut the mesh open along the lip contact line (a new revision) and show it. */
	async open() {

		await this._replace( 'Opening the mouth…', ( id ) => api.openMouth( id ) );

	}

	/** Go back to the mesh before the mouth was opened. */
	async undo() {

		await this._replace( 'Going back to the mesh with joined lips…', ( id ) => api.revertMesh( id ) );

	}

	/** Stop listening. */
	dispose() {

		this._events.abort();

	}

	/**
	 * Replace the project's mesh through `change`, then reload the face and rig it again
	 * with the method it had (a new mesh drops the rig).
	 */
	async _replace( what, change ) {

		const app = this.app, id = app.projectId, method = app.project?.rig?.method;
		const buttons = [ $( 'open-mouth' ), $( 'undo-open-mouth' ) ];
		buttons.forEach( ( b ) => ( b.disabled = true ) );
		$( 'mouth-note' ).textContent = what;
		try {

			await change( id );
			if ( app.projectId !== id || ! await app.openProject( id, { force: true } ) ) return;
			if ( method ) {

				$( 'rig-method' ).value = method;
				await app.rig.compute();

			}

		} finally {

			buttons.forEach( ( b ) => ( b.disabled = false ) );

		}

	}

	_bind() {

		const signal = this._events.signal, errors = this.app.errors;
		$( 'open-mouth' ).addEventListener( 'click', guarded( errors, () => this.open() ), { signal } );
		$( 'undo-open-mouth' ).addEventListener( 'click', guarded( errors, () => this.undo() ), { signal } );

	}

}
