import { placedByHand, surfacePoints } from '../model/LandmarkSet.js';
import { ApiError, api } from '../net/api.js';
import { ask } from './ask.js';
import { $, guarded, option } from './dom.js';
import { LayoutGuide } from './LayoutGuide.js';

export const DEFAULT_LAYOUT = 'dutreve22'; // Dutreve's points and the chin: the jaw follows the mouth, one more click
const LAST_LAYOUT_KEY = 'retarget.layout';

/** Where a point of the face's side is in the guide, which shows the face as you see it. */
const SIDE_WORDS = { right: '· on your left', left: '· on your right' };

/**
 * The Landmarks panel (index.html #landmarks-panel): the layout, the reference face
 * (LayoutGuide), the count and the next point, undo, redo, Mirror, delete, clear and
 * *Save landmarks*, over the page's LandmarkSet (`app.landmarks`) that the picker edits.
 * Unsaved points are kept with the project as a draft (its settings' `draft` key: layout,
 * points, the mesh revision they were placed on), restored on the next visit.
 *
 * *Find points* (and every upload, through `App.animateUpload`) has the server find the
 * layout's points with no clicks (POST .../landmarks/find, a job); the points it is unsure
 * of are ringed on the face and named by region under the button ("Check 3 points: jaw,
 * brows") until they are moved or saved. Whatever the user does to the points while they
 * are being found wins: the found ones are then neither shown over the user's nor, once
 * the draft reaches the server, saved there.
 */
export class LandmarksPanel {

	/**
	 * @param {import('../App.js').App} app
	 */
	constructor( app ) {

		this.app = app;
		this.guide = new LayoutGuide( $( 'guide' ) );
		/** Whether points are being found for the shown project. */
		this.finding = false;
		this._find = null; // {follow: AbortController, before: PickState, touched: boolean} while finding
		this._findNote = ''; // the last find's news when no point is flagged
		this._events = new AbortController();
		this._bind();

	}

	/**
	 * The layouts the server knows, in the layout chooser.
	 * @param {object[]} layouts - GET /api/layouts.
	 */
	setLayouts( layouts ) {

		$( 'layout-select' ).replaceChildren( ...layouts.map( ( layout ) => option( layout.name, `${ layout.name } · ${ layout.n_points } points`, layout.description ) ) );

	}

	/**
	 * Show a project's saved landmarks, or its draft, or none in the last layout used.
	 * @param {object} project - GET /api/projects/{id}.
	 * @param {() => boolean} current - false once another project is being opened.
	 */
	async load( project, current ) {

		const app = this.app, landmarks = app.landmarks;
		let saved = null;
		if ( project.landmarks ) saved = await api.landmarks( project.id );
		if ( ! current() ) return;
		const known = ( name ) => app.layouts.some( ( l ) => l.name === name );
		let layout = saved?.layout || project.landmarks?.layout || '';
		if ( saved && ! known( layout ) ) {

			// landmarks saved without a layout (e.g. through the API): any layout of that size fits
			const n = saved.triangles ? saved.triangles.length : saved.vertex_indices.length;
			layout = app.layouts.find( ( l ) => l.n_points === n )?.name || '';
			if ( ! layout ) {

				app.errors.show( `The project's ${ n } saved landmarks match no layout; pick them again.` );
				saved = null;

			}

		}

		if ( ! saved ) layout = known( localStorage.getItem( LAST_LAYOUT_KEY ) ) ? localStorage.getItem( LAST_LAYOUT_KEY ) : DEFAULT_LAYOUT;
		landmarks.load( layout, saved );

		const draft = project.settings?.draft;
		if ( draft && draft.revision === project.revision && known( draft.layout ) && app.face ) {

			try {

				landmarks.replace( draft.layout, draft.points.map( ( p ) => p && { triangle: p.slice( 0, 3 ), barycentric: p.slice( 3, 6 ) } ) );
				$( 'landmarks-note' ).textContent = 'Unsaved points restored from your last visit (Undo drops them).';

			} catch ( error ) {

				console.warn( 'retarget: draft ignored:', error.message );

			}

		}

	}

	/** Forget an old project's notes and stop following its find. */
	clear() {

		this._find?.follow.abort();
		this._find = null;
		this.finding = false;
		this._findNote = '';
		$( 'find-progress' ).hidden = true;
		$( 'landmarks-note' ).textContent = '';

	}

	/**
	 * Have the server find the layout's points on the mesh and show them once saved as the
	 * project's landmarks, unless the user placed, moved or chose anything meanwhile.
	 * @param {{auto?: boolean, confirmed?: boolean}} [options] - auto: after an upload;
	 *   nothing is asked and nothing happens when the project already has points, saved or
	 *   drafted. confirmed: the user already chose to replace the points (a switch to a
	 *   layout that is found, not placed): nothing is asked.
	 * @returns {Promise<boolean>} whether the found points are the ones shown now.
	 */
	async find( { auto = false, confirmed = false } = {} ) {

		const app = this.app, landmarks = app.landmarks, project = app.project;
		if ( ! project?.mesh || ! app.face ) throw new ApiError( 0, 'Upload a mesh first.' );
		if ( this._find ) return false;
		if ( auto && ( project.landmarks || landmarks.placedCount > 0 ) ) return false;
		const placed = landmarks.placedCount;
		if ( ! auto && ! confirmed && this._ownPoints() ) {

			const answer = await ask( `Replace the ${ placed } placed point${ placed > 1 ? 's' : '' } with points found on the mesh? Undo brings yours back.`, { ok: 'Find points' } );
			if ( answer !== 'ok' ) return false;

		}

		const id = app.projectId, current = app.ticket();
		const find = this._find = { follow: new AbortController(), before: landmarks.state, touched: false };
		const bar = $( 'find-progress' );
		this.finding = true;
		this._findNote = '';
		bar.value = 0;
		bar.hidden = false;
		this._showFinding( 'Finding the points on the mesh…' );
		let job;
		try {

			const started = await api.findLandmarks( id, { layout: landmarks.state.layout, replace: ! auto } );
			job = await api.waitJob( started.id, ( { progress } ) => {

				bar.value = progress;
				this._showFinding( `Finding the points on the mesh… ${ Math.round( progress * 100 ) }%` );

			}, { what: 'Finding the points', signal: find.follow.signal } );

		} catch ( error ) {

			if ( find.follow.signal.aborted || ! current() ) return false;
			// no face on the mesh is news, not a fault: the points are placed by hand as before
			const reason = error.message.replace( /^Finding the points failed: /, '' );
			this._findNote = reason.charAt( 0 ).toUpperCase() + reason.slice( 1 );
			return false;

		} finally {

			if ( this._find === find ) {

				this._find = null;
				this.finding = false;
				bar.hidden = true;
				this.update();

			}

		}

		const { result } = job;
		if ( ! result.saved ) {

			this._findNote = `Points were found but not kept: ${ result.reason }.`;
			this.update();
			return false;

		}

		const [ fresh, saved ] = await Promise.all( [ api.project( id ), api.landmarks( id ) ] );
		if ( ! current() ) return false;
		app.project = fresh;
		if ( ! saved.confidence ) {

			// landmarks saved since (another window, the API) replaced them: those are shown
			this._findNote = 'Points were found, then replaced by landmarks saved meanwhile.';
			await this.load( fresh, current );
			app.landmarksSaved();
			return false;

		}

		const found = { layout: saved.layout, points: surfacePoints( saved ) };
		if ( find.touched || landmarks.state !== find.before ) {

			// the server kept them before it heard of the user's points: those stay on screen, unsaved
			landmarks.markSaved( found, saved );
			this._findNote = `Points were found and saved while you placed yours; yours are shown (unsaved).`;
			app.landmarksSaved();
			return false;

		}

		if ( auto ) {

			landmarks.load( saved.layout, saved );

		} else {

			landmarks.replace( saved.layout, found.points ); // undoable: the user's points come back
			landmarks.markSaved( landmarks.state, saved );

		}

		this._findNote = `Found the ${ result.n_points } points of ${ result.layout }.`;
		app.landmarksSaved();
		app.showLandmarks();
		return true;

	}

	/**
	 * Save the landmarks on screen as the project's (which drops its rig).
	 * @returns {Promise<void>}
	 */
	async save() {

		const app = this.app, landmarks = app.landmarks;
		if ( ! app.project?.mesh ) throw new ApiError( 0, 'Upload a mesh before placing landmarks.' );
		if ( ! landmarks.dirty && app.project.landmarks ) return;
		const missing = landmarks.missing();
		if ( missing.length ) {

			const shown = missing.slice( 0, 8 ).join( ', ' ) + ( missing.length > 8 ? `, … (${ missing.length - 8 } more)` : '' );
			throw new ApiError( 0, `Cannot save yet: ${ missing.length } of ${ landmarks.points.length } points are not placed (${ shown }). Next: ${ missing[ 0 ] }.` );

		}

		const id = app.projectId, current = app.ticket();
		app.projectSettings.cancel( 'draft' ); // the save supersedes the draft
		$( 'save-landmarks' ).disabled = true;
		try {

			const sent = landmarks.state;
			await api.putLandmarks( id, landmarks.toJSON() );
			if ( ! current() ) return;
			// the points saved are the ones sent, even if the user edited while the request ran
			landmarks.markSaved( sent );
			app.project = await api.patchProject( id, { settings: { draft: null } } );
			if ( ! current() ) return;
			app.landmarksSaved();
			$( 'landmarks-note' ).textContent = 'Saved. Compute the rig to animate the face.';

		} finally {

			app.showLandmarks();

		}

	}

	/** Show the landmarks' state: count, next point, what the buttons can do, the guide. */
	update() {

		const landmarks = this.app.landmarks;
		const layout = landmarks.layout;
		const next = landmarks.next;
		const hasMesh = !! this.app.face;
		$( 'layout-select' ).value = landmarks.state.layout;
		$( 'landmark-count' ).textContent = layout ? `${ landmarks.placedCount } / ${ layout.n_points }` : '';
		$( 'landmark-count' ).className = 'badge' + ( layout && landmarks.placedCount === layout.n_points ? ' good' : '' );
		$( 'unsaved' ).hidden = ! landmarks.dirty || ! hasMesh;
		const byHand = placedByHand( layout );
		$( 'next-point' ).textContent = ! layout ? '' : next < 0 ? 'all placed ✓' : byHand ? layout.points[ next ].name : 'Find points places them';
		$( 'next-side' ).textContent = layout && next >= 0 && byHand ? SIDE_WORDS[ layout.points[ next ].side ] ?? '' : '';
		$( 'undo' ).disabled = ! landmarks.canUndo;
		$( 'redo' ).disabled = ! landmarks.canRedo;
		$( 'delete-point' ).disabled = landmarks.selected < 0;
		$( 'mirror' ).disabled = ! hasMesh || ! landmarks.canMirror;
		$( 'clear-points' ).disabled = landmarks.placedCount === 0;
		$( 'save-landmarks' ).disabled = ! hasMesh || ! landmarks.dirty; // saving drops the rig: only when something changed
		$( 'find-points' ).disabled = ! hasMesh || this.finding;
		if ( ! this.finding ) this._showFindNote();
		this.guide.setLayout( layout );
		this.guide.update( { placed: landmarks.points.map( Boolean ), next: hasMesh && byHand ? next : - 1, selected: landmarks.selected } );

	}

	/**
	 * The viewport hint while placing points.
	 * @param {number} hovered - the marker under the pointer, -1 for none.
	 * @returns {string}
	 */
	hint( hovered ) {

		const landmarks = this.app.landmarks, layout = landmarks.layout;
		if ( hovered >= 0 && layout ) return `${ layout.points[ hovered ].name } · drag to slide it over the surface`;
		if ( layout && landmarks.next >= 0 && ! placedByHand( layout ) ) return `Find points places the ${ layout.n_points } points of ${ layout.name } · drag a marker to move it · Shift+click selects`;
		if ( layout && landmarks.next >= 0 ) return `Click the mesh to place ${ layout.points[ landmarks.next ].name } · drag a marker to move it · Shift+click selects`;
		if ( landmarks.selected >= 0 && layout ) return `${ layout.points[ landmarks.selected ].name } selected · Delete removes it`;
		return 'Drag to orbit · right-drag pans · wheel zooms · F frames the face';

	}

	/** Keep unsaved picks with the project (its settings' draft) so a reload or crash loses nothing. */
	scheduleDraft() {

		const app = this.app, project = app.project;
		if ( ! project || ! app.face ) return;
		if ( ! app.landmarks.dirty && ! project.settings?.draft ) return;
		// while points are being found the draft goes at once: the server keeps found points only over none
		app.projectSettings.schedule( project.id, 'draft', () => this._draft(), this._find ? 0 : undefined );

	}

	/**
	 * Keys of the landmarks: Ctrl+Z undo, Ctrl+Shift+Z or Ctrl+Y redo, Ctrl+S save,
	 * Delete removes the selected point, M mirrors.
	 * @param {KeyboardEvent} event
	 * @returns {Promise<boolean>} whether the key was taken (its default prevented).
	 */
	async key( event ) {

		const landmarks = this.app.landmarks;
		const mod = event.ctrlKey || event.metaKey, key = event.key.toLowerCase();
		if ( mod && key === 'z' ) {

			event.preventDefault();
			if ( event.shiftKey ) landmarks.redo();
			else landmarks.undo();

		} else if ( mod && key === 'y' ) {

			event.preventDefault();
			landmarks.redo();

		} else if ( mod && key === 's' ) {

			event.preventDefault();
			await this.save();

		} else if ( mod || event.altKey ) {

			return false;

		} else if ( key === 'delete' || key === 'backspace' ) {

			if ( landmarks.deleteSelected() ) event.preventDefault();

		} else if ( key === 'm' ) {

			this._mirror();

		} else {

			return false;

		}

		return true;

	}

	/** Stop listening. */
	dispose() {

		this._events.abort();
		this.guide.dispose();

	}

	/** Whether points on screen are the user's own (placed, moved, or never found): replacing them asks first. */
	_ownPoints() {

		const landmarks = this.app.landmarks;
		return landmarks.placedCount > 0 && ( landmarks.dirty || ! landmarks.flagged.some( Boolean ) );

	}

	/** The user chose something in the panel while points were being found: theirs win. */
	_touched() {

		if ( this._find ) this._find.touched = true;

	}

	_showFinding( text ) {

		const note = $( 'find-note' );
		note.textContent = text;
		note.className = 'note';

	}

	/** The points to check by region ("Check 3 points: jaw, brows"), else the last find's news. */
	_showFindNote() {

		const landmarks = this.app.landmarks, layout = landmarks.layout, note = $( 'find-note' );
		const flagged = landmarks.flagged;
		const n = flagged.filter( Boolean ).length;
		if ( n && layout ) {

			const regions = [ ...new Set( layout.points.filter( ( _, i ) => flagged[ i ] ).map( ( p ) => p.region.replace( /_/g, ' ' ) ) ) ];
			note.textContent = `Check ${ n } point${ n > 1 ? 's' : '' }: ${ regions.join( ', ' ) } (ringed in red; drag any that is off, then save).`;
			note.className = 'note warn';

		} else {

			note.textContent = this._findNote;
			note.className = 'note';

		}

	}

	/**
	 * The draft to store: the unsaved points, null to drop a stored one, undefined when
	 * there is nothing to change.
	 */
	_draft() {

		const app = this.app, project = app.project, landmarks = app.landmarks;
		if ( ! project || ! app.face ) return undefined;
		const draft = landmarks.dirty ? {
			revision: project.revision,
			layout: landmarks.state.layout,
			points: landmarks.points.map( ( p ) => p && [ ...p.triangle, ...p.barycentric ] ),
		} : null;
		return draft || project.settings?.draft ? draft : undefined;

	}

	async _switchLayout( name ) {

		const app = this.app, landmarks = app.landmarks;
		if ( name === landmarks.state.layout ) return;
		if ( ! placedByHand( landmarks.layouts.get( name ) ) && app.face ) {

			// nobody places 468 points: they are found, the face rigged and played, as after an upload
			if ( this._ownPoints() ) {

				const placed = landmarks.placedCount;
				const answer = await ask( `Switch the layout to ${ name } and find its points on the mesh? They replace the ${ placed } placed point${ placed > 1 ? 's' : '' }; Undo brings yours back.`, { ok: 'Switch layout' } );
				if ( answer !== 'ok' ) {

					$( 'layout-select' ).value = landmarks.state.layout;
					return;

				}

			}

			landmarks.setLayout( name );
			localStorage.setItem( LAST_LAYOUT_KEY, name );
			app.animateFound(); // not awaited: finding, rigging and playing show in their panels
			return;

		}

		if ( landmarks.placedCount > 0 ) {

			const dropped = landmarks.droppedBy( name );
			const kept = landmarks.placedCount - dropped;
			const answer = await ask(
				`Switch the layout to ${ name }? ` + ( dropped ? `${ dropped } placed point${ dropped > 1 ? 's have' : ' has' } no counterpart there and will be dropped` : 'Every placed point carries over' )
				+ ( kept && dropped ? `; ${ kept } carry over by name.` : '.' ) + ' Undo switches back.',
				{ ok: 'Switch layout' } );
			if ( answer !== 'ok' ) {

				$( 'layout-select' ).value = landmarks.state.layout;
				return;

			}

		}

		landmarks.setLayout( name );
		localStorage.setItem( LAST_LAYOUT_KEY, name );

	}

	_mirror() {

		const { placed, plane } = this.app.picker.mirror();
		const n = plane?.normal;
		// no pair placed yet: the plane is x = const, as before any pair tells its tilt
		const across = n && n.x === 1 ? `x = ${ plane.offset.toPrecision( 4 ) }`
			: n && `the face's symmetry plane (normal ${ n.x.toFixed( 3 ) }, ${ n.y.toFixed( 3 ) }, ${ n.z.toFixed( 3 ) })`;
		$( 'landmarks-note' ).textContent = placed ? `Mirrored ${ placed } point${ placed > 1 ? 's' : '' } across ${ across }.` : 'Nothing to mirror: every placed point has its partner.';

	}

	_bind() {

		const app = this.app, landmarks = app.landmarks, signal = this._events.signal;
		const guard = ( fn ) => guarded( app.errors, fn );
		this.guide.addEventListener( 'pick', ( event ) => {

			this._touched();
			landmarks.select( event.detail.index );

		}, { signal } );
		$( 'layout-select' ).addEventListener( 'change', guard( ( event ) => {

			this._touched();
			return this._switchLayout( event.target.value );

		} ), { signal } );
		$( 'find-points' ).addEventListener( 'click', guard( () => this.find() ), { signal } );
		$( 'undo' ).addEventListener( 'click', () => landmarks.undo(), { signal } );
		$( 'redo' ).addEventListener( 'click', () => landmarks.redo(), { signal } );
		$( 'delete-point' ).addEventListener( 'click', () => landmarks.deleteSelected(), { signal } );
		$( 'mirror' ).addEventListener( 'click', () => this._mirror(), { signal } );
		$( 'clear-points' ).addEventListener( 'click', () => landmarks.clear(), { signal } );
		$( 'save-landmarks' ).addEventListener( 'click', guard( () => this.save() ), { signal } );

	}

}
