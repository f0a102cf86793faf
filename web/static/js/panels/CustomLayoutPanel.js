import { REGIONS, SIDES, layoutSpec } from '../model/customLayout.js';
import { ApiError, api } from '../net/api.js';
import { $, guarded, option } from './dom.js';
import { MarkerFrame } from './MarkerFrame.js';

/**
 * *Custom layout from a take's markers* (a fold under the Landmarks panel): the marker
 * names of an uploaded take, or of a take file read for it (a take of markers the project's
 * layout lacks is refused as a take until the layout exists), become a layout's points; the user picks each one's region,
 * side, left/right partner and whether it moves with the head only, and saves it to the
 * project (PUT /api/projects/{id}/layouts/{name}). The saved layout is then chosen in the
 * layout select, and its points are clicked on the mesh with the landmark picker, in the
 * take's order, as any layout's are.
 *
 * A take tracked from a ring-marker video also shows the video's first frame with each
 * marker labelled (MarkerFrame): a click on a label (or on a row's marker name) chooses
 * that marker, and once the layout is chosen the next click on the mesh places its point
 * (the landmark set's `select` of an unplaced point makes it the next one placed).
 */
export class CustomLayoutPanel {

	/**
	 * @param {import('../App.js').App} app
	 */
	constructor( app ) {

		this.app = app;
		/** @type {Array<{name: string, region: string, side: string, mirror: string, anchor: boolean}>} */
		this.rows = [];
		/** The marker last clicked on the frame or in the table, or null. */
		this.chosen = null;
		this._pending = false; // chosen before its layout was: placed once the layout is chosen
		this.frame = new MarkerFrame( ( name ) => this.choose( name ) );
		this.root = build( this.frame.root );
		$( 'landmarks-panel' ).append( this.root );
		const errors = app.errors;
		this.root.addEventListener( 'toggle', guarded( errors, () => this.root.open && this.refreshTakes() ) );
		$( 'custom-markers' ).addEventListener( 'click', guarded( errors, () => this.useTake( $( 'custom-take' ).value ) ) );
		$( 'custom-file' ).addEventListener( 'change', guarded( errors, () => this.useFile( $( 'custom-file' ).files[ 0 ] ) ) );
		$( 'custom-save' ).addEventListener( 'click', guarded( errors, () => this.save() ) );
		app.landmarks.addEventListener( 'change', () => this._landmarksChanged() );

	}

	/**
	 * Open the fold on a take's markers (a ring-marker video just tracked).
	 * @param {string} takeId
	 */
	async showTake( takeId ) {

		this.root.open = true; // its toggle lists the takes too; this waits for the list
		await this.refreshTakes();
		$( 'custom-take' ).value = takeId;
		await this.useTake( takeId );
		this.root.scrollIntoView( { block: 'nearest' } );

	}

	/**
	 * Choose a marker: its row is marked, and the landmark picker places its point with the
	 * next click on the mesh once the layout is the one chosen for the landmarks.
	 * @param {string} name
	 */
	choose( name ) {

		this.chosen = name;
		this._pending = false; // before select, whose change event comes back here
		this._pending = ! this._pointAt( name );
		if ( this._pending ) $( 'custom-note' ).textContent = `${ name } chosen: save the layout, then click its point on the mesh.`;
		this._mark();

	}

	/** Forget the last project's rows; list the shown project's takes when open. */
	async setProject() {

		this._showRows( [] );
		this.frame.show( null );
		$( 'custom-note' ).textContent = '';
		if ( this.root.open ) await this.refreshTakes();

	}

	/** The project's takes in the take select. */
	async refreshTakes() {

		const id = this.app.projectId;
		const takes = id ? await api.takes( id ) : [];
		if ( id !== this.app.projectId ) return;
		const select = $( 'custom-take' ), kept = select.value; // a list again keeps the take shown
		select.replaceChildren( ...takes.map( ( t ) => option( t.id, `${ t.name } · ${ t.n_points } markers` ) ) );
		if ( takes.some( ( t ) => t.id === kept ) ) select.value = kept;
		$( 'custom-markers' ).disabled = takes.length === 0;
		if ( takes.length === 0 ) $( 'custom-note' ).textContent = 'Choose a take file of your markers, or upload one as a take first.';

	}

	/**
	 * A row per marker of the take, its region and side guessed from its name.
	 * @param {string} takeId
	 */
	async useTake( takeId ) {

		const id = this.app.projectId;
		if ( ! id || ! takeId ) throw new ApiError( 0, 'Choose a take whose markers make the layout.' );
		const [ { names, reference }, frame ] = await Promise.all( [ api.takeMarkers( id, takeId ), firstFrame( id, takeId ) ] );
		if ( id !== this.app.projectId ) return;
		this._useNames( names, reference );
		this.frame.show( frame );
		this._mark();
		if ( ! frame ) return;
		const unseen = frame.markers.filter( ( m ) => m.x === null ).map( ( m ) => m.name );
		$( 'custom-note' ).textContent += ' Click a marker on the frame, then its point on the mesh'
			+ ( unseen.length ? ` (${ unseen.join( ', ' ) }, not on the first frame: click ${ unseen.length > 1 ? 'their rows' : 'its row' }).` : '.' );

	}

	/**
	 * A row per marker of a take file (read by the server, not stored).
	 * @param {File|undefined} file
	 */
	async useFile( file ) {

		const id = this.app.projectId;
		if ( ! id || ! file ) return;
		const { names, reference } = await api.takeFileMarkers( id, file );
		$( 'custom-file' ).value = '';
		if ( id !== this.app.projectId ) return;
		this._useNames( names, reference );
		this.frame.show( null ); // a file has no frame to show

	}

	/**
	 * @param {string[]} names - the take's markers.
	 * @param {number[][]|null} reference - where each sat on the take's frames (2D takes
	 *   with every marker seen), kept in the saved layout.
	 */
	_useNames( names, reference ) {

		this._showRows( names.map( ( name, i ) => ( { name, region: guessRegion( name ), side: guessSide( name ), mirror: '', anchor: false, reference: reference?.[ i ] ?? null } ) ) );
		$( 'custom-note' ).textContent = `${ names.length } markers: set each one's region and side, pair left with right, tick 3 that move with the head only (or none), then save.`;

	}

	/** Save the rows as a custom layout of the project and choose it for placing. */
	async save() {

		const app = this.app, id = app.projectId;
		const name = $( 'custom-name' ).value.trim();
		if ( ! id ) throw new ApiError( 0, 'Open a project first.' );
		if ( this.rows.length === 0 ) throw new ApiError( 0, 'Use a take\'s markers first.' );
		if ( ! name ) throw new ApiError( 0, 'Name the layout (letters, digits, _ or -).' );
		const saved = await api.putLayout( id, name, layoutSpec( this.rows, `markers of ${ name }` ) );
		if ( id !== app.projectId ) return;
		await app.loadLayouts( id );
		const select = $( 'layout-select' );
		select.value = saved.name;
		select.dispatchEvent( new Event( 'change' ) );
		const how = this.frame.root.hidden ? 'click them on the mesh in order' : 'click a marker on the frame, then its point on the mesh';
		$( 'custom-note' ).textContent = `Saved ${ name } (${ saved.n_points } points): ${ how }, then Save landmarks.`;

	}

	_showRows( rows ) {

		this.rows = rows;
		this.chosen = null;
		this._pending = false;
		const names = rows.map( ( r ) => r.name );
		const body = $( 'custom-points' ).tBodies[ 0 ];
		body.replaceChildren( ...rows.map( ( row, i ) => {

			const tr = document.createElement( 'tr' );
			const cell = ( child ) => {

				const td = document.createElement( 'td' );
				td.append( child );
				tr.append( td );

			};

			cell( document.createTextNode( row.name ) );
			tr.dataset.marker = row.name;
			tr.cells[ 0 ].title = `${ row.name }: click, then click its point on the mesh`;
			tr.cells[ 0 ].style.cursor = 'pointer';
			tr.cells[ 0 ].addEventListener( 'click', () => this.choose( row.name ) );
			tr.cells[ 0 ].style.overflow = 'hidden';
			tr.cells[ 0 ].style.textOverflow = 'ellipsis';
			cell( choice( REGIONS, row.region, `custom-region-${ i }`, ( v ) => ( row.region = v ) ) );
			cell( choice( SIDES, row.side, `custom-side-${ i }`, ( v ) => ( row.side = v ) ) );
			cell( choice( [ '', ...names.filter( ( n ) => n !== row.name ) ], row.mirror, `custom-mirror-${ i }`, ( v ) => ( row.mirror = v ) ) );
			const anchor = document.createElement( 'input' );
			anchor.type = 'checkbox';
			anchor.id = `custom-anchor-${ i }`;
			anchor.title = 'moves with the head only (a head anchor)';
			anchor.addEventListener( 'change', () => ( row.anchor = anchor.checked ) );
			cell( anchor );
			return tr;

		} ) );
		$( 'custom-save' ).disabled = rows.length === 0;

	}

	/**
	 * Make `name`'s point the next the picker places (or select it, when placed).
	 * @returns {boolean} false when the landmarks' layout has no point of that name.
	 */
	_pointAt( name ) {

		const landmarks = this.app.landmarks;
		const index = landmarks.layout ? landmarks.layout.points.findIndex( ( p ) => p.name === name ) : - 1;
		if ( index < 0 ) return false;
		landmarks.select( index );
		$( 'custom-note' ).textContent = landmarks.state.points[ index ]
			? `${ name } is placed: drag its marker on the mesh to move it.`
			: `Click ${ name }'s point on the mesh.`;
		return true;

	}

	_landmarksChanged() {

		// a marker chosen before the layout was saved: its point comes next once it is chosen
		if ( this._pending && this.chosen ) {

			this._pending = false; // before select, whose change event comes back here
			this._pending = ! this._pointAt( this.chosen );

		}

		this._mark();

	}

	/** Mark the chosen marker's row and label, and the labels of the points placed. */
	_mark() {

		const landmarks = this.app.landmarks, layout = landmarks.layout;
		const placed = new Set( layout ? layout.points.filter( ( _, i ) => landmarks.state.points[ i ] ).map( ( p ) => p.name ) : [] );
		for ( const tr of $( 'custom-points' ).tBodies[ 0 ].rows ) tr.style.background = tr.dataset.marker === this.chosen ? 'rgba(68, 170, 255, 0.25)' : '';
		this.frame.mark( this.chosen, placed );

	}

}

/**
 * A take's first frame and its markers' places, or null for a take tracked from no
 * ring-marker video (404).
 * @returns {Promise<{url: string, size: number[], markers: object[]}|null>}
 */
async function firstFrame( id, takeId ) {

	try {

		return { url: api.takePreviewUrl( id, takeId ), ...await api.takePreviewMarkers( id, takeId ) };

	} catch ( error ) {

		if ( error instanceof ApiError && error.status === 404 ) return null;
		throw error;

	}

}

/** The fold's elements (the page has no markup for it). */
function build( frame ) {

	const root = document.createElement( 'details' );
	root.id = 'custom-layout';
	const summary = document.createElement( 'summary' );
	summary.textContent = 'Custom layout from a take\'s markers';
	const pick = document.createElement( 'div' );
	pick.className = 'row';
	const take = document.createElement( 'select' );
	take.id = 'custom-take';
	take.setAttribute( 'aria-label', 'Take' );
	const markers = button( 'custom-markers', 'Use its markers', 'Make a layout point of each of the take\'s markers' );
	const file = document.createElement( 'input' );
	file.type = 'file';
	file.id = 'custom-file';
	file.accept = '.csv,.json,.npy,.trc,.c3d,.glb,.gltf,.zip';
	file.title = 'or a take file\'s markers (read, not stored)';
	const fileRow = document.createElement( 'div' );
	fileRow.className = 'row';
	fileRow.append( file );
	pick.append( take, markers );
	const table = document.createElement( 'table' );
	table.id = 'custom-points';
	table.style.width = '100%';
	table.style.tableLayout = 'fixed'; // the panel's width, however long the names
	table.style.fontSize = '12px';
	const head = table.createTHead().insertRow();
	for ( const [ title, width ] of [ [ 'Marker', '22%' ], [ 'Region', '32%' ], [ 'Side', '20%' ], [ 'Partner', '17%' ], [ 'Head', '9%' ] ] ) {

		const th = document.createElement( 'th' );
		th.textContent = title;
		th.style.width = width;
		th.style.textAlign = 'left';
		head.append( th );

	}

	table.createTBody();
	const store = document.createElement( 'div' );
	store.className = 'row';
	const name = document.createElement( 'input' );
	name.id = 'custom-name';
	name.placeholder = 'layout name';
	name.maxLength = 64;
	name.setAttribute( 'aria-label', 'Layout name' );
	const save = button( 'custom-save', 'Save layout', 'Save the layout to the project and choose it' );
	save.disabled = true;
	store.append( name, save );
	const note = document.createElement( 'div' );
	note.id = 'custom-note';
	note.className = 'note';
	root.append( summary, pick, fileRow, frame, table, store, note );
	return root;

}

function button( id, text, title ) {

	const element = document.createElement( 'button' );
	element.id = id;
	element.textContent = text;
	element.title = title;
	return element;

}

function choice( values, value, id, onChange ) {

	const select = document.createElement( 'select' );
	select.id = id;
	select.style.width = '100%';
	select.replaceChildren( ...values.map( ( v ) => option( v, v || '—' ) ) );
	select.value = value;
	select.addEventListener( 'change', () => onChange( select.value ) );
	return select;

}

/** A region a marker's name suggests ("LBrow", "mouth_corner_l", "chin"), else cheeks. */
function guessRegion( name ) {

	const n = name.toLowerCase();
	const hints = [ [ /brow/, 'brows' ], [ /eye|lid/, 'eyes' ], [ /nose|nostril/, 'nose' ], [ /corner|mouth/, 'mouth_corners' ],
		[ /upper.*lip|lip.*upper|ulip/, 'upper_lip' ], [ /lower.*lip|lip.*lower|llip/, 'lower_lip' ], [ /chin|jaw/, 'jaw' ],
		[ /forehead|head/, 'forehead' ], [ /cheek/, 'cheeks' ] ];
	return hints.find( ( [ re ] ) => re.test( n ) )?.[ 1 ] ?? 'cheeks';

}

/** The subject's side a marker's name suggests ("left", "_l", "L..."), else center. */
function guessSide( name ) {

	const tokens = name.split( /[_\-\s.]+/ ).map( ( t ) => t.toLowerCase() );
	if ( tokens.includes( 'left' ) || tokens.includes( 'l' ) || /^L[A-Z]/.test( name ) ) return 'left';
	if ( tokens.includes( 'right' ) || tokens.includes( 'r' ) || /^R[A-Z]/.test( name ) ) return 'right';
	return 'center';

}
