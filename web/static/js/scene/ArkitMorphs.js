import { SKIN_TEXTURE_WIDTH, exactTexture } from './VertexPasses.js';

/**
 * ARKit's 52 blendshapes of a face as the shader plays them (web/shaders/arkit.glsl): the
 * sparse morph targets of GET .../arkit/shapes (server/wire.py's RTAK, `ArkitShapesDecoder`)
 * packed into one RGBA32F texture, vertex-major (a vertex's 52 targets adjacent,
 * web/shaders/morph_targets.glsl), each shape's painted fix (a per-vertex mask in [0, 1],
 * `retarget.arkit.settings`) multiplied in. Painting a fix rewrites only the texels of the
 * vertices it touched and uploads only those.
 */
export class ArkitMorphs {

	/**
	 * @param {{nVertices: number, names: string[], shapes: Array<{vertices: Uint32Array,
	 *   values: Int16Array, scale: number}>}} decoded - ArkitShapesDecoder's result (viewed).
	 * @param {Object<string, {vertices: number[], values: number[]}>} [masks] - painted
	 *   fixes by shape name (the settings' sparse form).
	 */
	constructor( { nVertices, names, shapes }, masks = {} ) {

		/** Vertex count V. */
		this.nVertices = nVertices;
		/** (K) shape names, ARKit's order. */
		this.names = names;
		/** Shape count K (52). */
		this.nTargets = names.length;
		this._shapes = shapes;
		/** @type {Map<number, Float32Array>} shape index -> (V) mask, for painted shapes only. */
		this.masks = new Map();
		for ( const [ name, mask ] of Object.entries( masks ) ) {

			const k = names.indexOf( name );
			if ( k < 0 ) continue;
			const dense = this.mask( k );
			mask.vertices.forEach( ( v, n ) => {

				dense[ v ] = mask.values[ n ];

			} );

		}

		const height = Math.ceil( nVertices * this.nTargets / SKIN_TEXTURE_WIDTH );
		this._texels = new Float32Array( 4 * SKIN_TEXTURE_WIDTH * height );
		shapes.forEach( ( _, k ) => this._write( k ) );
		/** The texture arkit.glsl samples (arkitTargetTexture). */
		this.texture = exactTexture( this._texels, SKIN_TEXTURE_WIDTH, height );

	}

	/**
	 * The (V) mask of shape `k`, made (all 1) on first use; change it, then `update`.
	 * @param {number} k
	 * @returns {Float32Array}
	 */
	mask( k ) {

		if ( ! this.masks.has( k ) ) this.masks.set( k, new Float32Array( this.nVertices ).fill( 1 ) );
		return this.masks.get( k );

	}

	/**
	 * Shape `k`'s mask changed at `vertices`: rewrite and upload their texels.
	 * @param {number} k
	 * @param {ArrayLike<number>} vertices
	 */
	update( k, vertices ) {

		const raw = this._raw( k );
		const mask = this.masks.get( k );
		const t = this.nTargets;
		for ( let n = 0; n < vertices.length; n ++ ) {

			const v = vertices[ n ], at = 4 * ( v * t + k ), scale = mask ? mask[ v ] : 1;
			this._texels[ at ] = raw[ 3 * v ] * scale;
			this._texels[ at + 1 ] = raw[ 3 * v + 1 ] * scale;
			this._texels[ at + 2 ] = raw[ 3 * v + 2 ] * scale;
			this.texture.addUpdateRange( at, 4 ); // one texel never crosses a texture row

		}

		this.texture.needsUpdate = true;

	}

	/**
	 * The painted fixes in the settings' sparse form (vertices below 1, ascending).
	 * @returns {Object<string, {vertices: number[], values: number[]}>}
	 */
	sparseMasks() {

		const out = {};
		for ( const [ k, mask ] of this.masks ) {

			const vertices = [], values = [];
			mask.forEach( ( x, v ) => {

				if ( x < 1 ) {

					vertices.push( v );
					values.push( Math.round( x * 1e5 ) / 1e5 );

				}

			} );
			if ( vertices.length ) out[ this.names[ k ] ] = { vertices, values };

		}

		return out;

	}

	/**
	 * (V*3) displacements of shape `k` at weight 1, mask applied (the CPU twin of what the
	 * shader adds; tests compare the two).
	 * @param {number} k
	 * @returns {Float32Array}
	 */
	target( k ) {

		const raw = this._raw( k ), mask = this.masks.get( k );
		if ( mask ) for ( let v = 0; v < this.nVertices; v ++ ) for ( let c = 0; c < 3; c ++ ) raw[ 3 * v + c ] *= mask[ v ];
		return raw;

	}

	/** Free the texture. */
	dispose() {

		this.texture.dispose();

	}

	/** (V*3) shape `k` as sent, dense. */
	_raw( k ) {

		const { vertices, values, scale } = this._shapes[ k ];
		const out = new Float32Array( 3 * this.nVertices );
		for ( let n = 0; n < vertices.length; n ++ ) {

			const v = vertices[ n ];
			out[ 3 * v ] = values[ 3 * n ] * scale;
			out[ 3 * v + 1 ] = values[ 3 * n + 1 ] * scale;
			out[ 3 * v + 2 ] = values[ 3 * n + 2 ] * scale;

		}

		return out;

	}

	/** Write shape `k`'s texels of every vertex it moves (the texture is made after). */
	_write( k ) {

		const { vertices, values, scale } = this._shapes[ k ];
		const mask = this.masks.get( k ), t = this.nTargets;
		for ( let n = 0; n < vertices.length; n ++ ) {

			const v = vertices[ n ], at = 4 * ( v * t + k ), s = scale * ( mask ? mask[ v ] : 1 );
			this._texels[ at ] = values[ 3 * n ] * s;
			this._texels[ at + 1 ] = values[ 3 * n + 1 ] * s;
			this._texels[ at + 2 ] = values[ 3 * n + 2 ] * s;

		}

	}

}
