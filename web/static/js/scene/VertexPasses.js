import {
	BufferAttribute,
	BufferGeometry,
	Camera,
	Color,
	DataTexture,
	FloatType,
	GLSL3,
	NearestFilter,
	NoBlending,
	Points,
	RGBAFormat,
	RGFormat,
	Scene,
	ShaderMaterial,
	WebGLRenderTarget,
	WebGLRenderer,
} from 'three';

/** Texels per row of every per-vertex texture; web/shaders/skinning.glsl's SKIN_TEXTURE_WIDTH. */
export const SKIN_TEXTURE_WIDTH = 4096;

/**
 * The two GPU passes of a SkinnedFace that write one RGBA32F texel per vertex: the
 * skinning pass (web/shaders/skin_pass.vert, running skinning.glsl) the skinned positions,
 * then the normal pass (normal_pass.vert) the normals of the deformed surface. Each draws
 * every vertex as a point (unindexed, so gl_VertexID is the vertex index) into its texel
 * of a float target; the face's display pass samples `positionTarget` and `normalTarget`,
 * and `read` brings them back to the CPU, so tests compare the very values that are drawn.
 *
 * The passes run on a renderer only when the pose changed since they last ran there.
 */
export class VertexPasses {

	/**
	 * @param {BufferGeometry} geometry - the face's rest pose: position and normal attributes
	 *   (shared, not copied).
	 * @param {Uint32Array} faces - (F*3) vertex indices.
	 * @param {Object<string, string>} shaders - GLSL by file name, includes resolved.
	 * @param {Object<string, {value: *}>} skinUniforms - skinning.glsl's uniforms, shared
	 *   with the display material.
	 */
	constructor( geometry, faces, shaders, skinUniforms ) {

		const nVertices = geometry.getAttribute( 'position' ).count;
		this.nVertices = nVertices;
		const size = { value: [ SKIN_TEXTURE_WIDTH, Math.ceil( nVertices / SKIN_TEXTURE_WIDTH ) ] };
		/** Skinned positions, one texel per vertex (xyz, w = 1 once written). */
		this.positionTarget = vertexTarget( size.value );
		/** Deformed unit normals, one texel per vertex. */
		this.normalTarget = vertexTarget( size.value );
		const { ranges, texture } = incidences( faces, geometry.getAttribute( 'position' ).array );
		this._incidenceTexture = texture;
		this._skin = pointsPass( shaders[ 'skin_pass.vert' ], shaders[ 'texel_pass.frag' ],
			Object.assign( { passSize: size }, skinUniforms ), { position: geometry.getAttribute( 'position' ) } );
		this._normal = pointsPass( shaders[ 'normal_pass.vert' ], shaders[ 'texel_pass.frag' ], {
			passSize: size,
			skinnedPositions: { value: this.positionTarget.texture },
			incidenceTexture: { value: texture },
		}, {
			position: geometry.getAttribute( 'position' ), // its count is the number of points
			normal: geometry.getAttribute( 'normal' ),
			incidence: new BufferAttribute( ranges, 2 ),
		} );
		this._camera = new Camera(); // unused by the shaders; three.js needs one
		this._done = new WeakMap(); // renderer -> the version of the pose its targets hold
		this._renderer = null; // a private one, only if a readback comes before any drawing

	}

	/** The skinning pass's material (its defines follow the rig's kind). */
	get skinMaterial() {

		return this._skin.material;

	}

	/**
	 * Share a vertex attribute of the face with the skinning pass (the rig's skinIndex,
	 * skinWeight, ...).
	 * @param {string} name
	 * @param {BufferAttribute} attribute
	 */
	setSkinAttribute( name, attribute ) {

		this._skin.geometry.setAttribute( name, attribute );

	}

	/**
	 * Run both passes on `renderer` unless its targets already hold pose `version`.
	 * @param {WebGLRenderer} renderer
	 * @param {number} version - bumped by the face on every change of pose or rig.
	 * @returns {boolean} whether the passes ran.
	 */
	run( renderer, version ) {

		if ( this._done.get( renderer ) === version ) return false;
		const previousTarget = renderer.getRenderTarget();
		const previousClearColor = renderer.getClearColor( new Color() );
		const previousClearAlpha = renderer.getClearAlpha();
		try {

			renderer.setClearColor( 0x000000, 0 );
			for ( const [ { scene }, target ] of [ [ this._skin, this.positionTarget ], [ this._normal, this.normalTarget ] ] ) {

				renderer.setRenderTarget( target );
				renderer.clear();
				renderer.render( scene, this._camera );

			}

			this._done.set( renderer, version );
			return true;

		} finally {

			renderer.setRenderTarget( previousTarget );
			renderer.setClearColor( previousClearColor, previousClearAlpha );

		}

	}

	/**
	 * (V*3) floats of a per-vertex target as `renderer` last wrote it.
	 * @param {WebGLRenderer} renderer
	 * @param {WebGLRenderTarget} target - `positionTarget` or `normalTarget`.
	 * @returns {Float32Array}
	 */
	read( renderer, target ) {

		const v = this.nVertices;
		const texels = new Float32Array( 4 * target.width * target.height );
		renderer.readRenderTargetPixels( target, 0, 0, target.width, target.height, texels );
		const values = new Float32Array( 3 * v );
		for ( let i = 0; i < v; i ++ ) {

			if ( texels[ 4 * i + 3 ] !== 1 ) throw new Error( `VertexPasses: vertex ${ i } was not written by its pass.` );
			values[ 3 * i ] = texels[ 4 * i ];
			values[ 3 * i + 1 ] = texels[ 4 * i + 1 ];
			values[ 3 * i + 2 ] = texels[ 4 * i + 2 ];

		}

		return values;

	}

	/**
	 * A renderer of the passes' own, for a readback before anything drew the face (made
	 * on first use, freed by `dispose`).
	 * @returns {WebGLRenderer}
	 */
	get privateRenderer() {

		return ( this._renderer ??= new WebGLRenderer() );

	}

	/** Free the passes' geometries, materials, textures and targets. */
	dispose() {

		for ( const pass of [ this._skin, this._normal ] ) {

			pass.geometry.dispose();
			pass.material.dispose();

		}

		this._incidenceTexture.dispose();
		this.positionTarget.dispose();
		this.normalTarget.dispose();
		this._renderer?.dispose();

	}

}

/**
 * A data texture read with texelFetch: nearest, unfiltered, no mipmaps.
 * @param {Float32Array} data
 * @param {number} width - texels.
 * @param {number} height - texels.
 * @param {number} [format] - RGBAFormat or RGFormat.
 * @returns {DataTexture}
 */
export function exactTexture( data, width, height, format = RGBAFormat ) {

	const texture = new DataTexture( data, width, height, format, FloatType );
	texture.minFilter = texture.magFilter = NearestFilter;
	texture.generateMipmaps = false;
	texture.needsUpdate = true;
	return texture;

}

/**
 * A float target with one texel per vertex (web/shaders/vertex_texels.glsl).
 * @param {number[]} size - [width, height] texels.
 */
function vertexTarget( [ width, height ] ) {

	return new WebGLRenderTarget( width, height, {
		type: FloatType, format: RGBAFormat, minFilter: NearestFilter, magFilter: NearestFilter,
		depthBuffer: false, generateMipmaps: false,
	} );

}

/**
 * A pass that draws one point per vertex with `vertexShader`; render its scene into a
 * vertexTarget.
 * @param {Object<string, BufferAttribute>} attributes - shared with the face's geometry.
 * @returns {{scene: Scene, geometry: BufferGeometry, material: ShaderMaterial}}
 */
function pointsPass( vertexShader, fragmentShader, uniforms, attributes ) {

	const geometry = new BufferGeometry();
	for ( const [ name, attribute ] of Object.entries( attributes ) ) geometry.setAttribute( name, attribute );
	const material = new ShaderMaterial( {
		glslVersion: GLSL3, uniforms, vertexShader, fragmentShader,
		blending: NoBlending, // float targets cannot blend without EXT_float_blend
		depthTest: false,
		depthWrite: false,
	} );
	const points = new Points( geometry, material );
	points.frustumCulled = false;
	const scene = new Scene();
	scene.add( points );
	return { scene, geometry, material };

}

/**
 * Each vertex's triangles for the deformed normals (web/shaders/normal_pass.vert): for every
 * corner of every triangle, the other two corners in winding order, grouped by position:
 * the copies of a vertex at one place (a UV seam, which glTF splits; an STL's corners)
 * share all their triangles, so the surface is shaded smooth across them, as the rig
 * moves them as one (retarget/welding.py).
 * @param {Uint32Array} faces - (F*3) vertex indices.
 * @param {Float32Array} positions - (V*3) rest positions.
 * @returns {{ranges: Uint32Array, texture: DataTexture}} ranges: (V*2) first texel and
 *   count per vertex (its position's); texture: RG32F, SKIN_TEXTURE_WIDTH wide, one corner
 *   pair a texel.
 */
function incidences( faces, positions ) {

	const nVertices = positions.length / 3;
	const place = new Uint32Array( nVertices );
	const places = new Map();
	for ( let v = 0; v < nVertices; v ++ ) {

		const key = `${ positions[ 3 * v ] },${ positions[ 3 * v + 1 ] },${ positions[ 3 * v + 2 ] }`;
		let p = places.get( key );
		if ( p === undefined ) places.set( key, p = places.size );
		place[ v ] = p;

	}

	const spans = new Uint32Array( 2 * places.size );
	for ( let i = 0; i < faces.length; i ++ ) spans[ 2 * place[ faces[ i ] ] + 1 ] ++;
	for ( let p = 1; p < places.size; p ++ ) spans[ 2 * p ] = spans[ 2 * p - 2 ] + spans[ 2 * p - 1 ];

	const height = Math.max( 1, Math.ceil( faces.length / SKIN_TEXTURE_WIDTH ) );
	const corners = new Float32Array( 2 * SKIN_TEXTURE_WIDTH * height );
	const filled = new Uint32Array( places.size );
	for ( let f = 0; f < faces.length; f += 3 ) {

		for ( let c = 0; c < 3; c ++ ) {

			const p = place[ faces[ f + c ] ];
			const texel = spans[ 2 * p ] + filled[ p ] ++;
			corners[ 2 * texel ] = faces[ f + ( c + 1 ) % 3 ];
			corners[ 2 * texel + 1 ] = faces[ f + ( c + 2 ) % 3 ];

		}

	}

	const ranges = new Uint32Array( 2 * nVertices );
	for ( let v = 0; v < nVertices; v ++ ) {

		ranges[ 2 * v ] = spans[ 2 * place[ v ] ];
		ranges[ 2 * v + 1 ] = spans[ 2 * place[ v ] + 1 ];

	}

	return { ranges, texture: exactTexture( corners, SKIN_TEXTURE_WIDTH, height, RGFormat ) };

}
