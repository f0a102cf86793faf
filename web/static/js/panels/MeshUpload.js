import { ApiError, api } from '../net/api.js';
import { $, guarded, mebibytes } from './dom.js';

/**
 * Mesh upload (index.html: *Upload mesh…*, #upload-progress, and a file dropped on the
 * view). A mesh goes into the open project when that has no landmarks or rig yet, else
 * into a new project named after the file, so an upload never drops work; a refused file
 * changes nothing (a project made for it is deleted again).
 */
export class MeshUpload {

	/**
	 * @param {import('../App.js').App} app
	 */
	constructor( app ) {

		this.app = app;
		this._events = new AbortController();
		this._bind();

	}

	/**
	 * What the server accepts: the file chooser's types and the drop hint.
	 * @param {{mesh_extensions: string[], max_upload_bytes: number}} info - GET /api/info.
	 */
	setInfo( info ) {

		const extensions = info.mesh_extensions.map( ( e ) => '.' + e );
		$( 'file-input' ).accept = extensions.join( ',' );
		$( 'drop-formats' ).textContent = `${ extensions.join( ' ' ) } · up to ${ mebibytes( info.max_upload_bytes ) }`;

	}

	/**
	 * Upload a mesh file and open the project it went into.
	 * @param {File} file
	 */
	async upload( file ) {

		const app = this.app, info = app.info;
		const extensions = info.mesh_extensions;
		const ext = file.name.includes( '.' ) ? file.name.split( '.' ).pop().toLowerCase() : '';
		if ( ! extensions.includes( ext ) ) {

			throw new ApiError( 0, `"${ file.name }" is not a mesh this app reads: use ${ extensions.map( ( e ) => '.' + e ).join( ', ' ) }` );

		}

		if ( file.size === 0 ) throw new ApiError( 0, `"${ file.name }" is empty` );
		if ( file.size > info.max_upload_bytes ) {

			throw new ApiError( 0, `"${ file.name }" is ${ mebibytes( file.size ) }, over the limit of ${ mebibytes( info.max_upload_bytes ) } per upload` );

		}

		let target = app.project;
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

		await app.refreshProjects();
		if ( target.id === app.projectId ) app.landmarks.load( app.landmarks.state.layout ); // the old picks belong to the old mesh
		const from = app.project;
		await app.openProject( target.id, { force: true } );
		if ( created && from ) $( 'landmarks-note' ).textContent = `Uploaded into the new project "${ created.name }"; "${ from.name }" keeps its mesh and landmarks.`;

	}

	/** Stop listening. */
	dispose() {

		this._events.abort();

	}

	_bind() {

		const signal = this._events.signal, guard = ( fn ) => guarded( this.app.errors, fn );
		const input = $( 'file-input' );
		input.addEventListener( 'change', guard( async () => {

			const file = input.files[ 0 ];
			input.value = ''; // choosing the same file again must fire 'change' again
			if ( file ) await this.upload( file );

		} ), { signal } );
		const zone = $( 'drop-zone' );
		let depth = 0; // dragenter/leave fire for every child crossed
		zone.addEventListener( 'dragenter', ( event ) => {

			if ( ! hasFiles( event ) ) return;
			event.preventDefault();
			depth ++;
			zone.classList.add( 'dragging' );

		}, { signal } );
		zone.addEventListener( 'dragover', ( event ) => {

			if ( ! hasFiles( event ) ) return;
			event.preventDefault();
			event.dataTransfer.dropEffect = 'copy';

		}, { signal } );
		zone.addEventListener( 'dragleave', () => {

			if ( -- depth <= 0 ) {

				depth = 0;
				zone.classList.remove( 'dragging' );

			}

		}, { signal } );
		zone.addEventListener( 'drop', guard( async ( event ) => {

			event.preventDefault();
			depth = 0;
			zone.classList.remove( 'dragging' );
			const files = [ ...event.dataTransfer.files ];
			if ( files.length > 1 ) throw new ApiError( 0, `Drop one mesh file at a time (got ${ files.length }).` );
			if ( files.length ) await this.upload( files[ 0 ] );

		} ), { signal } );
		// a file dropped beside the zone must not make the browser navigate away
		window.addEventListener( 'dragover', ( event ) => event.preventDefault(), { signal } );
		window.addEventListener( 'drop', ( event ) => event.preventDefault(), { signal } );

	}

}

function hasFiles( event ) {

	return event.dataTransfer && [ ...event.dataTransfer.types ].includes( 'Files' );

}
