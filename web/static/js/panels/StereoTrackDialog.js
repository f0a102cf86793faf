import { api } from '../net/api.js';

/**
 * The stereo colour-marker form (Woodward §5): the two synchronised videos of a face
 * wearing coloured stickers on the dutreve21 points, or stickers of one colour wherever the
 * user put them (unnamed: a take of columns m01..mM in the head frame, from which the
 * Landmarks panel makes a layout that keeps where each sticker sits), and the cameras'
 * calibration, either a .npz (`retarget calibrate`, or the calibration download of an
 * earlier stereo take) or both cameras' videos of a checkerboard with its pattern.
 *
 * The server checks the pair, calibrates when asked and tracks in a job; this form only
 * collects the files, shows the progress and what came out in the Performance panel's
 * status (SourceStatus), and hands the new take to the panel.
 */

const VIDEO_ACCEPT = 'video/*,.mp4,.m4v,.mov,.avi,.mkv,.webm';

const FORM = `<form method="dialog">
	<h3>Track a stereo pair</h3>
	<p class="muted">Two videos filmed at the same time by two cameras side by side, of coloured markers on the dutreve21 points, and the cameras' calibration.</p>
	<div class="row"><label for="stereo-left">Left</label><input id="stereo-left" type="file" accept="${ VIDEO_ACCEPT }"></div>
	<div class="row"><label for="stereo-right">Right</label><input id="stereo-right" type="file" accept="${ VIDEO_ACCEPT }"></div>
	<fieldset>
		<legend>Markers</legend>
		<div>
			<label class="toggle"><input type="radio" name="stereo-markers" value="layout" checked> dutreve21's coloured markers</label>
			<label class="toggle"><input type="radio" name="stereo-markers" value="stickers"> stickers of one colour</label>
		</div>
		<div data-markers="stickers" hidden>
			<p class="muted">Every sticker of the colour in view becomes a point, m01, m02, … The head anchors (3 or more stickers that move only with the head: temples, forehead, nose bridge) are chosen as the most rigid unless you name them.</p>
			<div class="row"><label for="stereo-color">Colour</label><input id="stereo-color" type="text" value="blue" maxlength="40" title="a name (blue, green, cyan, magenta, yellow), B,G,R picked from the video, or hsv:H,S,V"></div>
			<div class="row"><label for="stereo-anchors">Anchors</label><input id="stereo-anchors" type="text" placeholder="m01,m03,m04 (empty: the most rigid)" maxlength="400"></div>
		</div>
	</fieldset>
	<fieldset>
		<legend>Calibration</legend>
		<div>
			<label class="toggle"><input type="radio" name="stereo-calibration" value="file" checked> calibration file (.npz)</label>
			<label class="toggle"><input type="radio" name="stereo-calibration" value="board"> checkerboard videos</label>
		</div>
		<div class="row" data-calibration="file"><label for="stereo-calibration">File</label><input id="stereo-calibration" type="file" accept=".npz"></div>
		<div data-calibration="board" hidden>
			<div class="row"><label for="stereo-board-left">Left</label><input id="stereo-board-left" type="file" accept="${ VIDEO_ACCEPT }"></div>
			<div class="row"><label for="stereo-board-right">Right</label><input id="stereo-board-right" type="file" accept="${ VIDEO_ACCEPT }"></div>
			<div class="row">
				<label for="stereo-cols" title="Inner corners per row and per column">Corners</label>
				<input id="stereo-cols" type="number" min="2" max="64" step="1" value="9" aria-label="Inner corners per row">
				×
				<input id="stereo-rows" type="number" min="2" max="64" step="1" value="6" aria-label="Inner corners per column">
			</div>
			<div class="row"><label for="stereo-square">Square</label><input id="stereo-square" type="number" min="0.1" step="0.1" value="25"> mm</div>
		</div>
	</fieldset>
	<div id="stereo-note" class="note warn"></div>
	<menu>
		<button id="stereo-cancel" value="cancel">Cancel</button>
		<button id="stereo-track" type="button" class="primary">Track</button>
	</menu>
</form>`;

export class StereoTrackDialog {

	/**
	 * @param {object} options
	 * @param {() => string} options.projectId - the project the take goes to
	 * @param {import('./SourceStatus.js').SourceStatus} options.status - the panel's note and
	 *   bar; the upload and tracking run as its task (controls wait, a failure is shown)
	 * @param {(takeId: string) => Promise<void>} options.onTracked - select the new take
	 * @param {(takeId: string) => Promise<void>} options.onStickers - then, for a take of
	 *   unnamed stickers, show its markers for a layout of them
	 */
	constructor( { projectId, status, onTracked, onStickers } ) {

		this.projectId = projectId;
		this.status = status;
		this.onTracked = onTracked;
		this.onStickers = onStickers;
		this.dialog = document.createElement( 'dialog' );
		this.dialog.id = 'stereo-dialog';
		this.dialog.innerHTML = FORM;
		document.body.append( this.dialog );
		for ( const radio of this.dialog.querySelectorAll( 'input[name=stereo-calibration]' ) ) {

			radio.addEventListener( 'change', () => this._showCalibration() );

		}

		for ( const radio of this.dialog.querySelectorAll( 'input[name=stereo-markers]' ) ) {

			radio.addEventListener( 'change', () => this._showMarkers() );

		}

		this._input( 'stereo-track' ).addEventListener( 'click', () => this._submit() );

	}

	/** Show the form (the files chosen last time stay, for a retry). */
	open() {

		this._input( 'stereo-note' ).textContent = '';
		this.dialog.showModal();

	}

	/** Remove the form from the page. */
	dispose() {

		this.dialog.remove();

	}

	/**
	 * The request's files and fields from the form, or a sentence saying what is missing.
	 * @returns {{left: File, fields: object}|string}
	 */
	request() {

		const file = ( id ) => this._input( id ).files[ 0 ];
		const left = file( 'stereo-left' ), right = file( 'stereo-right' );
		if ( ! left || ! right ) return `Choose the ${ left ? 'right' : 'left' } camera's video.`;
		// the server checks the colour and anchors, and says what is wrong with them
		const markers = this._markersKind() === 'layout' ? {} : { layout: '*', color: this._input( 'stereo-color' ).value.trim() || 'blue',
			...( this._input( 'stereo-anchors' ).value.trim() ? { anchors: this._input( 'stereo-anchors' ).value.trim() } : {} ) };
		if ( this._calibrationKind() === 'file' ) {

			const calibration = file( 'stereo-calibration' );
			if ( ! calibration ) return 'Choose the calibration file (.npz), or calibrate from checkerboard videos.';
			return { left, fields: { right, calibration, ...markers } };

		}

		const boardLeft = file( 'stereo-board-left' ), boardRight = file( 'stereo-board-right' );
		if ( ! boardLeft || ! boardRight ) return `Choose the ${ boardLeft ? 'right' : 'left' } camera's checkerboard video.`;
		const [ cols, rows, square ] = [ 'stereo-cols', 'stereo-rows', 'stereo-square' ].map( ( id ) => this._input( id ).value );
		return { left, fields: { right, calibration_left: boardLeft, calibration_right: boardRight, cols, rows, square, ...markers } };

	}

	_input( id ) {

		return this.dialog.querySelector( '#' + id );

	}

	_calibrationKind() {

		return this.dialog.querySelector( 'input[name=stereo-calibration]:checked' ).value;

	}

	_markersKind() {

		return this.dialog.querySelector( 'input[name=stereo-markers]:checked' ).value;

	}

	_showMarkers() {

		const kind = this._markersKind();
		for ( const block of this.dialog.querySelectorAll( '[data-markers]' ) ) block.hidden = block.dataset.markers !== kind;

	}

	_showCalibration() {

		const kind = this._calibrationKind();
		for ( const block of this.dialog.querySelectorAll( '[data-calibration]' ) ) block.hidden = block.dataset.calibration !== kind;

	}

	_submit() {

		const request = this.request();
		if ( typeof request === 'string' ) {

			this._input( 'stereo-note' ).textContent = request;
			return;

		}

		this.dialog.close();
		this.status.task( () => this._track( request ) );

	}

	async _track( { left, fields } ) {

		const id = this.projectId(), bar = this.status.bar;
		const note = ( text ) => this.status.note( text );

		bar.hidden = false;
		bar.value = 0;
		note( `Uploading ${ left.name } and ${ fields.right.name }…` );
		const job = await api.trackStereo( id, left, fields, ( fraction ) => {

			bar.value = fraction;
			if ( fraction < 1 ) return;
			// the server now checks the pair (and calibrates): no fraction to show
			bar.removeAttribute( 'value' );
			note( fields.calibration ? 'Checking the pair on the server…' : 'Calibrating from the checkerboard videos and checking the pair on the server…' );

		} );
		const cal = job.calibration;
		const calibrated = `calibration ${ cal.source === 'file' ? 'file' : `from ${ cal.views } checkerboard views` }: RMS ${ cal.rms.toFixed( 3 ) } px, baseline ${ cal.baseline.toFixed( 1 ) } mm`;
		bar.value = 0;
		const { result: detail } = await api.waitJob( job.id, ( state ) => {

			bar.value = state.progress;
			note( `Tracking the stereo pair on the server: ${ ( 100 * state.progress ).toFixed( 0 ) } % (${ calibrated }).` );

		}, { what: 'Stereo tracking' } );
		if ( id !== this.projectId() ) return;
		await this.onTracked( detail.take );
		const stickers = fields.layout === '*';
		const made = stickers ? ` Each sticker is a point m01, m02, …: make your layout of them under Landmarks › Custom layout (it keeps where each sticker sits, so live sessions of the same stickers are named by it).` : '';
		note( `Tracked ${ detail.frames } stereo frames of ${ left.name } and ${ fields.right.name } (${ calibrated }).${ made } ` );
		if ( cal.source !== 'file' ) {

			// calibrate once: the next pairs from these cameras can reuse the file
			const link = document.createElement( 'a' );
			link.href = api.takeCalibrationUrl( id, detail.take );
			link.download = 'stereo-calibration.npz';
			link.textContent = 'Download the calibration';
			this.status.element.append( link );

		}

		if ( stickers ) await this.onStickers( detail.take );

	}

}
