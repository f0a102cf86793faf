import { $ } from './dom.js';

/**
 * The Performance panel's status: the note under the take tools (#source-note), the
 * progress bar (#source-progress), and the file controls, which wait while an import or a
 * tracking runs. Shared by the panel, its take import, the stereo form and the recorder.
 */
export class SourceStatus {

	/**
	 * @param {{show: (error: Error|string) => void}} errors - the page's ErrorBanner.
	 */
	constructor( errors ) {

		this.errors = errors;
		this.bar = $( 'source-progress' );
		this.element = $( 'source-note' );

	}

	/** The note's text. */
	get text() {

		return this.element.textContent;

	}

	/**
	 * Say `text` under the take tools.
	 * @param {string} text
	 * @param {boolean} [warn] - show it as a warning.
	 */
	note( text, warn = false ) {

		this.element.textContent = text;
		this.element.classList.toggle( 'warn', Boolean( warn ) );

	}

	/**
	 * Run `work` with the bar shown from 0 and `text` in the note; the bar hides after.
	 * @template T
	 * @param {string} text
	 * @param {(progress: (fraction: number) => void) => Promise<T>} work
	 * @returns {Promise<T>}
	 */
	async withProgress( text, work ) {

		const bar = this.bar;
		bar.hidden = false;
		bar.value = 0;
		this.note( text );
		try {

			return await work( ( fraction ) => {

				bar.value = fraction;

			} );

		} finally {

			bar.hidden = true;

		}

	}

	/**
	 * Run an import or a tracking: the file controls wait until it ends, and a failure
	 * leaves no stale progress behind (bar hidden, note cleared) and shows why.
	 * @param {() => Promise<void>} work
	 */
	async task( work ) {

		const controls = [ 'take-file', 'video-file', 'video-method' ].map( $ );
		for ( const control of controls ) control.disabled = true;
		$( 'source-panel' ).classList.add( 'busy' );
		try {

			await work();

		} catch ( error ) {

			this.note( '' );
			this.errors.show( error );

		} finally {

			this.bar.hidden = true;
			for ( const control of controls ) control.disabled = false;
			$( 'source-panel' ).classList.remove( 'busy' );

		}

	}

}
