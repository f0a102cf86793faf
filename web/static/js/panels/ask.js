/**
 * Ask a question in the confirmation dialog (#confirm), a styled <dialog> instead of
 * window.confirm so it looks like the app and tests can answer it by clicking
 * #confirm-ok / #confirm-cancel.
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
