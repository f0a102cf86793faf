import { api } from '../net/api.js';
import { trackVideo } from '../tracking/videoTake.js';
import { $ } from './dom.js';
import { StereoTrackDialog } from './StereoTrackDialog.js';

const TAKE_EXTENSIONS = [ 'csv', 'json', 'npy', 'trc', 'c3d', 'glb', 'gltf', 'zip' ];

/**
 * New takes for the Performance panel: *Import take…* (a file the server reads) and
 * *Track…* a video, markerless in this page (tracking/), ring markers on the server (a
 * job, its progress in the bar), or a stereo pair of colour-marker videos (its own form,
 * StereoTrackDialog). Each new take becomes the chosen one.
 */
export class TakeImport {

	/**
	 * @param {import('../App.js').App} app
	 * @param {import('./TakeList.js').TakeList} list - where new takes are chosen.
	 * @param {import('./SourceStatus.js').SourceStatus} status - the panel's note and bar.
	 * @param {(take: string) => Promise<void>} onTake - a new take is stored: choose it.
	 */
	constructor( app, list, status, onTake ) {

		this.app = app;
		this.list = list;
		this.status = status;
		this.onTake = onTake;
		this._abort = null; // the in-page video tracking, stopped by another project
		this.stereo = new StereoTrackDialog( {
			projectId: () => this.app.projectId,
			status,
			onTracked: onTake,
		} );
		this._events = new AbortController();
		this._bind();

	}

	/** Another project: an in-page tracking stops. */
	stop() {

		this._abort?.abort( new Error( 'Video tracking stopped: another project was opened.' ) );

	}

	/**
	 * Import a take file.
	 * @param {File} file - csv, json, npy, trc, c3d, glb, gltf or zip.
	 */
	async importTake( file ) {

		const ext = file.name.split( '.' ).pop().toLowerCase();
		if ( ! TAKE_EXTENSIONS.includes( ext ) ) throw new Error( `${ file.name }: a take is read from ${ TAKE_EXTENSIONS.map( ( e ) => '.' + e ).join( ', ' ) }.` );
		const fields = ext === 'npy' ? { layout: this.app.sources.layout().name } : {};
		const info = await this.status.withProgress( `Uploading ${ file.name }…`, ( progress ) => api.uploadTake( this.app.projectId, file, fields, progress ) );
		this.status.note( `Imported "${ info.name }": ${ info.n_frames } frames of ${ info.n_points } points (${ info.source }).` );
		await this.onTake( info.id );

	}

	/**
	 * Track a video into a take by the method chosen (markerless or ring markers).
	 * @param {File} file
	 */
	async trackVideoFile( file ) {

		const method = $( 'video-method' ).value;
		if ( method === 'markers' ) return this._trackOnServer( file );
		const id = this.app.projectId;
		const layout = this.app.sources.layout();
		const controller = new AbortController();
		this._abort = controller; // another project stops it
		const result = await this.status.withProgress( `Tracking ${ file.name } in this page…`, ( progress ) => trackVideo( file, {
			layoutIndices: layout.points.map( ( p ) => p.mediapipe468 ),
			signal: controller.signal,
			onProgress: ( { done, total, faces } ) => {

				if ( total ) progress( done / total );
				this.status.note( `Tracking ${ file.name }: frame ${ done }${ total ? ' / ' + total : '' }, a face in ${ faces }.` );

			},
		} ) );
		if ( result.faces === 0 ) throw new Error( `No face was found in ${ file.name } (${ result.n_frames } frames): nothing to keep.` );
		const npy = new File( [ npyBytes( result.points, [ result.n_frames, result.n_points, 3 ] ) ], file.name.replace( /\.[^.]*$/, '' ) + '.npy' );
		const info = await api.uploadTake( id, npy, { layout: layout.name, fps: result.fps, name: file.name.replace( /\.[^.]*$/, '' ).slice( 0, 200 ), source: `video: ${ file.name }`.slice( 0, 200 ) } ); // the server takes 200 characters of each
		if ( id !== this.app.projectId ) return; // kept in its project; this one lists its own takes
		const share = result.faces / result.n_frames;
		this.status.note( `Tracked "${ info.name }": ${ result.n_frames } frames at ${ +result.fps.toFixed( 3 ) } fps, a face in ${ ( 100 * share ).toFixed( 0 ) } % of them (${ ( result.n_frames / result.seconds ).toFixed( 1 ) } frames tracked a second).`, share < 0.9 );
		await this.onTake( info.id );

	}

	/** Stop listening; remove the stereo form. */
	dispose() {

		this._events.abort();
		this.stereo.dispose();

	}

	async _trackOnServer( file ) {

		const id = this.app.projectId, status = this.status;
		const job = await status.withProgress( `Uploading ${ file.name }…`, ( progress ) => api.trackVideo( id, file, { method: 'markers', layout: 'dutreve21' }, progress ) );
		status.bar.value = 0; // the job's share done, no longer the upload's
		status.bar.hidden = false;
		let result; // {take, frames, truncated?, frames_claimed?}
		try {

			( { result } = await api.waitJob( job.id, ( state ) => {

				status.bar.value = state.progress;
				status.note( `Tracking the markers of ${ file.name } on the server: ${ ( 100 * state.progress ).toFixed( 0 ) } %` );

			}, { what: 'Marker tracking' } ) );

		} finally {

			status.bar.hidden = true;

		}

		$( 'source-select' ).value = 'take';
		if ( id !== this.app.projectId ) return;
		await this.list.select( result.take );
		const info = this.list.takes.find( ( t ) => t.id === result.take );
		let text = `Tracked "${ info?.name ?? file.name }": ${ info?.n_points ?? '' } markers in ${ result.frames } frames of ${ file.name }.`;
		// a cut-off file still gives its frames up to the cut: say so, or the take looks whole
		if ( result.truncated ) text += ` The file is cut off: only ${ result.frames } of the ${ result.frames_claimed } frames it announces could be read.`;
		status.note( text, result.truncated );

	}

	_bind() {

		const signal = this._events.signal;
		$( 'take-file' ).addEventListener( 'change', ( event ) => {

			const file = event.target.files[ 0 ];
			event.target.value = '';
			if ( file ) this.status.task( () => this.importTake( file ) );

		}, { signal } );
		$( 'video-file' ).addEventListener( 'click', ( event ) => {

			// a stereo pair is two videos and a calibration: its own form
			if ( $( 'video-method' ).value !== 'stereo' ) return;
			event.preventDefault();
			this.stereo.open();

		}, { signal } );
		$( 'video-file' ).addEventListener( 'change', ( event ) => {

			const file = event.target.files[ 0 ];
			event.target.value = '';
			if ( file ) this.status.task( () => this.trackVideoFile( file ) );

		}, { signal } );

	}

}

/**
 * A NumPy .npy file (format 1.0) of little-endian float32 values.
 * @param {Float32Array} values
 * @param {number[]} shape
 * @returns {Uint8Array}
 */
function npyBytes( values, shape ) {

	let header = `{'descr': '<f4', 'fortran_order': False, 'shape': (${ shape.join( ', ' ) }${ shape.length === 1 ? ',' : '' }), }`;
	const unpadded = 10 + header.length + 1;
	header += ' '.repeat( ( 64 - ( unpadded % 64 ) ) % 64 ) + '\n';
	const bytes = new Uint8Array( 10 + header.length + 4 * values.length );
	bytes.set( [ 0x93, 0x4e, 0x55, 0x4d, 0x50, 0x59, 1, 0 ] );
	new DataView( bytes.buffer ).setUint16( 8, header.length, true );
	for ( let i = 0; i < header.length; i ++ ) bytes[ 10 + i ] = header.charCodeAt( i );
	new Float32Array( bytes.buffer, 10 + header.length ).set( values );
	return bytes;

}
