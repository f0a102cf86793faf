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
const SHADER_FILES = [ 'skinning.glsl', 'vertex_texels.glsl', 'skin_pass.vert', 'normal_pass.vert', 'texel_pass.frag', 'face.vert', 'face.frag' ];

const shaderSources = new Map(); // base URL -> Promise of { file name: GLSL with includes resolved }

/**
 * A face mesh skinned on the GPU by its feature points (Dutreve et al. 2008, §3.1: feature
 * points are translation-only joints), `v = v0 + sum_k w[v,k] d[j[v,k]]`.
 *
 * The geometry holds the rest pose (raycasting and picking work on it). Whenever the pose
 * or rig changed, two passes write one RGBA32F texel per vertex: the skinning pass
 * (web/shaders/skin_pass.vert, running web/shaders/skinning.glsl) the skinned positions,
 * then the normal pass (normal_pass.vert) the normals of the deformed surface. The display
 * pass (face.vert) draws from those textures, and `deformedPositions()` /
 * `deformedNormals()` read those very textures back, so tests compare what is drawn with
 * the CPU twin (retarget/skin.py).
 *
 * Rigs with at most 8 influences per vertex go in vertex attributes; denser ones (the
 * default biharmonic rig weights every vertex by every joint) in an RGBA32F texture. Both
 * upload once per rig, and painting (`updateWeights`) uploads only the span of rows it
 * changed; a pose updates only the N-texel displacement texture.
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
		geometry.computeVertexNormals(); // rest normals: for picking tools, and where triangles collapse
		geometry.computeBoundingBox();
		geometry.computeBoundingSphere();

		// shared by the skinning pass and the display material (heat map)
		this._skinUniforms = {
			displacementTexture: { value: null },
			skinWeightTexture: { value: null },
			skinQuads: { value: 0 },
		};

		// Per pose, two passes draw every vertex as a point (unindexed, so gl_VertexID is the
		// vertex index) into its texel of a float target: skinned positions, then normals.
		const size = { value: [ SKIN_TEXTURE_WIDTH, Math.ceil( nVertices / SKIN_TEXTURE_WIDTH ) ] };
		const positionTarget = vertexTarget( size.value );
		const normalTarget = vertexTarget( size.value );
		const { ranges, texture: incidenceTexture } = incidences( faces, nVertices );
		const skinPass = pointsPass( shaders[ 'skin_pass.vert' ], shaders[ 'texel_pass.frag' ],
			Object.assign( { passSize: size }, this._skinUniforms ), { position: geometry.getAttribute( 'position' ) } );
		const normalPass = pointsPass( shaders[ 'normal_pass.vert' ], shaders[ 'texel_pass.frag' ], {
			passSize: size,
			skinnedPositions: { value: positionTarget.texture },
			incidenceTexture: { value: incidenceTexture },
		}, {
			position: geometry.getAttribute( 'position' ), // its count is the number of points
			normal: geometry.getAttribute( 'normal' ),
			incidence: new BufferAttribute( ranges, 2 ),
		} );
		this._pass = {
			skin: skinPass, normal: normalPass, positionTarget, normalTarget,
			camera: new Camera(), // unused by the shaders; three.js needs one
			done: new WeakMap(), // renderer -> the version of the pose its targets hold
			renderer: null, // a private one, only if a readback comes before any drawing
		};
		this._version = 0; // bumped by every change of pose or rig

		const uniforms = UniformsUtils.merge( [ UniformsLib.lights ] );
		Object.assign( uniforms, this._skinUniforms, {
			skinnedPositions: { value: positionTarget.texture },
			skinnedNormals: { value: normalTarget.texture },
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
		// a nested render, as three.js's Reflector does; the passes run only when the pose
		// changed since this renderer last ran them
		this.mesh.onBeforeRender = ( renderer ) => {

			this._renderer = renderer;
			this._runPasses( renderer );

		};

		this._displacements = null; // Float32Array( 4 * skinQuads * 4 ), RGBA texels
		this._rigUploaded = false; // the rig's attributes or texture reached the GPU
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
		this._rigUploaded = false;
		this._version ++;

	}

	/**
	 * Change the weights of some vertices of the current rig, as painting does: their rows
	 * are read from `indices` and `weights` (the (V*k) arrays of `setRig`'s form, k the
	 * rig's nInfluences) and only their attribute or texture ranges are uploaded again
	 * (three.js merges adjacent ones). The pose and the heat map follow at the next draw.
	 * @param {ArrayLike<number>} vertices - vertex indices whose rows changed.
	 * @param {Uint16Array} indices - (V*k) joint indices, each below nJoints.
	 * @param {Float32Array} weights - (V*k) weights.
	 */
	updateWeights( vertices, indices, weights ) {

		const k = this.nInfluences;
		if ( k === 0 ) throw new Error( 'SkinnedFace.updateWeights: the face has no rig.' );
		if ( indices.length !== this.nVertices * k || weights.length !== this.nVertices * k ) {

			throw new TypeError( `SkinnedFace.updateWeights: indices and weights must hold ${ this.nVertices } x ${ k } values; got ${ describe( indices ) } and ${ describe( weights ) }.` );

		}

		if ( vertices.length === 0 ) return;
		for ( let n = 0; n < vertices.length; n ++ ) {

			const i = vertices[ n ];
			if ( ! ( i >= 0 && i < this.nVertices ) ) throw new RangeError( `SkinnedFace.updateWeights: vertex ${ i } is not one of the ${ this.nVertices } vertices.` );
			for ( let s = i * k; s < i * k + k; s ++ ) {

				if ( indices[ s ] >= this.nJoints ) throw new RangeError( `SkinnedFace.updateWeights: joint index ${ indices[ s ] } at slot ${ s } is not below nJoints = ${ this.nJoints }.` );

			}

		}

		// before the rig's first upload a partial range would leave the rest uninitialised
		const partial = this._rigUploaded;
		if ( k <= MAX_SPARSE_INFLUENCES ) {

			const geometry = this.mesh.geometry;
			const slots = [ geometry.getAttribute( 'skinIndex' ), geometry.getAttribute( 'skinIndex1' ) ];
			const values = [ geometry.getAttribute( 'skinWeight' ), geometry.getAttribute( 'skinWeight1' ) ];
			for ( let n = 0; n < vertices.length; n ++ ) {

				const i = vertices[ n ];
				for ( let s = 0; s < 8; s ++ ) {

					const half = s >> 2, lane = 4 * i + ( s & 3 );
					slots[ half ].array[ lane ] = s < k ? indices[ i * k + s ] : 0;
					values[ half ].array[ lane ] = s < k ? weights[ i * k + s ] : 0;

				}

				if ( partial ) for ( const attribute of [ ...slots, ...values ] ) attribute.addUpdateRange( 4 * i, 4 );

			}

			for ( const attribute of [ ...slots, ...values ] ) attribute.needsUpdate = true;

		} else {

			const texture = this._skinUniforms.skinWeightTexture.value;
			const dense = texture.image.data;
			const stride = 4 * this._skinUniforms.skinQuads.value;
			const rowFloats = 4 * SKIN_TEXTURE_WIDTH;
			for ( let n = 0; n < vertices.length; n ++ ) {

				const i = vertices[ n ], row = i * stride, slot = i * k;
				dense.fill( 0, row, row + stride );
				for ( let s = 0; s < k; s ++ ) dense[ row + indices[ slot + s ] ] += weights[ slot + s ];
				// a texture update range may not cross a texture row: split the vertex's texels at one
				for ( let start = row; partial && start < row + stride; ) {

					const count = Math.min( row + stride, ( Math.floor( start / rowFloats ) + 1 ) * rowFloats ) - start;
					texture.addUpdateRange( start, count );
					start += count;

				}

			}

			texture.needsUpdate = true;

		}

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

		return this._readBack( renderer, this._pass.positionTarget );

	}

	/**
	 * The unit normals of the deformed surface as drawn (area-weighted over each vertex's
	 * triangles), read back from the GPU.
	 * @param {WebGLRenderer} [renderer] - defaults to the renderer that last drew the face.
	 * @returns {Float32Array} (V*3) unit vectors, object space.
	 */
	deformedNormals( renderer = this._renderer ?? this._privateRenderer() ) {

		return this._readBack( renderer, this._pass.normalTarget );

	}

	/** Free the GPU resources (geometry, materials, textures, render targets). */
	dispose() {

		this._disposeRigTextures();
		this.mesh.geometry.dispose();
		this.mesh.material.dispose();
		const { skin, normal, positionTarget, normalTarget } = this._pass;
		for ( const pass of [ skin, normal ] ) {

			pass.geometry.dispose();
			pass.material.dispose();

		}

		normal.material.uniforms.incidenceTexture.value.dispose();
		positionTarget.dispose();
		normalTarget.dispose();
		this._pass.renderer?.dispose();

	}

	/** Run the skinning and normal passes on `renderer` unless its targets hold this pose. */
	_runPasses( renderer ) {

		const pass = this._pass;
		if ( pass.done.get( renderer ) === this._version ) return;

		const previousTarget = renderer.getRenderTarget();
		const previousClearColor = renderer.getClearColor( new Color() );
		const previousClearAlpha = renderer.getClearAlpha();
		try {

			renderer.setClearColor( 0x000000, 0 );
			for ( const [ { scene }, target ] of [ [ pass.skin, pass.positionTarget ], [ pass.normal, pass.normalTarget ] ] ) {

				renderer.setRenderTarget( target );
				renderer.clear();
				renderer.render( scene, pass.camera );

			}

			pass.done.set( renderer, this._version );
			this._rigUploaded = this.nInfluences > 0;

		} finally {

			renderer.setRenderTarget( previousTarget );
			renderer.setClearColor( previousClearColor, previousClearAlpha );

		}

	}

	/** (V*3) floats of a per-vertex target, brought up to date first. */
	_readBack( renderer, target ) {

		this._runPasses( renderer );
		const v = this.nVertices;
		const texels = new Float32Array( 4 * target.width * target.height );
		renderer.readRenderTargetPixels( target, 0, 0, target.width, target.height, texels );

		const values = new Float32Array( 3 * v );
		for ( let i = 0; i < v; i ++ ) {

			if ( texels[ 4 * i + 3 ] !== 1 ) throw new Error( `SkinnedFace: vertex ${ i } was not written by its pass.` );
			values[ 3 * i ] = texels[ 4 * i ];
			values[ 3 * i + 1 ] = texels[ 4 * i + 1 ];
			values[ 3 * i + 2 ] = texels[ 4 * i + 2 ];

		}

		return values;

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
				this._pass.skin.geometry.setAttribute( name, attribute );

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
		for ( const material of [ this.mesh.material, this._pass.skin.material ] ) {

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
