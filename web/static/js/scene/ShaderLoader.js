/**
 * Loads GLSL files and resolves our own includes: a line `#include "name.glsl"` is
 * replaced by that file (one of the files loaded together); three.js's `#include <chunk>`
 * lines are left for three.js. A set of files is fetched once per base URL and shared by
 * every later load; a failed load is forgotten, so a later one retries.
 */
export class ShaderLoader {

	static _cache = new Map(); // base URL + file names -> Promise of { file name: GLSL }

	/**
	 * @param {string} baseURL - where the files are served, e.g. '/shaders/'.
	 * @param {string[]} files - file names under it.
	 * @returns {Promise<Object<string, string>>} GLSL by file name, includes resolved.
	 */
	load( baseURL, files ) {

		const key = `${ baseURL }\n${ files.join( '\n' ) }`;
		let loading = ShaderLoader._cache.get( key );
		if ( ! loading ) {

			loading = loadShaders( baseURL, files );
			ShaderLoader._cache.set( key, loading );
			loading.catch( () => ShaderLoader._cache.delete( key ) );

		}

		return loading;

	}

}

async function loadShaders( baseURL, names ) {

	const texts = await Promise.all( names.map( async ( name ) => {

		const response = await fetch( new URL( name, new URL( baseURL, location.href ) ) );
		if ( ! response.ok ) throw new Error( `ShaderLoader: could not load shader ${ baseURL }${ name }: HTTP ${ response.status }.` );
		return [ name, await response.text() ];

	} ) );
	const files = Object.fromEntries( texts );
	const resolve = ( source ) => source.replace( /^[ \t]*#include "([^"]+)"[ \t]*$/gm, ( line, name ) => {

		if ( ! ( name in files ) ) throw new Error( `ShaderLoader: shader include "${ name }" is not one of ${ names.join( ', ' ) }.` );
		return files[ name ];

	} );
	return Object.fromEntries( texts.map( ( [ name, text ] ) => [ name, resolve( text ) ] ) );

}
