/**
 * JPEG encoding of camera frames off the page's main thread (a module worker of
 * StereoCapture.js), where the encoder would wait for the page's rendering (in Chromium a
 * canvas's toBlob encodes in the main thread's idle time, of which a page that draws
 * every frame leaves little).
 *
 * Message in: {id, quality, width, height, views: [{bitmap, x, y}, ...]}: each view is the
 * width x height rectangle at (x, y) of an ImageBitmap (transferred; one bitmap may serve
 * two views: a camera holding both). Message out: {id, jpegs: [ArrayBuffer, ...]} in the
 * views' order (transferred), or {id, error}. The bitmaps are closed once drawn.
 */

const canvases = [];

function canvas( i, width, height ) {

	if ( ! canvases[ i ] ) {

		const c = new OffscreenCanvas( width, height );
		// in memory, as the encoder reads it (on SwiftShader no faster than a GPU canvas: the
		// time goes to reading the video frame back, about 80 ms a pair under load)
		canvases[ i ] = { canvas: c, context: c.getContext( '2d', { alpha: false, willReadFrequently: true } ) };

	}

	const entry = canvases[ i ];
	if ( entry.canvas.width !== width || entry.canvas.height !== height ) {

		entry.canvas.width = width;
		entry.canvas.height = height;

	}

	return entry;

}

async function encode( { quality, width, height, views } ) {

	try {

		// one canvas per view, encoded at once: the browser may use a thread for each
		const blobs = views.map( ( { bitmap, x, y }, i ) => {

			const { canvas: c, context } = canvas( i, width, height );
			context.drawImage( bitmap, x, y, width, height, 0, 0, width, height );
			return c.convertToBlob( { type: 'image/jpeg', quality } );

		} );
		return await Promise.all( ( await Promise.all( blobs ) ).map( ( blob ) => blob.arrayBuffer() ) );

	} finally {

		for ( const { bitmap } of views ) bitmap.close();

	}

}

self.addEventListener( 'message', async ( { data } ) => {

	try {

		const jpegs = await encode( data );
		self.postMessage( { id: data.id, jpegs }, jpegs );

	} catch ( error ) {

		self.postMessage( { id: data.id, error: String( error?.message ?? error ) } );

	}

} );
