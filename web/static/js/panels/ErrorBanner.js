/**
 * The page's dismissable error banner (#error): what failed, in the server's words when
 * the server refused.
 */
export class ErrorBanner {

	/**
	 * @param {HTMLElement} element - #error, holding #error-text and #error-close.
	 */
	constructor( element ) {

		this.element = element;
		this.text = element.querySelector( '#error-text' );
		this._onClose = () => this.clear();
		element.querySelector( '#error-close' ).addEventListener( 'click', this._onClose );

	}

	/**
	 * Show an error (replacing the previous one) and log it.
	 * @param {Error|string} error - an ApiError's message carries the server's detail and status.
	 */
	show( error ) {

		const message = typeof error === 'string' ? error : error.message;
		this.text.textContent = message;
		this.element.hidden = false;
		console.warn( 'retarget:', message );

	}

	/** Hide the banner. */
	clear() {

		this.text.textContent = '';
		this.element.hidden = true;

	}

	/** Whether an error is shown. */
	get visible() {

		return ! this.element.hidden;

	}

	/** Stop listening to the close button. */
	dispose() {

		this.element.querySelector( '#error-close' ).removeEventListener( 'click', this._onClose );

	}

}
