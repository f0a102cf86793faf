import { api } from '../net/api.js';
import { ask } from './ask.js';
import { $, guarded } from './dom.js';

/**
 * The project's takes in the Performance panel (index.html #take-list): choose one (which
 * makes *Recorded take* the source), rename it in place, trim it (non-destructively: the
 * server keeps the span), download its points, delete it.
 *
 * Dispatches 'select' when the user chooses a take.
 */
export class TakeList extends EventTarget {

	/**
	 * @param {import('../App.js').App} app
	 */
	constructor( app ) {

		super();
		this.app = app;
		/** The project's takes (GET .../takes), oldest first. */
		this.takes = [];
		/** The chosen take's id, or null. */
		this.selected = null;

	}

	/** The chosen take's info, or undefined. */
	get selectedTake() {

		return this.takes.find( ( t ) => t.id === this.selected );

	}

	/** Empty the list (another project). */
	clear() {

		this.takes = [];
		this.selected = null;
		this.render();

	}

	/** List the project's takes again; the newest is chosen when the chosen one is gone. */
	async refresh() {

		const id = this.app.projectId;
		const takes = await api.takes( id );
		if ( id !== this.app.projectId ) return;
		this.takes = takes;
		if ( ! takes.some( ( t ) => t.id === this.selected ) ) this.selected = takes.length ? takes[ takes.length - 1 ].id : null;
		this.render();

	}

	/**
	 * Choose a take and list the takes again (it may be new).
	 * @param {string} id
	 */
	async select( id ) {

		this.selected = id;
		await this.refresh();

	}

	/** Show the takes, the chosen one selected; the Export panel lists the same takes. */
	render() {

		const list = $( 'take-list' );
		list.replaceChildren();
		$( 'takes-empty' ).hidden = this.takes.length > 0;
		for ( const take of this.takes ) list.append( this._row( take ) );
		this.app.exports?.showTakes( this.takes );

	}

	/** Scroll the chosen take into view. */
	reveal() {

		$( 'take-list' ).querySelector( 'li.selected' )?.scrollIntoView( { block: 'nearest' } );

	}

	_row( take ) {

		const guard = ( fn ) => guarded( this.app.errors, fn )();
		const li = document.createElement( 'li' );
		li.dataset.take = take.id;
		li.className = take.id === this.selected ? 'selected' : '';
		const [ start, stop ] = take.trim;
		li.innerHTML = `<label class="take-name"><input type="radio" name="take"></label>
			<span class="muted take-meta"></span>
			<span class="take-tools">
				<input class="trim-start" type="number" min="0" step="0.1" title="Trim: start (s)">
				<input class="trim-stop" type="number" min="0" step="0.1" title="Trim: stop (s)">
				<button class="quiet rename" title="Rename" aria-label="Rename">✎</button>
				<a class="button quiet download" title="Download the points (.npy)">⤓</a>
				<button class="quiet delete" title="Delete" aria-label="Delete">✕</button>
			</span>`;
		const radio = li.querySelector( 'input[type=radio]' );
		radio.checked = take.id === this.selected;
		radio.after( document.createTextNode( ' ' + take.name ) );
		// click, not change: choosing the take already selected must still choose the take source
		radio.addEventListener( 'click', () => {

			this.selected = take.id;
			this.dispatchEvent( new Event( 'select' ) );
			this.render();

		} );
		li.querySelector( '.take-meta' ).textContent = `${ take.source || 'file' } · ${ take.n_points } pts ${ take.dims }D · ${ ( stop - start ).toFixed( 1 ) } / ${ take.duration.toFixed( 1 ) } s`;
		const startInput = li.querySelector( '.trim-start' ), stopInput = li.querySelector( '.trim-stop' );
		startInput.value = start.toFixed( 2 );
		stopInput.value = stop.toFixed( 2 );
		startInput.max = stopInput.max = take.duration.toFixed( 3 );
		const trim = () => guard( () => this._trim( take, Number( startInput.value ), Number( stopInput.value ) ) );
		startInput.addEventListener( 'change', trim );
		stopInput.addEventListener( 'change', trim );
		li.querySelector( '.rename' ).addEventListener( 'click', () => this._rename( take, li.querySelector( '.take-name' ) ) );
		li.querySelector( '.delete' ).addEventListener( 'click', () => guard( () => this._delete( take ) ) );
		const download = li.querySelector( '.download' );
		download.href = api.takePointsUrl( this.app.projectId, take.id );
		download.download = `${ take.name }.npy`;
		return li;

	}

	/** Edit the take's name in its row: Enter or leaving the box saves, Escape cancels. */
	_rename( take, label ) {

		const box = document.createElement( 'input' );
		box.type = 'text';
		box.className = 'take-rename';
		box.maxLength = 200;
		box.value = take.name;
		box.setAttribute( 'aria-label', 'Take name' );
		let done = false;
		const finish = ( save ) => {

			if ( done ) return;
			done = true;
			const name = box.value.trim();
			if ( ! save || ! name || name === take.name ) {

				this.render();
				return;

			}

			guarded( this.app.errors, async () => {

				try {

					await api.patchTake( this.app.projectId, take.id, { name } );

				} finally {

					await this.refresh();

				}

			} )();

		};

		box.addEventListener( 'keydown', ( event ) => {

			if ( event.key === 'Enter' ) finish( true );
			else if ( event.key === 'Escape' ) finish( false );

		} );
		box.addEventListener( 'blur', () => finish( true ) );
		label.replaceWith( box );
		box.focus();
		box.select();

	}

	async _trim( take, start, stop ) {

		try {

			await api.patchTake( this.app.projectId, take.id, { trim: [ start, stop >= take.duration ? null : stop ] } );

		} finally {

			// a refused span puts the boxes back to the stored one
			await this.refresh();

		}

	}

	async _delete( take ) {

		const answer = await ask( `Delete the take "${ take.name }"? This cannot be undone.`, { ok: 'Delete' } );
		if ( answer !== 'ok' ) return;
		await api.deleteTake( this.app.projectId, take.id );
		await this.refresh();

	}

}
