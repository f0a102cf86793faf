/**
 * The page's two kinds of interruption: the dismissable error banner (#error) and the
 * confirmation dialog (#confirm), a styled <dialog> instead of window.confirm so it looks
 * like the app and tests can answer it by clicking #confirm-ok / #confirm-cancel.
 */

export class ErrorBanner {

	/**
	 * @param {HTMLElement} element - #error, holding #error-text and #error-close.
	 */
	constructor( element ) {

		this.element = element;
		this.text = element.querySelector( '#error-text' );
		element.querySelector( '#error-close' ).addEventListener( 'click', () => this.clear() );

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

	clear() {

		this.text.textContent = '';
		this.element.hidden = true;

	}

	get visible() {

		return ! this.element.hidden;

	}

}

/**
 * Ask a question in #confirm.
 * @param {string} text
 * @param {{ok?: string, cancel?: string, alt?: string}} [labels] - button labels; `alt`
 *   adds a third choice.
 * @returns {Promise<'ok'|'alt'|'cancel'>}
 */
export function ask( text, { ok = 'OK', cancel = 'Cancel', alt = '' } = {} ) {

	const dialog = document.getElementById( 'confirm' );
	document.getElementById( 'confirm-text' ).textContent = text;
	document.getElementById( 'confirm-ok' ).textContent = ok;
	document.getElementById( 'confirm-cancel' ).textContent = cancel;
	const altButton = document.getElementById( 'confirm-alt' );
	altButton.textContent = alt;
	altButton.hidden = ! alt;
	dialog.returnValue = 'cancel';
	return new Promise( ( resolve ) => {

		dialog.addEventListener( 'close', () => resolve( dialog.returnValue || 'cancel' ), { once: true } );
		dialog.showModal();
		document.getElementById( 'confirm-ok' ).focus();

	} );

}
