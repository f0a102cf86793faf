import { ApiError, api } from '../net/api.js';
import { $, guarded, mebibytes } from './dom.js';

/**
 * Mesh upload (index.html: *Upload mesh…*, #upload-progress, and files dropped on the
 * view): one mesh file with the files it refers to (an OBJ's MTL and texture images, a
 * glTF's buffers), picked or dropped together, or a zip of them. A mesh goes into the open project when that has no landmarks or rig yet, else
 * into a new project named after the file, so an upload never drops work; a refused file
 * changes nothing (a project made for it is deleted again). An uploaded face then comes
 * alive with no click (`App.animateUpload`: points found, rigged, played).
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
	 * @param {{mesh_extensions: string[], mesh_side_extensions: string[], max_upload_bytes: number}} info -
	 *   GET /api/info.
	 */
	setInfo( info ) {

		const extensions = info.mesh_extensions.map( ( e ) => '.' + e );
		const sides = info.mesh_side_extensions.map( ( e ) => '.' + e );
		$( 'file-input' ).accept = [ ...extensions, ...sides ].join( ',' );
		$( 'drop-formats' ).textContent = `${ extensions.join( ' ' ) } · with ${ sides.join( ' ' ) } · up to ${ mebibytes( info.max_upload_bytes ) }`;

	}

	/**
	 * Upload a mesh file, with the files it refers to, and open the project it went into.
	 * Refused before sending: no mesh or several, a file of another kind, an empty one,
	 * one over the upload limit, too many side files or over twice the limit in all.
	 * @param {File[]} files - one mesh (or zip) and its side files, in any order.
	 */
	async upload( files ) {

		const app = this.app, info = app.info;
		const { mesh: file, sides } = meshAndSides( files, info );
		const total = files.reduce( ( sum, f ) => sum + f.size, 0 );
		if ( sides.length > 0 && total > 2 * info.max_upload_bytes ) {

			throw new ApiError( 0, `the mesh and its files are ${ mebibytes( total ) }, over the limit of ${ mebibytes( 2 * info.max_upload_bytes ) } in all` );

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
		text.textContent = `Uploading ${ file.name }${ sides.length ? ` and ${ sides.length } file${ sides.length > 1 ? 's' : '' }` : '' }…`;
		try {

			await api.uploadMesh( target.id, file, ( fraction ) => {

				bar.value = fraction;
				text.textContent = fraction < 1 ? `Uploading ${ Math.round( fraction * 100 ) }%` : 'Checking the mesh…';

			}, sides );

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
		if ( ! await app.openProject( target.id, { force: true } ) ) return;
		if ( created && from ) $( 'landmarks-note' ).textContent = `Uploaded into the new project "${ created.name }"; "${ from.name }" keeps its mesh and landmarks.`;
		app.animateUpload(); // not awaited: the upload is done; finding, rigging and playing show in their panels

	}

	/** Stop listening. */
	dispose() {

		this._events.abort();

	}

	_bind() {

		const signal = this._events.signal, guard = ( fn ) => guarded( this.app.errors, fn );
		const input = $( 'file-input' );
		input.addEventListener( 'change', guard( async () => {

			const files = [ ...input.files ];
			input.value = ''; // choosing the same files again must fire 'change' again
			if ( files.length ) await this.upload( files );

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
			if ( files.length ) await this.upload( files );

		} ), { signal } );
		// a file dropped beside the zone must not make the browser navigate away
		window.addEventListener( 'dragover', ( event ) => event.preventDefault(), { signal } );
		window.addEventListener( 'drop', ( event ) => event.preventDefault(), { signal } );

	}

}

/**
 * The one mesh (or zip) among `files` and the files it brings along, each checked by name
 * and size against what the server accepts (GET /api/info).
 * @param {File[]} files
 * @returns {{mesh: File, sides: File[]}}
 */
function meshAndSides( files, info ) {

	const extensionOf = ( file ) => file.name.includes( '.' ) ? file.name.split( '.' ).pop().toLowerCase() : '';
	const listed = ( extensions ) => extensions.map( ( e ) => '.' + e ).join( ', ' );
	const meshes = files.filter( ( f ) => info.mesh_extensions.includes( extensionOf( f ) ) );
	const sides = files.filter( ( f ) => info.mesh_side_extensions.includes( extensionOf( f ) ) );
	const other = files.find( ( f ) => ! meshes.includes( f ) && ! sides.includes( f ) );
	if ( other ) {

		throw new ApiError( 0, `"${ other.name }" is not a mesh this app reads nor a file a mesh refers to: use ${ listed( info.mesh_extensions ) }, with ${ listed( info.mesh_side_extensions ) }` );

	}

	if ( meshes.length !== 1 ) {

		const found = meshes.length ? `${ meshes.length } meshes (${ meshes.map( ( f ) => f.name ).join( ', ' ) })` : 'no mesh';
		throw new ApiError( 0, `${ found } among the ${ files.length } files: upload one mesh (${ listed( info.mesh_extensions ) }) at a time, with the files it refers to` );

	}

	const mesh = meshes[ 0 ];
	if ( sides.length && extensionOf( mesh ) === 'zip' ) throw new ApiError( 0, `"${ mesh.name }" is a zip: it holds the mesh's files, so upload it alone` );
	if ( sides.length > info.max_mesh_side_files ) throw new ApiError( 0, `${ sides.length } files with the mesh; it may bring at most ${ info.max_mesh_side_files }` );
	for ( const file of files ) {

		if ( file.size === 0 ) throw new ApiError( 0, `"${ file.name }" is empty` );
		if ( file.size > info.max_upload_bytes ) {

			throw new ApiError( 0, `"${ file.name }" is ${ mebibytes( file.size ) }, over the limit of ${ mebibytes( info.max_upload_bytes ) } per upload` );

		}

	}

	return { mesh, sides };

}

function hasFiles( event ) {

	return event.dataTransfer && [ ...event.dataTransfer.types ].includes( 'Files' );

}
