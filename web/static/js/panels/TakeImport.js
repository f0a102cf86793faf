import { api } from '../net/api.js';
import { $, option } from './dom.js';
import { StereoTrackDialog } from './StereoTrackDialog.js';

const TAKE_EXTENSIONS = [ 'csv', 'json', 'npy', 'trc', 'c3d', 'glb', 'gltf', 'zip' ];
const OWN_MARKERS = 'own-markers'; // the Video choice: every ring marker in view, the user's layout

/**
 * New takes for the Performance panel: *Import take…* (a file the server reads) and
 * *Track…* a video on the server, markerless or ring markers (a job, its progress in the
 * bar), or a stereo pair of colour-marker videos (its own form, StereoTrackDialog). Each
 * new take becomes the chosen one. Ring markers may be tracked as a layout's or as every
 * marker in view (m01…): then the Custom layout fold opens on the take's first frame, for
 * the user to make their own layout of them.
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
		this.stereo = new StereoTrackDialog( {
			projectId: () => this.app.projectId,
			status,
			onTracked: onTake,
			// unnamed stickers: their layout is made from the take, as for ring markers
			onStickers: ( takeId ) => this.app.customLayout.showTake( takeId ),
		} );
		this._events = new AbortController();
		// after "ring markers" (the page's markup lists the layouts' trackers); once per page
		const methods = $( 'video-method' );
		if ( ! methods.querySelector( `option[value="${ OWN_MARKERS }"]` ) ) {

			methods.querySelector( 'option[value="markers"]' ).after( option( OWN_MARKERS, 'ring markers, every one in view (your own layout)',
				'Every ring marker in view, named m01…: click each on the first frame, then its point on the mesh' ) );

		}

		this._bind();

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
	 * Track a video into a take on the server, by the method chosen: markerless (the face
	 * mesh, into the project's layout), ring markers (dutreve21) or every ring marker in
	 * view (layout *, shown in the Custom layout fold). The bar shows the upload, then the
	 * server's job.
	 * @param {File} file
	 */
	async trackVideoFile( file ) {

		const choice = $( 'video-method' ).value, own = choice === OWN_MARKERS;
		const method = own ? 'markers' : choice;
		const markers = method === 'markers';
		const id = this.app.projectId, status = this.status;
		const fields = { method, layout: own ? '*' : markers ? 'dutreve21' : this.app.sources.layout().name };
		const job = await status.withProgress( `Uploading ${ file.name }…`, ( progress ) => api.trackVideo( id, file, fields, progress ) );
		status.bar.value = 0; // the job's share done, no longer the upload's
		status.bar.hidden = false;
		const what = markers ? `the markers of ${ file.name }` : `the face in ${ file.name }`;
		let result; // {take, frames, truncated?, frames_claimed?, frames_with_face?}
		try {

			( { result } = await api.waitJob( job.id, ( state ) => {

				status.bar.value = state.progress;
				status.note( `Tracking ${ what } on the server: ${ ( 100 * state.progress ).toFixed( 0 ) } %` );

			}, { what: markers ? 'Marker tracking' : 'Face tracking' } ) );

		} finally {

			status.bar.hidden = true;

		}

		if ( id !== this.app.projectId ) return; // kept in its project; this one lists its own takes
		await this.onTake( result.take );
		const info = this.list.takes.find( ( t ) => t.id === result.take );
		const name = info?.name ?? file.name;
		let text, warn = Boolean( result.truncated );
		if ( markers ) {

			text = `Tracked "${ name }": ${ info?.n_points ?? '' } markers in ${ result.frames } frames of ${ file.name }.`;

		} else {

			const share = result.frames_with_face / result.frames;
			text = `Tracked "${ name }": ${ result.frames } frames${ info ? ` at ${ +info.fps.toFixed( 3 ) } fps` : '' }, a face in ${ ( 100 * share ).toFixed( 0 ) } % of them.`;
			warn ||= share < 0.9; // frames without a face hold the take still

		}

		// a cut-off file still gives its frames up to the cut: say so, or the take looks whole
		if ( result.truncated ) text += ` The file is cut off: only ${ result.frames } of the ${ result.frames_claimed } frames it announces could be read.`;
		if ( own ) text += ' Make your layout of them under Landmarks › Custom layout.';
		status.note( text, warn );
		if ( own ) await this.app.customLayout.showTake( result.take );

	}

	/** Stop listening; remove the stereo form. */
	dispose() {

		this._events.abort();
		this.stereo.dispose();

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
