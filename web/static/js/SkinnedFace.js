import {
	BufferAttribute,
	BufferGeometry,
	Camera,
	Color,
	DataTexture,
	DoubleSide,
	FloatType,
	GLSL3,
	IntType,
	Mesh,
	NearestFilter,
	NoBlending,
	Points,
	RGBAFormat,
	RGFormat,
	Scene,
	ShaderMaterial,
	UniformsLib,
	UniformsUtils,
	WebGLRenderTarget,
	WebGLRenderer,
} from 'three';

const SKIN_TEXTURE_WIDTH = 4096; // texels; web/shaders/skinning.glsl's SKIN_TEXTURE_WIDTH
const MAX_SPARSE_INFLUENCES = 8;
const MAX_JOINTS = 4096; // the displacement texture is one row
const MAX_VERTICES = 2 ** 24; // vertex indices are stored in float32 textures, exact up to 2^24
const SHADER_FILES = [ 'skinning.glsl', 'skin_pass.vert', 'skin_pass.frag', 'face.vert', 'face.frag' ];

const shaderSources = new Map(); // base URL -> Promise of { file name: GLSL with includes resolved }

/**
 * A face mesh skinned on the GPU by its feature points (Dutreve et al. 2008, §3.1: feature
 * points are translation-only joints), `v = v0 + sum_k w[v,k] d[j[v,k]]`.
 *
 * The geometry holds the rest pose (raycasting and picking work on it). Drawing takes two
 * passes: a skinning pass (web/shaders/skin_pass.vert, running web/shaders/skinning.glsl)
 * writes every vertex's skinned position to an RGBA32F texture whenever the pose or rig
 * changed, and the display pass (face.vert) draws from that texture, with normals of the
 * deformed surface. `deformedPositions()` reads that very texture back, so tests compare
 * what is drawn with the CPU twin (retarget/skin.py).
 *
 * Rigs with at most 8 influences per vertex go in vertex attributes; denser ones (the
 * default biharmonic rig weights every vertex by every joint) in an RGBA32F texture. Both
 * upload once per rig; a pose updates only the N-texel displacement texture.
 */
export class SkinnedFace {

	/**
	 * @param {{positions: Float32Array, faces: Uint32Array}} arrays - rest positions (V*3,
	 *   mesh units, vertex-major) and triangles (F*3 vertex indices); used in place, not copied.
	 * @param {{shaderURL?: string}} [options] - where the GLSL files are served.
	 * @returns {Promise<SkinnedFace>}
	 */
	static async create( { positions, faces }, { shaderURL = '/shaders/' } = {} ) {

		if ( ! shaderSources.has( shaderURL ) ) {

			const loading = loadShaders( shaderURL );
			shaderSources.set( shaderURL, loading );
			loading.catch( () => shaderSources.delete( shaderURL ) ); // let a later call retry

		}

		return new SkinnedFace( positions, faces, await shaderSources.get( shaderURL ) );

	}

	/**
	 * Use `SkinnedFace.create`, which fetches the shaders.
	 * @param {Float32Array} positions - (V*3) rest positions.
	 * @param {Uint32Array} faces - (F*3) vertex indices.
	 * @param {Object<string, string>} shaders - GLSL by file name, includes resolved.
	 */
	constructor( positions, faces, shaders ) {

		if ( ! ( positions instanceof Float32Array ) || positions.length === 0 || positions.length % 3 !== 0 ) {

			throw new TypeError( `SkinnedFace: positions must be a non-empty Float32Array of V*3 coordinates; got ${ describe( positions ) }.` );

		}

		if ( ! ( faces instanceof Uint32Array ) || faces.length % 3 !== 0 ) {

			throw new TypeError( `SkinnedFace: faces must be a Uint32Array of F*3 vertex indices; got ${ describe( faces ) }.` );

		}

		const nVertices = positions.length / 3;
		if ( nVertices > MAX_VERTICES ) throw new RangeError( `SkinnedFace: ${ nVertices } vertices; at most ${ MAX_VERTICES } are supported.` );
		let maxIndex = 0;
		for ( let i = 0; i < faces.length; i ++ ) if ( faces[ i ] > maxIndex ) maxIndex = faces[ i ];
		if ( faces.length > 0 && maxIndex >= nVertices ) {

			throw new RangeError( `SkinnedFace: faces refer to vertex ${ maxIndex }, but there are only ${ nVertices } vertices.` );

		}

		/** Vertex count V. */
		this.nVertices = nVertices;
		/** Joint (feature point) count N of the current rig; 0 without a rig. */
		this.nJoints = 0;
		/** Influences per vertex k of the current rig; 0 without a rig. */
		this.nInfluences = 0;

		const geometry = new BufferGeometry();
		geometry.setAttribute( 'position', new BufferAttribute( positions, 3 ) );
		geometry.setIndex( new BufferAttribute( faces, 1 ) );
		geometry.computeVertexNormals(); // the rest normals, for picking tools and degenerate triangles
		geometry.computeBoundingBox();
		geometry.computeBoundingSphere();
		const { ranges, texture: incidenceTexture } = incidences( faces, nVertices );
		geometry.setAttribute( 'incidence', new BufferAttribute( ranges, 2 ) );

		// shared by the skinning pass and the display (heat map) materials
		this._skinUniforms = {
			displacementTexture: { value: null },
			skinWeightTexture: { value: null },
			skinQuads: { value: 0 },
		};

		// the skinning pass draws the same vertices, unindexed, as points into a float target
		const width = SKIN_TEXTURE_WIDTH;
		const height = Math.ceil( nVertices / width );
		const passGeometry = new BufferGeometry();
		passGeometry.setAttribute( 'position', geometry.getAttribute( 'position' ) );
		this._pass = {
			geometry: passGeometry,
			material: new ShaderMaterial( {
				name: 'SkinnedFace.skinPass',
				glslVersion: GLSL3,
				uniforms: Object.assign( { skinPassSize: { value: [ width, height ] } }, this._skinUniforms ),
				vertexShader: shaders[ 'skin_pass.vert' ],
				fragmentShader: shaders[ 'skin_pass.frag' ],
				blending: NoBlending, // float targets cannot blend without EXT_float_blend
				depthTest: false,
				depthWrite: false,
			} ),
			target: new WebGLRenderTarget( width, height, {
				type: FloatType, format: RGBAFormat, minFilter: NearestFilter, magFilter: NearestFilter,
				depthBuffer: false, generateMipmaps: false,
			} ),
			scene: new Scene(),
			camera: new Camera(), // unused by the shader; three.js needs one
			done: new WeakMap(), // renderer -> the pose version its target holds
			renderer: null, // a private one, only if deformedPositions() comes before any drawing
		};

		const points = new Points( passGeometry, this._pass.material );
		points.frustumCulled = false;
		this._pass.scene.add( points );
		this._version = 0; // bumped by every change of pose or rig

		const uniforms = UniformsUtils.merge( [ UniformsLib.lights ] );
		Object.assign( uniforms, this._skinUniforms, {
			skinnedPositions: { value: this._pass.target.texture },
			incidenceTexture: { value: incidenceTexture },
			diffuse: { value: new Color( 0xd9b8a6 ) },
			specular: { value: 0.03 },
			shininess: { value: 24 },
			heatJoint: { value: - 1 },
		} );

		const material = new ShaderMaterial( {
			name: 'SkinnedFace',
			glslVersion: GLSL3,
			uniforms,
			vertexShader: shaders[ 'face.vert' ],
			fragmentShader: shaders[ 'face.frag' ],
			lights: true,
			side: DoubleSide, // scanned faces are open: the inside of the mouth and eyes shows
		} );

		/** The face as drawn: add it to a scene. Its geometry is the rest pose. */
		this.mesh = new Mesh( geometry, material );
		this.mesh.name = 'SkinnedFace';
		// the skinned surface leaves the rest pose's bounding sphere, and one object gains nothing from culling
		this.mesh.frustumCulled = false;
		// a nested render, as three.js's Reflector does: the skinning pass runs only when the
		// pose changed since this renderer last ran it
		this.mesh.onBeforeRender = ( renderer ) => {

			this._renderer = renderer;
			this._skin( renderer );

		};

		this._displacements = null; // Float32Array( 4 * skinQuads * 4 ), RGBA texels
		this._setDefine( null );

	}

	/**
	 * Set (or with null, remove) the rig: skin weights from GET /api/projects/{id}/rig/weights.
	 * Uploads the weights once; the face returns to rest until `setDisplacements`, and the
	 * heat map turns off (its joint may not exist in the new rig).
	 * @param {{nJoints: number, nInfluences: number, indices: Uint16Array, weights: Float32Array}|null} rig -
	 *   indices and weights are (V*k) row-major, k = nInfluences; unused slots have weight 0.
	 */
	setRig( rig ) {

		if ( rig === null ) {

			this.mesh.material.uniforms.heatJoint.value = - 1;
			this._disposeRigTextures();
			this.nJoints = this.nInfluences = 0;
			this._setDefine( null );
			this._version ++;
			return;

		}

		const { nJoints, nInfluences: k, indices, weights } = rig;
		const v = this.nVertices;
		if ( ! Number.isInteger( nJoints ) || nJoints < 1 || nJoints > MAX_JOINTS ) {

			throw new RangeError( `SkinnedFace.setRig: nJoints must be an integer in 1..${ MAX_JOINTS }; got ${ nJoints }.` );

		}

		if ( ! Number.isInteger( k ) || k < 1 ) throw new RangeError( `SkinnedFace.setRig: nInfluences must be a positive integer; got ${ k }.` );
		if ( ! ( indices instanceof Uint16Array ) || indices.length !== v * k ) {

			throw new TypeError( `SkinnedFace.setRig: indices must be a Uint16Array of ${ v } x ${ k } = ${ v * k }; got ${ describe( indices ) }.` );

		}

		if ( ! ( weights instanceof Float32Array ) || weights.length !== v * k ) {

			throw new TypeError( `SkinnedFace.setRig: weights must be a Float32Array of ${ v } x ${ k } = ${ v * k }; got ${ describe( weights ) }.` );

		}

		for ( let i = 0; i < indices.length; i ++ ) {

			if ( indices[ i ] >= nJoints ) throw new RangeError( `SkinnedFace.setRig: joint index ${ indices[ i ] } at slot ${ i } is not below nJoints = ${ nJoints }.` );

		}

		const quads = Math.ceil( nJoints / 4 );
		this.mesh.material.uniforms.heatJoint.value = - 1;
		this._disposeRigTextures();

		if ( k <= MAX_SPARSE_INFLUENCES ) {

			this._setSparseAttributes( indices, weights, k );
			this._setDefine( 'SKIN_SPARSE' );

		} else {

			this._setWeightTexture( indices, weights, k, quads );
			this._setDefine( 'SKIN_DENSE' );

		}

		this._displacements = new Float32Array( 4 * 4 * quads );
		const texture = new DataTexture( this._displacements, 4 * quads, 1, RGBAFormat, FloatType );
		setExact( texture );
		this._skinUniforms.displacementTexture.value = texture;
		this._skinUniforms.skinQuads.value = quads;
		this.nJoints = nJoints;
		this.nInfluences = k;
		this._version ++;

	}

	/**
	 * Pose the face: feature displacements, such as a stream frame's.
	 * A face without a rig has nothing that could move it and stays at rest; the call is
	 * accepted then, so a stream may run before the rig has loaded.
	 * @param {Float32Array|null} displacements - (N*3) point-major x, y, z in mesh units,
	 *   N = the rig's nJoints; null puts the face at rest.
	 */
	setDisplacements( displacements ) {

		if ( this._displacements === null ) return;
		const texels = this._displacements;
		if ( displacements === null ) {

			texels.fill( 0 );

		} else {

			if ( ! ( displacements instanceof Float32Array ) || displacements.length !== 3 * this.nJoints ) {

				throw new TypeError( `SkinnedFace.setDisplacements: expected a Float32Array of ${ this.nJoints } x 3 = ${ 3 * this.nJoints }; got ${ describe( displacements ) }.` );

			}

			for ( let j = 0; j < this.nJoints; j ++ ) {

				texels[ 4 * j ] = displacements[ 3 * j ];
				texels[ 4 * j + 1 ] = displacements[ 3 * j + 1 ];
				texels[ 4 * j + 2 ] = displacements[ 3 * j + 2 ];

			}

		}

		this._skinUniforms.displacementTexture.value.needsUpdate = true;
		this._version ++;

	}

	/**
	 * Colour the surface by one joint's weights (viridis 0..1, red below 0, white above 1).
	 * @param {number|null} joint - joint index in 0..nJoints-1; null: normal shading.
	 */
	setHeatmap( joint ) {

		if ( joint !== null && ( ! Number.isInteger( joint ) || joint < 0 || joint >= this.nJoints ) ) {

			throw new RangeError( `SkinnedFace.setHeatmap: joint must be null or an integer below the rig's ${ this.nJoints } joints; got ${ joint }.` );

		}

		this.mesh.material.uniforms.heatJoint.value = joint === null ? - 1 : joint;

	}

	/** @param {boolean} on - draw triangle edges instead of the surface. */
	setWireframe( on ) {

		this.mesh.material.wireframe = Boolean( on );

	}

	/**
	 * The skinned vertex positions as drawn: the skinning pass's texture, which the display
	 * pass draws from, read back from the GPU.
	 * @param {WebGLRenderer} [renderer] - defaults to the renderer that last drew the face.
	 * @returns {Float32Array} (V*3) positions, mesh units.
	 */
	deformedPositions( renderer = this._renderer ?? this._privateRenderer() ) {

		const v = this.nVertices;
		const { target } = this._pass;
		this._skin( renderer );
		const texels = new Float32Array( 4 * target.width * target.height );
		renderer.readRenderTargetPixels( target, 0, 0, target.width, target.height, texels );

		const positions = new Float32Array( 3 * v );
		for ( let i = 0; i < v; i ++ ) {

			if ( texels[ 4 * i + 3 ] !== 1 ) throw new Error( `SkinnedFace.deformedPositions: vertex ${ i } was not written by the skinning pass.` );
			positions[ 3 * i ] = texels[ 4 * i ];
			positions[ 3 * i + 1 ] = texels[ 4 * i + 1 ];
			positions[ 3 * i + 2 ] = texels[ 4 * i + 2 ];

		}

		return positions;

	}

	/** Free the GPU resources (geometry, materials, textures, render targets). */
	dispose() {

		this._disposeRigTextures();
		this.mesh.geometry.dispose();
		this.mesh.material.dispose();
		this.mesh.material.uniforms.incidenceTexture.value.dispose();
		this._pass.geometry.dispose();
		this._pass.material.dispose();
		this._pass.target.dispose();
		this._pass.renderer?.dispose();

	}

	/** Run the skinning pass on `renderer` unless its target already holds this pose. */
	_skin( renderer ) {

		const pass = this._pass;
		if ( pass.done.get( renderer ) === this._version ) return;

		const previousTarget = renderer.getRenderTarget();
		const previousClearColor = renderer.getClearColor( new Color() );
		const previousClearAlpha = renderer.getClearAlpha();
		try {

			renderer.setRenderTarget( pass.target );
			renderer.setClearColor( 0x000000, 0 );
			renderer.clear();
			renderer.render( pass.scene, pass.camera );
			pass.done.set( renderer, this._version );

		} finally {

			renderer.setRenderTarget( previousTarget );
			renderer.setClearColor( previousClearColor, previousClearAlpha );

		}

	}

	_setSparseAttributes( indices, weights, k ) {

		const v = this.nVertices;
		const geometry = this.mesh.geometry;
		// allocated once: three.js frees an attribute's buffer only with its geometry
		if ( ! geometry.hasAttribute( 'skinIndex' ) ) {

			for ( const [ name, ArrayType ] of [ [ 'skinIndex', Uint16Array ], [ 'skinWeight', Float32Array ], [ 'skinIndex1', Uint16Array ], [ 'skinWeight1', Float32Array ] ] ) {

				const attribute = new BufferAttribute( new ArrayType( 4 * v ), 4 );
				if ( ArrayType === Uint16Array ) attribute.gpuType = IntType; // uvec4 in the shader, not normalised floats
				geometry.setAttribute( name, attribute );
				this._pass.geometry.setAttribute( name, attribute );

			}

		}

		const slots = [ geometry.getAttribute( 'skinIndex' ), geometry.getAttribute( 'skinIndex1' ) ];
		const values = [ geometry.getAttribute( 'skinWeight' ), geometry.getAttribute( 'skinWeight1' ) ];
		for ( const attribute of [ ...slots, ...values ] ) attribute.array.fill( 0 );

		for ( let i = 0; i < v; i ++ ) {

			for ( let s = 0; s < k; s ++ ) {

				const half = s >> 2, lane = 4 * i + ( s & 3 );
				slots[ half ].array[ lane ] = indices[ i * k + s ];
				values[ half ].array[ lane ] = weights[ i * k + s ];

			}

		}

		for ( const attribute of [ ...slots, ...values ] ) attribute.needsUpdate = true;

	}

	_setWeightTexture( indices, weights, k, quads ) {

		const v = this.nVertices;
		const stride = 4 * quads; // floats per vertex
		const height = Math.ceil( v * quads / SKIN_TEXTURE_WIDTH );
		const dense = new Float32Array( 4 * SKIN_TEXTURE_WIDTH * height );
		// a scatter-add, not a copy: k may be below N with any joint order, and a joint listed
		// twice counts twice, as in the CPU twin's sparse matrix
		for ( let i = 0; i < v; i ++ ) {

			const row = i * stride, slot = i * k;
			for ( let s = 0; s < k; s ++ ) dense[ row + indices[ slot + s ] ] += weights[ slot + s ];

		}

		const texture = new DataTexture( dense, SKIN_TEXTURE_WIDTH, height, RGBAFormat, FloatType );
		setExact( texture );
		this._skinUniforms.skinWeightTexture.value = texture;

	}

	_setDefine( define ) {

		const defines = define === null ? {} : { [ define ]: '' };
		for ( const material of [ this.mesh.material, this._pass.material ] ) {

			material.defines = defines;
			material.needsUpdate = true;

		}

	}

	_disposeRigTextures() {

		for ( const name of [ 'displacementTexture', 'skinWeightTexture' ] ) {

			this._skinUniforms[ name ].value?.dispose();
			this._skinUniforms[ name ].value = null;

		}

		this._displacements = null;

	}

	_privateRenderer() {

		if ( this._pass.renderer === null ) this._pass.renderer = new WebGLRenderer();
		return this._pass.renderer;

	}

}

async function loadShaders( baseURL ) {

	const texts = await Promise.all( SHADER_FILES.map( async ( name ) => {

		const response = await fetch( new URL( name, new URL( baseURL, location.href ) ) );
		if ( ! response.ok ) throw new Error( `SkinnedFace: could not load shader ${ baseURL }${ name }: HTTP ${ response.status }.` );
		return [ name, await response.text() ];

	} ) );
	const files = Object.fromEntries( texts );
	// our own includes are quoted file names; three.js resolves its <chunk> includes itself
	const resolve = ( source ) => source.replace( /^[ \t]*#include "([^"]+)"[ \t]*$/gm, ( line, name ) => {

		if ( ! ( name in files ) ) throw new Error( `SkinnedFace: shader include "${ name }" is not one of ${ SHADER_FILES.join( ', ' ) }.` );
		return files[ name ];

	} );
	return Object.fromEntries( texts.map( ( [ name, text ] ) => [ name, resolve( text ) ] ) );

}

/**
 * Each vertex's triangles for the deformed normals (web/shaders/face.vert): for every
 * corner of every triangle, the other two corners in winding order, grouped by vertex.
 * @param {Uint32Array} faces - (F*3) vertex indices.
 * @param {number} nVertices
 * @returns {{ranges: Uint32Array, texture: DataTexture}} ranges: (V*2) first texel and
 *   count per vertex; texture: RG32F, SKIN_TEXTURE_WIDTH wide, one corner pair a texel.
 */
function incidences( faces, nVertices ) {

	const ranges = new Uint32Array( 2 * nVertices );
	for ( let i = 0; i < faces.length; i ++ ) ranges[ 2 * faces[ i ] + 1 ] ++;
	for ( let v = 1; v < nVertices; v ++ ) ranges[ 2 * v ] = ranges[ 2 * v - 2 ] + ranges[ 2 * v - 1 ];

	const height = Math.max( 1, Math.ceil( faces.length / SKIN_TEXTURE_WIDTH ) );
	const corners = new Float32Array( 2 * SKIN_TEXTURE_WIDTH * height );
	const filled = new Uint32Array( nVertices );
	for ( let f = 0; f < faces.length; f += 3 ) {

		for ( let c = 0; c < 3; c ++ ) {

			const vertex = faces[ f + c ];
			const texel = ranges[ 2 * vertex ] + filled[ vertex ] ++;
			corners[ 2 * texel ] = faces[ f + ( c + 1 ) % 3 ];
			corners[ 2 * texel + 1 ] = faces[ f + ( c + 2 ) % 3 ];

		}

	}

	const texture = new DataTexture( corners, SKIN_TEXTURE_WIDTH, height, RGFormat, FloatType );
	setExact( texture );
	return { ranges, texture };

}

/** Nearest, unfiltered, no mipmaps: the texture is data, read with texelFetch. */
function setExact( texture ) {

	texture.minFilter = texture.magFilter = NearestFilter;
	texture.generateMipmaps = false;
	texture.needsUpdate = true;

}

function describe( value ) {

	return value?.constructor ? `${ value.constructor.name }${ value.length !== undefined ? ` of length ${ value.length }` : '' }` : String( value );

}
