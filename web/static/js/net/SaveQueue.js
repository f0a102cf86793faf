const SAVE_DELAY_MS = 300; // changes reach the server this long after the last one

/**
 * Painted rows on their way to the server: the vertices changed since the last save go
 * together SAVE_DELAY_MS after the last change, one save at a time; a refused save keeps
 * its vertices, and the server's reason, for the next save or a retry.
 */
export class SaveQueue {

	/**
	 * @param {(vertices: Int32Array, options: {keepalive: boolean}) => Promise<void>} send -
	 *   saves the current rows of `vertices` (sorted); rejects with the server's reason.
	 * @param {() => void} onChange - after every change of `state`.
	 */
	constructor( send, onChange ) {

		this._send = send;
		this._onChange = onChange;
		this._dirty = new Set(); // vertices whose rows the server does not have yet
		this._saving = null; // the save in flight
		this._timer = 0;
		this._generation = 0; // bumps on clear(): a late refusal of older rows keeps nothing
		/** The server's reason the last save failed ('' when it did not). */
		this.error = '';

	}

	/** 'saved', 'unsaved', 'saving' or 'failed' (the reason in `error`). */
	get state() {

		if ( this._saving ) return 'saving';
		if ( this._dirty.size && this.error ) return 'failed';
		return this._dirty.size ? 'unsaved' : 'saved';

	}

	/** Whether some rows are not saved (waiting, or refused). */
	get pending() {

		return this._dirty.size > 0;

	}

	/** @param {Iterable<number>} vertices - their rows changed: save them soon. */
	add( vertices ) {

		for ( const v of vertices ) this._dirty.add( v );
		clearTimeout( this._timer );
		this._timer = setTimeout( () => this.flush().catch( () => {} ), SAVE_DELAY_MS );
		this._onChange();

	}

	/** Forget the unsaved rows (another rig); a save in flight still ends. */
	clear() {

		clearTimeout( this._timer );
		this._dirty.clear();
		this.error = '';
		this._generation ++;

	}

	/**
	 * Save the unsaved rows now and wait for the answer.
	 * @param {{keepalive?: boolean}} [options] - keepalive: the page is being unloaded.
	 */
	async flush( { keepalive = false } = {} ) {

		clearTimeout( this._timer );
		this._timer = 0;
		while ( this._saving ) await this._saving;
		if ( this._dirty.size ) await this._save( keepalive );

	}

	/** Retry a failed save. */
	retry() {

		this.error = '';
		return this.flush();

	}

	async _save( keepalive ) {

		const generation = this._generation;
		const vertices = Int32Array.from( this._dirty ).sort();
		this._dirty.clear();
		let done;
		this._saving = new Promise( ( resolve ) => ( done = resolve ) );
		this._onChange();
		try {

			await this._send( vertices, { keepalive } );
			if ( generation === this._generation ) this.error = '';

		} catch ( error ) {

			if ( generation === this._generation ) {

				for ( const v of vertices ) this._dirty.add( v );
				this.error = error.detail || error.message;

			}

		} finally {

			this._saving = null;
			done();
			this._onChange();

		}

	}

}
