/**
 * The few DOM helpers every panel uses.
 */

/**
 * @param {string} id
 * @returns {HTMLElement} the page's element with that id.
 */
export const $ = ( id ) => document.getElementById( id );

/**
 * An <option>.
 * @param {string} value
 * @param {string} text
 * @param {string} [title]
 * @returns {HTMLOptionElement}
 */
export function option( value, text, title = '' ) {

	const element = document.createElement( 'option' );
	element.value = value;
	element.textContent = text;
	if ( title ) element.title = title;
	return element;

}

/**
 * An event handler that shows what `fn` throws (or rejects with) in the error banner
 * instead of leaving it uncaught.
 * @param {{show: (error: Error|string) => void}} errors - the page's ErrorBanner.
 * @param {(...args: *[]) => *} fn
 * @returns {(...args: *[]) => Promise<void>}
 */
export function guarded( errors, fn ) {

	return async ( ...args ) => {

		try {

			await fn( ...args );

		} catch ( error ) {

			errors.show( error );

		}

	};

}

/**
 * "12.3 MiB".
 * @param {number} bytes
 * @returns {string}
 */
export function mebibytes( bytes ) {

	return `${ Number( ( bytes / 2 ** 20 ).toPrecision( 3 ) ) } MiB`;

}
