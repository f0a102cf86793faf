import { api } from './api.js';

/**
 * Keys of a project's `settings` object (PATCH /api/projects/{id} merges them; a key set
 * to null is removed; the whole object is capped at 64 KiB) saved a while after their
 * last change, so a reload or a crash loses nothing: the landmarks' unsaved `draft`, the
 * `conditioning` settings, the `held_regions`.
 *
 * A key's value is asked for when it is sent, so it is always the newest. Keys scheduled
 * together go in one request, and requests go in order, one at a time.
 */
export class ProjectSettings {

	/**
	 * @param {{onSaved: (project: object) => void, onError: (error: Error) => void}} handlers -
	 *   onSaved: the server's answer (the project, with all its settings); onError: a
	 *   refused or failed save.
	 */
	constructor( { onSaved, onError } ) {

		this._onSaved = onSaved;
		this._onError = onError;
		this._pending = new Map(); // key -> {projectId, value: () => *}
		this._timer = 0;
		// saves go one after another: two PATCHes in flight at once may reach the server
		// in either order, and an older draft landing last would lose the newer points
		this._sending = Promise.resolve();

	}

	/** Whether some key waits to be sent. */
	get pending() {

		return this._pending.size > 0;

	}

	/**
	 * Save `key` of project `projectId` `delayMs` after the last change (this call).
	 * @param {string} projectId
	 * @param {string} key
	 * @param {() => *} value - the JSON to store when it is sent; null removes the key,
	 *   undefined sends nothing.
	 * @param {number} [delayMs]
	 */
	schedule( projectId, key, value, delayMs = 400 ) {

		this._pending.set( key, { projectId, value } );
		clearTimeout( this._timer );
		this._timer = setTimeout( () => this.flush(), delayMs );

	}

	/**
	 * Forget a scheduled key (another save supersedes it), or every one.
	 * @param {string} [key] - absent: every key.
	 */
	cancel( key ) {

		if ( key === undefined ) this._pending.clear();
		else this._pending.delete( key );

	}

	/**
	 * Send every scheduled key now; a failure is reported to `onError`, not thrown.
	 * @param {{keepalive?: boolean}} [options] - keepalive: the page is being unloaded.
	 */
	async flush( { keepalive = false } = {} ) {

		clearTimeout( this._timer );
		this._timer = 0;
		const byProject = new Map();
		for ( const [ key, { projectId, value } ] of this._pending ) {

			const json = value();
			if ( json === undefined ) continue;
			if ( ! byProject.has( projectId ) ) byProject.set( projectId, {} );
			byProject.get( projectId )[ key ] = json;

		}

		this._pending.clear();
		const send = () => Promise.all( [ ...byProject ].map( async ( [ id, settings ] ) => {

			try {

				this._onSaved( await api.patchProject( id, { settings }, { keepalive } ) );

			} catch ( error ) {

				this._onError( error );

			}

		} ) );
		// an unloading page cannot wait for an earlier save: keepalive requests go at once
		this._sending = keepalive ? send() : this._sending.then( send );
		await this._sending;

	}

}
