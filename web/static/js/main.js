import { ApiError, api } from './net/api.js';
import { ErrorBanner, ask } from './dialogs.js';
import { ExportPanel } from './ExportPanel.js';
import { LandmarkPicker } from './LandmarkPicker.js';
import { LayoutGuide } from './LayoutGuide.js';
import { PaintPanel } from './PaintPanel.js';
import { regionColor } from './scene/palette.js';
import { SkinnedFace } from './scene/SkinnedFace.js';
import { StreamClient } from './net/StreamClient.js';
import { StreamDecoder } from './net/wire.js';
import { SourcePanel } from './SourcePanel.js';
import { Viewer } from './scene/Viewer.js';

const DRAFT_DELAY_MS = 400; // unsaved picks reach the server this long after the last edit
const STATS_MS = 250;
const DEFAULT_LAYOUT = 'dutreve21';
const LAST_LAYOUT_KEY = 'retarget.layout';

const $ = ( id ) => document.getElementById( id );

/**
 * The page: a project bar, the viewport with the face, and the landmarks, rig and live
 * panels. One App per page, exposed as `window.app` for the end-to-end tests:
 * {viewer, face, stream, projectId, picker, ready}.
 */
class App {

	constructor() {

		this.viewer = new Viewer( $( 'viewport' ) );
		this.picker = new LandmarkPicker( this.viewer );
		this.guide = new LayoutGuide( $( 'guide' ) );
		this.errors = new ErrorBanner( $( 'error' ) );
		/** @type {SkinnedFace|null} */
		this.face = null;
		/** @type {StreamClient|null} */
		this.stream = null;
		this.projectId = null;
		this.project = null;
		this.projects = [];
		this.layouts = [];
		this.info = null; // GET /api/info: upload limits, mesh formats, rig methods
		this.rigInfo = null; // GET /api/projects/{id}/rig of the shown project
		this.ready = Promise.resolve();

		this._open = 0; // bumps on every project switch: late answers for an old project are dropped
		this._rigJob = null;
		this._draftTimer = 0;
		this._streaming = false;
		this.sources = new SourcePanel( this );
		this.paint = new PaintPanel( this );
		this.exports = new ExportPanel( this );
		this.paint.painter.addEventListener( 'change', () => this._updateHint() );

	}

	/** Whether a source is playing on the stream. */
	get streaming() {

		return this._streaming;

	}

	async start() {

		this._bind();
		let resolveReady;
		this.ready = new Promise( ( resolve ) => ( resolveReady = resolve ) );
		try {

			[ this.info, this.layouts ] = await Promise.all( [ api.info(), api.layouts() ] );
			this._showInfo();
			this.picker.setLayouts( this.layouts );
			$( 'layout-select' ).replaceChildren( ...this.layouts.map( ( layout ) => option( layout.name, `${ layout.name } · ${ layout.n_points } points`, layout.description ) ) );
			await this._refreshProjects();
			const wanted = projectFromHash();
			const id = this.projects.some( ( p ) => p.id === wanted ) ? wanted : this.projects[ 0 ]?.id;
			if ( wanted && id !== wanted ) this.errors.show( `There is no project with id ${ wanted }; showing ${ this._projectName( id ) || 'none' } instead.` );
			if ( id ) await this.openProject( id, { force: true } );
			else this._showProject( null );

		} catch ( error ) {

			this.errors.show( error );

		} finally {

			resolveReady();

		}

		setInterval( () => this._showStats(), STATS_MS );

	}

	/** What the server accepts: rig methods, mesh formats. */
	_showInfo() {

		const info = this.info;
		const methods = $( 'rig-method' );
		methods.replaceChildren( ...info.rig_methods.map( ( m ) => option( m, m ) ) );
		methods.value = info.default_rig_method;
		const extensions = info.mesh_extensions.map( ( e ) => '.' + e );
		$( 'file-input' ).accept = extensions.join( ',' );
		$( 'drop-formats' ).textContent = `${ extensions.join( ' ' ) } · up to ${ mebibytes( info.max_upload_bytes ) }`;

	}

	// projects

	async _refreshProjects() {

		this.projects = await api.projects();
		const select = $( 'project-select' );
		select.replaceChildren( ...this.projects.map( ( p ) => option( p.id, p.name ) ) );
		if ( this.projectId ) select.value = this.projectId;

	}

	_projectName( id ) {

		return this.projects.find( ( p ) => p.id === id )?.name;

	}

	/**
	 * Show a project: its mesh, landmarks (or the unsaved draft), rig and stream.
	 * @param {string} id
	 * @param {{force?: boolean}} [options] - force: reload even if it is the current one.
	 * @returns {Promise<boolean>} false when the switch was cancelled.
	 */
	async openProject( id, { force = false } = {} ) {

		if ( id === this.projectId && ! force ) return true;
		let resolveReady;
		this.ready = new Promise( ( resolve ) => ( resolveReady = resolve ) );
		const ticket = ++ this._open;
		try {

			await this._flushDraft();
			await this.paint.flush();
			this._closeProject();
			this.projectId = id;
			$( 'project-select' ).value = id;
			history.replaceState( null, '', `#p=${ encodeURIComponent( id ) }` );
			const project = await api.project( id );
			if ( ticket !== this._open ) return false;
			this.project = project;
			this._showProject( project );

			if ( project.mesh ) {

				$( 'hint' ).textContent = 'Loading the mesh…';
				const arrays = await api.meshArrays( id );
				const face = await SkinnedFace.create( arrays );
				if ( ticket !== this._open ) {

					face.dispose();
					return false;

				}

				this.face = face;
				this.viewer.setObject( face.mesh );
				this.viewer.setWireframe( $( 'wireframe' ).checked );
				this.picker.setMesh( face.mesh );
				$( 'mesh-info' ).textContent = meshInfo( project.mesh, arrays.positions );

			}

			await this._loadLandmarks( project, ticket );
			if ( ticket !== this._open ) return false;
			if ( project.rig && this.face ) await this._loadRig( ticket );
			if ( ticket !== this._open ) return false;
			this._updateLive();
			if ( project.landmarks ) this._connectStream();
			await this.sources.setProject( project );
			await this.exports.setProject( project );
			return true;

		} catch ( error ) {

			if ( ticket === this._open ) this.errors.show( error );
			return false;

		} finally {

			if ( ticket === this._open ) {

				this._updateHint();
				this._updateLive();
				resolveReady();

			}

		}

	}

	/** Drop everything of the current project from the page (not from the server). */
	_closeProject() {

		clearTimeout( this._draftTimer );
		this._rigJob?.abort();
		this._rigJob = null;
		if ( this.stream ) {

			const stream = this.stream;
			this.stream = null; // first: its 'closed' status is no news to report
			stream.close();

		}

		this._streaming = false;
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
		this.rigInfo = null;
		$( 'mesh-info' ).textContent = '';
		$( 'landmarks-note' ).textContent = '';
		$( 'rig-progress' ).value = 0;
		$( 'rig-message' ).textContent = '';
		$( 'status' ).textContent = 'offline';
		$( 'status' ).className = 'badge';

	}

	_showProject( project ) {

		$( 'project-name' ).value = project ? project.name : '';
		$( 'project-name' ).disabled = ! project;
		$( 'delete-project' ).disabled = ! project;
		$( 'empty-hint' ).hidden = ! project || !! project.mesh;
		if ( ! project ) this.viewer.setObject( null );
		this._updateRigInfo();

	}

	async _loadLandmarks( project, ticket ) {

		let saved = null;
		if ( project.landmarks ) saved = await api.landmarks( project.id );
		if ( ticket !== this._open ) return;
		const known = ( name ) => this.layouts.some( ( l ) => l.name === name );
		let layout = saved?.layout || project.landmarks?.layout || '';
		if ( saved && ! known( layout ) ) {

			// landmarks saved without a layout (e.g. through the API): any layout of that size fits
			const n = saved.triangles ? saved.triangles.length : saved.vertex_indices.length;
			layout = this.layouts.find( ( l ) => l.n_points === n )?.name || '';
			if ( ! layout ) {

				this.errors.show( `The project's ${ n } saved landmarks match no layout; pick them again.` );
				saved = null;

			}

		}

		if ( ! saved ) layout = known( localStorage.getItem( LAST_LAYOUT_KEY ) ) ? localStorage.getItem( LAST_LAYOUT_KEY ) : DEFAULT_LAYOUT;
		this.picker.load( layout, saved );

		const draft = project.settings?.draft;
		if ( draft && draft.revision === project.revision && known( draft.layout ) && this.face ) {

			try {

				this.picker.replace( draft.layout, draft.points.map( ( p ) => p && { triangle: p.slice( 0, 3 ), barycentric: p.slice( 3, 6 ) } ) );
				$( 'landmarks-note' ).textContent = 'Unsaved points restored from your last visit (Undo drops them).';

			} catch ( error ) {

				console.warn( 'retarget: draft ignored:', error.message );

			}

		}

		this._fillLandmarkLists( project );

	}

	/** The heat-map features and the region toggles follow the saved landmarks (the rig's joints, the stream's points). */
	_fillLandmarkLists( project ) {

		const layout = this.layouts.find( ( l ) => l.name === project?.landmarks?.layout ) || this.picker.layout;
		const heatmap = $( 'heatmap-select' );
		const jointNames = project?.landmarks ? ( layout && layout.n_points === project.landmarks.n_points ? layout.points.map( ( p ) => p.name ) : range( project.landmarks.n_points ).map( ( j ) => `feature ${ j }` ) ) : [];
		heatmap.replaceChildren( option( '', 'off' ), ...jointNames.map( ( name, j ) => option( String( j ), `${ j } · ${ name }` ) ) );
		heatmap.disabled = ! this.face?.nJoints;

		const regions = layout ? layout.regions.filter( ( region ) => layout.points.some( ( p ) => p.region === region ) ) : [];
		const fieldset = $( 'regions' );
		fieldset.replaceChildren( fieldset.querySelector( 'legend' ), ...regions.map( ( region ) => {

			const label = document.createElement( 'label' );
			const box = document.createElement( 'input' );
			box.type = 'checkbox';
			box.checked = true;
			box.dataset.region = region;
			const swatch = document.createElement( 'span' );
			swatch.className = 'swatch';
			swatch.style.background = regionColor( region );
			label.append( box, swatch, region.replace( /_/g, ' ' ) );
			return label;

		} ) );

	}

	async _loadRig( ticket ) {

		const id = this.projectId;
		const [ info, weights ] = await Promise.all( [ api.rig( id ), api.rigWeights( id ) ] );
		if ( ticket !== this._open || ! this.face ) return;
		this.face.setRig( weights );
		this.face.setHeatmap( null );
		$( 'heatmap-select' ).value = '';
		$( 'heatmap-select' ).disabled = false;
		this.rigInfo = info;
		this._updateRigInfo();
		this.paint.setRig( info, weights );

	}

	async _newProject() {

		const taken = new Set( this.projects.map( ( p ) => p.name ) );
		let n = 1;
		while ( taken.has( `Untitled ${ n }` ) ) n ++;
		const project = await api.createProject( `Untitled ${ n }` );
		await this._refreshProjects();
		if ( await this.openProject( project.id ) ) {

			$( 'project-name' ).focus();
			$( 'project-name' ).select();

		}

		return project;

	}

	async _renameProject() {

		const input = $( 'project-name' );
		const name = input.value.trim();
		if ( ! this.project || ! name || name === this.project.name ) {

			input.value = this.project ? this.project.name : '';
			return;

		}

		try {

			this.project = await api.patchProject( this.project.id, { name } );
			await this._refreshProjects();

		} catch ( error ) {

			input.value = this.project.name;
			this.errors.show( error );

		}

	}

	async _deleteProject() {

		if ( ! this.project ) return;
		const answer = await ask( `Delete the project "${ this.project.name }" with its mesh, landmarks and rig? This cannot be undone.`, { ok: 'Delete' } );
		if ( answer !== 'ok' ) return;
		const id = this.project.id;
		await api.deleteProject( id );
		this.picker.load( this.picker.state.layout || DEFAULT_LAYOUT ); // nothing left to save
		this._closeProject();
		this.projectId = null;
		await this._refreshProjects();
		if ( this.projects.length ) await this.openProject( this.projects[ 0 ].id );
		else {

			history.replaceState( null, '', location.pathname );
			this._showProject( null );
			this._updateLive();

		}

	}

	// upload

	/**
	 * Upload a mesh file. It goes into the current project when that has no landmarks or
	 * rig yet, else into a new project named after the file, so an upload never drops
	 * work. A refused file changes nothing (a project made for it is deleted again).
	 * @param {File} file
	 */
	async upload( file ) {

		const extensions = this.info.mesh_extensions;
		const ext = file.name.includes( '.' ) ? file.name.split( '.' ).pop().toLowerCase() : '';
		if ( ! extensions.includes( ext ) ) {

			throw new ApiError( 0, `"${ file.name }" is not a mesh this app reads: use ${ extensions.map( ( e ) => '.' + e ).join( ', ' ) }` );

		}

		if ( file.size === 0 ) throw new ApiError( 0, `"${ file.name }" is empty` );
		if ( file.size > this.info.max_upload_bytes ) {

			throw new ApiError( 0, `"${ file.name }" is ${ mebibytes( file.size ) }, over the limit of ${ mebibytes( this.info.max_upload_bytes ) } per upload` );

		}

		let target = this.project;
		let created = null;
		if ( ! target || target.landmarks || target.rig ) {

			created = await api.createProject( file.name.replace( /\.[^.]+$/, '' ) || 'Untitled' );
			target = created;

		}

		const bar = $( 'upload-progress' ), text = $( 'upload-text' );
		bar.hidden = false;
		bar.value = 0;
		text.textContent = `Uploading ${ file.name }…`;
		try {

			await api.uploadMesh( target.id, file, ( fraction ) => {

				bar.value = fraction;
				text.textContent = fraction < 1 ? `Uploading ${ Math.round( fraction * 100 ) }%` : 'Checking the mesh…';

			} );

		} catch ( error ) {

			if ( created ) await api.deleteProject( created.id ).catch( () => {} );
			throw error;

		} finally {

			bar.hidden = true;
			text.textContent = '';

		}

		await this._refreshProjects();
		if ( target.id === this.projectId ) this.picker.load( this.picker.state.layout ); // the old picks belong to the old mesh
		const from = this.project;
		await this.openProject( target.id, { force: true } );
		if ( created && from ) $( 'landmarks-note' ).textContent = `Uploaded into the new project "${ created.name }"; "${ from.name }" keeps its mesh and landmarks.`;

	}

	// landmarks

	async _switchLayout( name ) {

		const picker = this.picker;
		const select = $( 'layout-select' );
		if ( name === picker.state.layout ) return;
		if ( picker.placedCount > 0 ) {

			const dropped = picker.droppedBy( name );
			const kept = picker.placedCount - dropped;
			const answer = await ask(
				`Switch the layout to ${ name }? ` + ( dropped ? `${ dropped } placed point${ dropped > 1 ? 's have' : ' has' } no counterpart there and will be dropped` : 'Every placed point carries over' )
				+ ( kept && dropped ? `; ${ kept } carry over by name.` : '.' ) + ' Undo switches back.',
				{ ok: 'Switch layout' } );
			if ( answer !== 'ok' ) {

				select.value = picker.state.layout;
				return;

			}

		}

		picker.setLayout( name );
		localStorage.setItem( LAST_LAYOUT_KEY, name );

	}

	async _saveLandmarks() {

		const picker = this.picker;
		if ( ! this.project?.mesh ) throw new ApiError( 0, 'Upload a mesh before placing landmarks.' );
		if ( ! picker.dirty && this.project.landmarks ) return;
		const missing = picker.missing();
		if ( missing.length ) {

			const shown = missing.slice( 0, 8 ).join( ', ' ) + ( missing.length > 8 ? `, … (${ missing.length - 8 } more)` : '' );
			throw new ApiError( 0, `Cannot save yet: ${ missing.length } of ${ picker.points.length } points are not placed (${ shown }). Next: ${ missing[ 0 ] }.` );

		}

		const id = this.projectId, ticket = this._open;
		clearTimeout( this._draftTimer ); // the save supersedes the draft
		$( 'save-landmarks' ).disabled = true;
		try {

			const sent = picker.state;
			await api.putLandmarks( id, picker.toJSON() );
			if ( ticket !== this._open ) return;
			// the points saved are the ones sent, even if the user edited while the request ran
			picker.markSaved( sent );
			this.project = await api.patchProject( id, { settings: { draft: null } } );
			if ( ticket !== this._open ) return;
			// new landmarks drop the old rig and change the stream's points
			this.rigInfo = null;
			this.face?.setRig( null );
			this.face?.setHeatmap( null );
			this.paint.setRig( null, null );
			this._fillLandmarkLists( this.project );
			this._updateRigInfo();
			$( 'landmarks-note' ).textContent = 'Saved. Compute the rig to animate the face.';
			this._connectStream();
			this._updateLive();

		} finally {

			this._updateLandmarkUI();

		}

	}

	_updateLandmarkUI() {

		const picker = this.picker;
		const layout = picker.layout;
		const next = picker.next;
		const hasMesh = !! this.face;
		$( 'layout-select' ).value = picker.state.layout;
		$( 'landmark-count' ).textContent = layout ? `${ picker.placedCount } / ${ layout.n_points }` : '';
		$( 'landmark-count' ).className = 'badge' + ( layout && picker.placedCount === layout.n_points ? ' good' : '' );
		$( 'unsaved' ).hidden = ! picker.dirty || ! hasMesh;
		$( 'next-point' ).textContent = ! layout ? '' : next >= 0 ? layout.points[ next ].name : 'all placed ✓';
		$( 'undo' ).disabled = ! picker.canUndo;
		$( 'redo' ).disabled = ! picker.canRedo;
		$( 'delete-point' ).disabled = picker.selected < 0;
		$( 'mirror' ).disabled = ! hasMesh || ! this._canMirror();
		$( 'clear-points' ).disabled = picker.placedCount === 0;
		$( 'save-landmarks' ).disabled = ! hasMesh || ! picker.dirty; // saving drops the rig: only when something changed
		this.guide.setLayout( layout );
		this.guide.update( { placed: picker.points.map( Boolean ), next: hasMesh ? next : - 1, selected: picker.selected } );
		this._updateHint();
		this._updateLive();

	}

	_canMirror() {

		const layout = this.picker.layout, points = this.picker.points;
		return !! layout && layout.points.some( ( p, i ) => points[ i ] && p.mirror !== i && ! points[ p.mirror ] );

	}

	_updateHint( hovered = this.picker.hovered ) {

		const layout = this.picker.layout;
		let text = '';
		if ( ! this.project ) text = 'Create a project to start.';
		else if ( ! this.face ) text = '';
		else if ( this.paint.active ) text = this.paint.hint();
		else if ( hovered >= 0 && layout ) text = `${ layout.points[ hovered ].name } · drag to slide it over the surface`;
		else if ( layout && this.picker.next >= 0 ) text = `Click the mesh to place ${ layout.points[ this.picker.next ].name } · drag a marker to move it · Shift+click selects`;
		else if ( this.picker.selected >= 0 && layout ) text = `${ layout.points[ this.picker.selected ].name } selected · Delete removes it`;
		else text = 'Drag to orbit · right-drag pans · wheel zooms · F frames the face';
		$( 'hint' ).textContent = text;

	}

	/** Keep unsaved picks on the server (project settings) so a reload or crash loses nothing. */
	_scheduleDraft() {

		clearTimeout( this._draftTimer );
		if ( ! this.project || ! this.face ) return;
		const project = this.project;
		const hadDraft = !! project.settings?.draft;
		if ( ! this.picker.dirty && ! hadDraft ) return;
		this._draftTimer = setTimeout( () => this._flushDraft(), DRAFT_DELAY_MS );

	}

	/** @param {{keepalive?: boolean}} [options] - keepalive: the page is being unloaded. */
	async _flushDraft( { keepalive = false } = {} ) {

		clearTimeout( this._draftTimer );
		this._draftTimer = 0;
		const project = this.project;
		if ( ! project || ! this.face ) return;
		const picker = this.picker;
		const draft = picker.dirty ? {
			revision: project.revision,
			layout: picker.state.layout,
			points: picker.points.map( ( p ) => p && [ ...p.triangle, ...p.barycentric ] ),
		} : null;
		if ( ! draft && ! project.settings?.draft ) return;
		try {

			const updated = await api.patchProject( project.id, { settings: { draft } }, { keepalive } );
			if ( this.project && this.project.id === updated.id ) this.project = updated;

		} catch ( error ) {

			this.errors.show( error );

		}

	}

	// rig

	async _computeRig() {

		if ( ! this.project?.mesh ) throw new ApiError( 0, 'Upload a mesh first.' );
		if ( this.picker.dirty || ! this.project.landmarks ) {

			// the rig is built from the saved landmarks: save the ones on screen first
			await this._saveLandmarks();

		}

		const id = this.projectId, ticket = this._open;
		const method = $( 'rig-method' ).value;
		const bar = $( 'rig-progress' ), message = $( 'rig-message' ), button = $( 'rig-button' );
		button.disabled = true;
		bar.value = 0;
		message.textContent = `Starting ${ method }…`;
		const t0 = performance.now();
		this._rigJob?.abort(); // a newer rig replaces the one followed so far
		const follow = this._rigJob = new AbortController();
		try {

			const started = await api.startRig( id, method );
			let job;
			try {

				job = await api.waitJob( started.id, ( { progress, detail } ) => {

					bar.value = progress;
					message.textContent = `${ Math.round( progress * 100 ) }% · ${ detail || method }`;

				}, { what: `Rig (${ method })`, signal: follow.signal } );

			} catch ( error ) {

				if ( follow.signal.aborted ) return; // another project or another rig
				bar.value = 0;
				message.textContent = 'Failed.';
				throw error;

			}

			if ( ticket !== this._open ) return;
			bar.value = 1;
			message.textContent = `${ job.detail || 'done' } · ${ ( ( performance.now() - t0 ) / 1000 ).toFixed( 1 ) } s`;
			this.project = await api.project( id );
			await this._loadRig( ticket );
			this._updateLive();

		} finally {

			if ( ticket === this._open ) button.disabled = false;

		}

	}

	_updateRigInfo() {

		const info = this.project?.rig ? this.rigInfo : null;
		$( 'rig-info' ).textContent = info ? `${ info.method } · ${ info.n_joints } joints · k ${ info.n_influences }` : this.project?.mesh ? 'none' : '';
		$( 'rig-info' ).className = 'badge' + ( info ? ' good' : '' );
		if ( info ) $( 'rig-method' ).value = info.method;

	}

	// live

	_connectStream() {

		const old = this.stream;
		const stream = new StreamClient( this.projectId );
		this.stream = stream; // before closing the old one, whose 'closed' status is then ignored
		old?.close();
		this._streaming = false;
		stream.addEventListener( 'status', ( event ) => {

			if ( stream !== this.stream ) return;
			const { state, reason } = event.detail;
			const badge = $( 'status' );
			badge.textContent = state;
			badge.className = 'badge' + ( state === 'open' ? ' good' : state === 'closed' ? ' bad' : ' warn' );
			badge.title = reason || '';
			if ( state !== 'open' ) this._setStreaming( false );
			if ( state === 'closed' && reason ) this.errors.show( `Live stream closed: ${ reason }` );

		} );
		stream.addEventListener( 'frame', ( event ) => {

			if ( stream !== this.stream || ! this.face ) return;
			const frame = event.detail;
			this.face.setDisplacements( frame.displacements );
			this._turnHead( frame.headRotation );
			this.picker.setDisplacements( frame.displacements );
			stream.markApplied( frame );
			if ( frame.flags & StreamDecoder.FLAG_LAST ) this._setStreaming( false );

		} );
		stream.addEventListener( 'message', ( event ) => {

			if ( stream !== this.stream ) return;
			const message = event.detail;
			if ( message.type === 'started' ) this._setStreaming( true );
			else if ( message.type === 'stopped' ) this._setStreaming( false );
			else if ( message.type === 'error' ) this.errors.show( `Live stream: ${ message.detail }` );
			else this.sources.onMessage( message );

		} );
		stream.connect();

	}

	/** What the demo still needs, or '' when it can run. */
	_liveMissing() {

		if ( ! this.project ) return 'Create a project first.';
		if ( ! this.project.mesh ) return 'Upload a mesh first.';
		if ( ! this.project.landmarks ) return `Place and save the ${ this.picker.layout?.n_points ?? '' } landmarks first (${ this.picker.placedCount } placed).`;
		if ( ! this.project.rig ) return 'Compute the rig first: the stream moves the feature points, the rig carries them to the skin.';
		return '';

	}

	_updateLive() {

		const missing = this._liveMissing();
		const note = $( 'live-note' );
		note.textContent = missing || ( this.picker.dirty && this.project?.landmarks ? 'The stream drives the saved landmarks; save to use your edits.' : '' );
		note.className = 'note' + ( missing ? ' warn' : '' );
		$( 'play' ).title = missing || 'Play the chosen performance source on this face';
		$( 'stop' ).disabled = ! this._streaming;

	}

	_setStreaming( on ) {

		this._streaming = on;
		$( 'play' ).textContent = on ? '↻ Restart' : '▶ Play';
		$( 'stop' ).disabled = ! on;
		if ( ! on ) {

			$( 'fps' ).textContent = '–';
			this._turnHead( null );
			this.sources.onStopped();

		}

	}

	async _play() {

		const missing = this._liveMissing();
		if ( missing ) {

			this.errors.show( `Cannot play: ${ missing }` );
			return;

		}

		if ( ! this.stream ) this._connectStream();
		const start = await this.sources.startMessage();
		this._sendMask();
		this.stream.send( start );

	}

	_stop() {

		this.stream?.send( { type: 'stop' } );
		this.sources.stopWebcam();
		this._setStreaming( false );

	}

	/**
	 * Turn the face by the performer's head rotation (a source's head pose, when the
	 * conditioning applies it), about the centre of its rest bounding sphere.
	 * @param {Float32Array|null} q - quaternion x, y, z, w; null puts the face back.
	 */
	_turnHead( q ) {

		const mesh = this.face?.mesh;
		if ( ! mesh ) return;
		if ( q ) mesh.quaternion.set( q[ 0 ], q[ 1 ], q[ 2 ], q[ 3 ] );
		else mesh.quaternion.identity();
		if ( ! mesh.geometry.boundingSphere ) mesh.geometry.computeBoundingSphere();
		const centre = mesh.geometry.boundingSphere.center;
		mesh.position.copy( centre ).applyQuaternion( mesh.quaternion ).negate().add( centre );

	}

	_sendMask() {

		const boxes = [ ...$( 'regions' ).querySelectorAll( 'input[data-region]' ) ];
		const on = boxes.filter( ( b ) => b.checked ).map( ( b ) => b.dataset.region );
		this.stream?.send( { type: 'mask', regions: on.length === boxes.length ? null : on } );

	}

	_showStats() {

		const stream = this.stream;
		if ( ! stream || ! this._streaming || ! stream.stats.frames ) return;
		const { fps, latencyMs } = stream.stats;
		$( 'fps' ).textContent = fps.toFixed( 0 );
		if ( Number.isFinite( latencyMs.median ) ) $( 'latency' ).textContent = `${ latencyMs.median.toFixed( 1 ) } / ${ latencyMs.p99.toFixed( 1 ) } ms`;

	}

	// wiring

	_bind() {

		const guard = ( fn ) => async ( ...args ) => {

			try {

				await fn( ...args );

			} catch ( error ) {

				this.errors.show( error );

			}

		};

		$( 'project-select' ).addEventListener( 'change', guard( async ( event ) => {

			const id = event.target.value;
			if ( ! await this.openProject( id ) && this.projectId !== id ) event.target.value = this.projectId;

		} ) );
		$( 'new-project' ).addEventListener( 'click', guard( () => this._newProject() ) );
		$( 'delete-project' ).addEventListener( 'click', guard( () => this._deleteProject() ) );
		$( 'project-name' ).addEventListener( 'change', guard( () => this._renameProject() ) );
		$( 'project-name' ).addEventListener( 'keydown', ( event ) => {

			if ( event.key === 'Enter' ) event.target.blur();
			if ( event.key === 'Escape' ) {

				event.target.value = this.project?.name ?? '';
				event.target.blur();

			}

		} );
		window.addEventListener( 'hashchange', guard( () => {

			const id = projectFromHash();
			if ( id && id !== this.projectId ) return this.openProject( id );

		} ) );

		const input = $( 'file-input' );
		input.addEventListener( 'change', guard( async () => {

			const file = input.files[ 0 ];
			input.value = ''; // choosing the same file again must fire 'change' again
			if ( file ) await this.upload( file );

		} ) );
		const zone = $( 'drop-zone' );
		let depth = 0; // dragenter/leave fire for every child crossed
		zone.addEventListener( 'dragenter', ( event ) => {

			if ( ! hasFiles( event ) ) return;
			event.preventDefault();
			depth ++;
			zone.classList.add( 'dragging' );

		} );
		zone.addEventListener( 'dragover', ( event ) => {

			if ( ! hasFiles( event ) ) return;
			event.preventDefault();
			event.dataTransfer.dropEffect = 'copy';

		} );
		zone.addEventListener( 'dragleave', () => {

			if ( -- depth <= 0 ) {

				depth = 0;
				zone.classList.remove( 'dragging' );

			}

		} );
		zone.addEventListener( 'drop', guard( async ( event ) => {

			event.preventDefault();
			depth = 0;
			zone.classList.remove( 'dragging' );
			const files = [ ...event.dataTransfer.files ];
			if ( files.length > 1 ) throw new ApiError( 0, `Drop one mesh file at a time (got ${ files.length }).` );
			if ( files.length ) await this.upload( files[ 0 ] );

		} ) );
		// a file dropped beside the zone must not make the browser navigate away
		window.addEventListener( 'dragover', ( event ) => event.preventDefault() );
		window.addEventListener( 'drop', ( event ) => event.preventDefault() );

		$( 'wireframe' ).addEventListener( 'change', ( event ) => this.viewer.setWireframe( event.target.checked ) );
		$( 'frame-view' ).addEventListener( 'click', () => this.viewer.frame() );

		const picker = this.picker;
		picker.addEventListener( 'change', () => {

			this._updateLandmarkUI();
			this._scheduleDraft();

		} );
		picker.addEventListener( 'hover', ( event ) => this._updateHint( event.detail.index ) );
		this.guide.addEventListener( 'pick', ( event ) => picker.select( event.detail.index ) );
		$( 'layout-select' ).addEventListener( 'change', guard( ( event ) => this._switchLayout( event.target.value ) ) );
		$( 'undo' ).addEventListener( 'click', () => picker.undo() );
		$( 'redo' ).addEventListener( 'click', () => picker.redo() );
		$( 'delete-point' ).addEventListener( 'click', () => picker.deleteSelected() );
		$( 'mirror' ).addEventListener( 'click', () => this._mirror() );
		$( 'clear-points' ).addEventListener( 'click', () => picker.clear() );
		$( 'save-landmarks' ).addEventListener( 'click', guard( () => this._saveLandmarks() ) );

		$( 'rig-button' ).addEventListener( 'click', guard( () => this._computeRig() ) );
		$( 'heatmap-select' ).addEventListener( 'change', ( event ) => {

			this.face?.setHeatmap( event.target.value === '' ? null : Number( event.target.value ) );

		} );

		$( 'play' ).addEventListener( 'click', guard( () => this._play() ) );
		$( 'stop' ).addEventListener( 'click', () => this._stop() );
		$( 'regions' ).addEventListener( 'change', () => this._sendMask() );

		window.addEventListener( 'keydown', guard( ( event ) => this._key( event ) ) );
		window.addEventListener( 'beforeunload', () => {

			if ( this._draftTimer ) this._flushDraft( { keepalive: true } );

		} );

	}

	_mirror() {

		const placed = this.picker.mirror();
		$( 'landmarks-note' ).textContent = placed ? `Mirrored ${ placed } point${ placed > 1 ? 's' : '' } across x = ${ this.picker.symmetryX().toPrecision( 4 ) }.` : 'Nothing to mirror: every placed point has its partner.';

	}

	async _key( event ) {

		const target = event.target;
		if ( target.closest?.( 'dialog[open]' ) ) return;
		const typing = target instanceof HTMLInputElement && target.type !== 'checkbox' || target instanceof HTMLSelectElement || target instanceof HTMLTextAreaElement;
		const mod = event.ctrlKey || event.metaKey;
		const key = event.key.toLowerCase();
		if ( key === 'escape' ) {

			if ( this.errors.visible ) this.errors.clear();
			else this.picker.select( - 1 );
			return;

		}

		if ( typing ) return;
		if ( this.paint.key( event ) ) {

			event.preventDefault();
			return;

		}

		if ( mod && key === 'z' ) {

			event.preventDefault();
			if ( event.shiftKey ) this.picker.redo();
			else this.picker.undo();

		} else if ( mod && key === 'y' ) {

			event.preventDefault();
			this.picker.redo();

		} else if ( mod && key === 's' ) {

			event.preventDefault();
			await this._saveLandmarks();

		} else if ( mod || event.altKey ) {

			return;

		} else if ( key === 'delete' || key === 'backspace' ) {

			if ( this.picker.deleteSelected() ) event.preventDefault();

		} else if ( key === 'm' ) {

			this._mirror();

		} else if ( key === 'w' ) {

			$( 'wireframe' ).click();

		} else if ( key === 'f' ) {

			this.viewer.frame();

		}

	}

}

function option( value, text, title = '' ) {

	const element = document.createElement( 'option' );
	element.value = value;
	element.textContent = text;
	if ( title ) element.title = title;
	return element;

}

function projectFromHash() {

	const match = /(?:^#|&)p=([^&]+)/.exec( location.hash );
	return match ? decodeURIComponent( match[ 1 ] ) : null;

}

function hasFiles( event ) {

	return event.dataTransfer && [ ...event.dataTransfer.types ].includes( 'Files' );

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

function mebibytes( bytes ) {

	return `${ Number( ( bytes / 2 ** 20 ).toPrecision( 3 ) ) } MiB`;

}

function range( n ) {

	return Array.from( { length: n }, ( _, i ) => i );

}

const app = new App();
window.app = app;
app.start();
