import {
	BufferAttribute,
	BufferGeometry,
	Color,
	DoubleSide,
	GLSL3,
	LinearMipmapLinearFilter,
	Mesh,
	SRGBColorSpace,
	ShaderMaterial,
	Texture,
	UniformsLib,
	UniformsUtils,
	Vector3,
	WebGLRenderer,
} from 'three';

import { GPUSkinWeights } from './GPUSkinWeights.js';
import { ShaderLoader } from './ShaderLoader.js';
import { SKIN_TEXTURE_WIDTH, VertexPasses, exactTexture } from './VertexPasses.js';
import { redraw } from './Viewer.js';

const MAX_JOINTS = 4096; // the displacement texture is one row
const MAX_VERTICES = 2 ** 24; // vertex indices are stored in float32 textures, exact up to 2^24
const SHADER_FILES = [ 'skinning.glsl', 'morph_targets.glsl', 'muscles.glsl', 'arkit.glsl', 'vertex_texels.glsl', 'skin_pass.vert', 'normal_pass.vert', 'texel_pass.frag', 'face.vert', 'face.frag' ];

/**
 * A face mesh skinned on the GPU by its feature points (Dutreve et al. 2008, §3.1: feature
 * points are translation-only joints), `v = v0 + sum_k w[v,k] d[j[v,k]]`.
 *
 * The geometry holds the rest pose (raycasting and picking work on it). Whenever the pose
 * or rig changed, two passes (VertexPasses) write one RGBA32F texel per vertex: the
 * skinned positions, then the normals of the deformed surface. The display pass
 * (web/shaders/face.vert) draws from those textures, and `deformedPositions()` /
 * `deformedNormals()` read those very textures back, so tests compare what is drawn with
 * the CPU twin (retarget/skin.py).
 *
 * Rigs with at most 8 influences per vertex go in vertex attributes; denser ones (the
 * default biharmonic rig weights every vertex by every joint) in an RGBA32F texture
 * (GPUSkinWeights). Both upload once per rig, and painting (`updateWeights`) uploads only
 * the span of rows it changed; a pose updates only the N-texel displacement texture.
 *
 * Driven by muscles instead (`setMuscles`, then `setContractions`), the same skinning
 * pass plays the muscles' morph targets and jaw joint (web/shaders/muscles.glsl): a pose
 * updates only T weights and an angle, and `setDisplacements` goes back to the rig.
 * Likewise ARKit's 52 blendshapes (`setArkit`, then `setArkitWeights`; arkit.glsl).
 *
 * A mesh with uv may be drawn with its base-colour texture (`setTexture`, `setTextured`);
 * the heat map is drawn over it all the same.
 */
export class SkinnedFace {

	/**
	 * @param {{positions: Float32Array, faces: Uint32Array, uv?: Float32Array|null}} arrays -
	 *   rest positions (V*3, mesh units, vertex-major), triangles (F*3 vertex indices) and
	 *   texture coordinates (V*2, v up) or null; used in place, not copied.
	 * @param {{shaderURL?: string}} [options] - where the GLSL files are served.
	 * @returns {Promise<SkinnedFace>}
	 */
	static async create( { positions, faces, uv = null }, { shaderURL = '/shaders/' } = {} ) {

		return new SkinnedFace( positions, faces, await new ShaderLoader().load( shaderURL, SHADER_FILES ), uv );

	}

	/**
	 * Use `SkinnedFace.create`, which fetches the shaders.
	 * @param {Float32Array} positions - (V*3) rest positions.
	 * @param {Uint32Array} faces - (F*3) vertex indices.
	 * @param {Object<string, string>} shaders - GLSL by file name, includes resolved.
	 * @param {Float32Array|null} [uv] - (V*2) texture coordinates, OBJ's convention (v up).
	 */
	constructor( positions, faces, shaders, uv = null ) {

		if ( ! ( positions instanceof Float32Array ) || positions.length === 0 || positions.length % 3 !== 0 ) {

			throw new TypeError( `SkinnedFace: positions must be a non-empty Float32Array of V*3 coordinates; got ${ describe( positions ) }.` );

		}

		if ( ! ( faces instanceof Uint32Array ) || faces.length % 3 !== 0 ) {

			throw new TypeError( `SkinnedFace: faces must be a Uint32Array of F*3 vertex indices; got ${ describe( faces ) }.` );

		}

		const nVertices = positions.length / 3;
		if ( uv !== null && ( ! ( uv instanceof Float32Array ) || uv.length !== 2 * nVertices ) ) {

			throw new TypeError( `SkinnedFace: uv must be null or a Float32Array of ${ nVertices } x 2 = ${ 2 * nVertices }; got ${ describe( uv ) }.` );

		}

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
		if ( uv !== null ) geometry.setAttribute( 'uv', new BufferAttribute( uv, 2 ) );
		geometry.computeVertexNormals(); // rest normals: for picking tools, and where triangles collapse
		geometry.computeBoundingBox();
		geometry.computeBoundingSphere();

		// shared by the skinning pass and the display material (heat map)
		this._skinUniforms = {
			displacementTexture: { value: null },
			skinWeightTexture: { value: null },
			skinQuads: { value: 0 },
			// muscles.glsl's, used once setMuscles defines MUSCLE_TARGETS
			muscleDrive: { value: false },
			muscleTargetTexture: { value: null },
			muscleWeights: { value: new Float32Array( 1 ) },
			jawPivot: { value: new Vector3() },
			jawAxis: { value: new Vector3( 1, 0, 0 ) },
			jawAngle: { value: 0 },
			// arkit.glsl's, used once setArkit defines ARKIT_TARGETS
			arkitDrive: { value: false },
			arkitTargetTexture: { value: null },
			arkitWeights: { value: new Float32Array( 1 ) },
		};
		/** @type {import('./ArkitMorphs.js').ArkitMorphs|null} ARKit's shapes (`setArkit`). */
		this.arkit = null;
		/** @type {import('../model/PlayedMuscles.js').PlayedMuscles|null} the muscles (`setMuscles`). */
		this.muscles = null;

		this._passes = new VertexPasses( geometry, faces, shaders, this._skinUniforms );
		this._weights = new GPUSkinWeights( geometry, this._passes, this._skinUniforms );
		this._version = 0; // bumped by every change of pose or rig

		const uniforms = UniformsUtils.merge( [ UniformsLib.lights ] );
		Object.assign( uniforms, this._skinUniforms, {
			skinnedPositions: { value: this._passes.positionTarget.texture },
			skinnedNormals: { value: this._passes.normalTarget.texture },
			diffuse: { value: new Color( 0xd9b8a6 ) },
			specular: { value: 0.03 },
			shininess: { value: 24 },
			heatJoint: { value: - 1 },
			baseColorMap: { value: null },
			textured: { value: false },
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
		this._rigDefine = null; // 'SKIN_SPARSE', 'SKIN_DENSE' or null
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
			redraw( this.mesh );
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

		this._skinUniforms.skinQuads.value = quads;
		this._setDefine( this._weights.set( indices, weights, k, quads ) );
		this._displacements = new Float32Array( 4 * 4 * quads );
		this._skinUniforms.displacementTexture.value = exactTexture( this._displacements, 4 * quads, 1 );
		this.nJoints = nJoints;
		this.nInfluences = k;
		this._rigUploaded = false;
		this._version ++;
		redraw( this.mesh );

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
		this._weights.update( vertices, indices, weights, k, this._rigUploaded );
		this._version ++;
		redraw( this.mesh );

	}

	/**
	 * Pose the face: feature displacements, such as a stream frame's.
	 * A face without a rig has nothing that could move it and stays at rest; the call is
	 * accepted then, so a stream may run before the rig has loaded.
	 * @param {Float32Array|null} displacements - (N*3) point-major x, y, z in mesh units,
	 *   N = the rig's nJoints; null puts the face at rest.
	 */
	setDisplacements( displacements ) {

		if ( this._skinUniforms.muscleDrive.value || this._skinUniforms.arkitDrive.value ) {

			this._skinUniforms.muscleDrive.value = this._skinUniforms.arkitDrive.value = false; // the feature points drive again
			this._version ++;
			redraw( this.mesh );

		}

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
		redraw( this.mesh );

	}

	/**
	 * Set (or with null, remove) the face's muscles, played from then on by
	 * `setContractions`. Uploads the morph targets once (an RGBA32F texture, a vertex's
	 * targets adjacent) and the jaw weights (a vertex attribute).
	 * @param {import('../model/PlayedMuscles.js').PlayedMuscles|null} muscles - for this mesh.
	 */
	setMuscles( muscles ) {

		const uniforms = this._skinUniforms;
		uniforms.muscleTargetTexture.value?.dispose();
		uniforms.muscleTargetTexture.value = null;
		uniforms.muscleDrive.value = false;
		this.muscles = null;
		if ( muscles !== null ) {

			const v = this.nVertices, t = muscles.nTargets;
			if ( muscles.nVertices !== v ) throw new RangeError( `SkinnedFace.setMuscles: the muscles are for ${ muscles.nVertices } vertices, the face has ${ v }.` );
			const height = Math.ceil( v * t / SKIN_TEXTURE_WIDTH );
			const texels = new Float32Array( 4 * SKIN_TEXTURE_WIDTH * height );
			// (T, V, 3) target-major in, vertex-major texels out: a vertex reads its T adjacent
			for ( let k = 0; k < t; k ++ ) {

				for ( let i = 0; i < v; i ++ ) {

					const from = 3 * ( k * v + i ), to = 4 * ( i * t + k );
					texels[ to ] = muscles.targets[ from ];
					texels[ to + 1 ] = muscles.targets[ from + 1 ];
					texels[ to + 2 ] = muscles.targets[ from + 2 ];

				}

			}

			uniforms.muscleTargetTexture.value = exactTexture( texels, SKIN_TEXTURE_WIDTH, height );
			uniforms.muscleWeights.value = new Float32Array( t );
			uniforms.jawPivot.value.fromArray( muscles.jawPivot );
			uniforms.jawAxis.value.fromArray( muscles.jawAxis );
			uniforms.jawAngle.value = 0;
			this._setJawWeights( muscles.jawWeights );
			this.muscles = muscles;

		}

		this._setDefine( this._rigDefine );
		this._version ++;
		redraw( this.mesh );

	}

	/**
	 * Pose the face by its muscles (`setMuscles` first), such as a contraction frame's or
	 * the Muscles panel's sliders; `setDisplacements` goes back to the feature points.
	 * @param {ArrayLike<number>} contractions - (D) the muscles' contractions, then the jaw
	 *   angle in radians (`muscles.dofs` order).
	 */
	setContractions( contractions ) {

		if ( this.muscles === null ) throw new Error( 'SkinnedFace.setContractions: the face has no muscles (setMuscles first).' );
		const uniforms = this._skinUniforms;
		this.muscles.weights( contractions, uniforms.muscleWeights.value );
		uniforms.jawAngle.value = this.muscles.jawAngle( contractions );
		uniforms.muscleDrive.value = true;
		uniforms.arkitDrive.value = false;
		this._version ++;
		redraw( this.mesh );

	}

	/**
	 * Set (or with null, remove) ARKit's 52 blendshapes, played from then on by
	 * `setArkitWeights`; the morphs own their texture (the face does not dispose it).
	 * @param {import('./ArkitMorphs.js').ArkitMorphs|null} morphs - for this mesh.
	 */
	setArkit( morphs ) {

		const uniforms = this._skinUniforms;
		if ( morphs !== null && morphs.nVertices !== this.nVertices ) throw new RangeError( `SkinnedFace.setArkit: the shapes are for ${ morphs.nVertices } vertices, the face has ${ this.nVertices }.` );
		this.arkit = morphs;
		uniforms.arkitDrive.value = false;
		uniforms.arkitTargetTexture.value = morphs?.texture ?? null;
		uniforms.arkitWeights.value = new Float32Array( morphs?.nTargets ?? 1 );
		this._setDefine( this._rigDefine );
		this._version ++;
		redraw( this.mesh );

	}

	/**
	 * Pose the face by ARKit's shapes (`setArkit` first): a weight frame's or the
	 * Blendshapes panel's sliders; `setDisplacements` goes back to the feature points.
	 * Also call it after painting a fix, so the passes run again.
	 * @param {ArrayLike<number>} weights - (52) ARKit's order.
	 */
	setArkitWeights( weights ) {

		if ( this.arkit === null ) throw new Error( 'SkinnedFace.setArkitWeights: the face has no ARKit shapes (setArkit first).' );
		const uniforms = this._skinUniforms;
		if ( weights.length !== this.arkit.nTargets ) throw new RangeError( `SkinnedFace.setArkitWeights: expected ${ this.arkit.nTargets } weights; got ${ weights.length }.` );
		uniforms.arkitWeights.value.set( weights );
		uniforms.arkitDrive.value = true;
		uniforms.muscleDrive.value = false;
		this._version ++;
		redraw( this.mesh );

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
		redraw( this.mesh );

	}

	/** True when the face has uv and a base-colour texture to draw (`setTexture`). */
	get hasTexture() {

		return this.mesh.geometry.getAttribute( 'uv' ) !== undefined && this.mesh.material.uniforms.baseColorMap.value !== null;

	}

	/**
	 * Set (or with null, remove) the base-colour texture, sampled with the uv; it is drawn
	 * once `setTextured( true )`.
	 * @param {ImageBitmap|HTMLImageElement|HTMLCanvasElement|null} image - sRGB colours, its
	 *   first row at v = 0 (an ImageBitmap made with imageOrientation: 'flipY'; WebGL does not
	 *   flip bitmaps on upload).
	 */
	setTexture( image ) {

		const uniforms = this.mesh.material.uniforms;
		uniforms.baseColorMap.value?.dispose();
		uniforms.baseColorMap.value = null;
		if ( image !== null ) {

			const texture = new Texture( image );
			texture.flipY = false;
			texture.colorSpace = SRGBColorSpace; // decoded to linear by the sampler
			texture.minFilter = LinearMipmapLinearFilter;
			texture.needsUpdate = true;
			uniforms.baseColorMap.value = texture;

		}

		uniforms.textured.value = uniforms.textured.value && this.hasTexture;
		redraw( this.mesh );

	}

	/**
	 * Draw the base-colour texture (true) or the plain shaded surface (false), e.g. to judge
	 * the shape; without a texture the surface is plain either way.
	 * @param {boolean} on
	 */
	setTextured( on ) {

		this.mesh.material.uniforms.textured.value = Boolean( on ) && this.hasTexture;
		redraw( this.mesh );

	}

	/**
	 * Turn the face about the centre of its rest bounding sphere, as a performer's head turns.
	 * @param {Float32Array|number[]|null} q - quaternion x, y, z, w; null puts the face back.
	 */
	setHeadRotation( q ) {

		const mesh = this.mesh;
		if ( q ) mesh.quaternion.set( q[ 0 ], q[ 1 ], q[ 2 ], q[ 3 ] );
		else mesh.quaternion.identity();
		const centre = mesh.geometry.boundingSphere.center; // computed by the constructor
		mesh.position.copy( centre ).applyQuaternion( mesh.quaternion ).negate().add( centre );
		redraw( this.mesh );

	}

	/** @param {boolean} on - draw triangle edges instead of the surface. */
	setWireframe( on ) {

		this.mesh.material.wireframe = Boolean( on );
		redraw( this.mesh );

	}

	/**
	 * The skinned vertex positions as drawn: the skinning pass's texture, which the display
	 * pass draws from, read back from the GPU.
	 * @param {WebGLRenderer} [renderer] - defaults to the renderer that last drew the face.
	 * @returns {Float32Array} (V*3) positions, mesh units.
	 */
	deformedPositions( renderer = this._renderer ?? this._passes.privateRenderer ) {

		this._runPasses( renderer );
		return this._passes.read( renderer, this._passes.positionTarget );

	}

	/**
	 * The unit normals of the deformed surface as drawn (area-weighted over each vertex's
	 * triangles), read back from the GPU.
	 * @param {WebGLRenderer} [renderer] - defaults to the renderer that last drew the face.
	 * @returns {Float32Array} (V*3) unit vectors, object space.
	 */
	deformedNormals( renderer = this._renderer ?? this._passes.privateRenderer ) {

		this._runPasses( renderer );
		return this._passes.read( renderer, this._passes.normalTarget );

	}

	/** Free the GPU resources (geometry, materials, textures, render targets). */
	dispose() {

		this._disposeRigTextures();
		this._skinUniforms.muscleTargetTexture.value?.dispose();
		this.setTexture( null );
		this.mesh.geometry.dispose();
		this.mesh.material.dispose();
		this._passes.dispose();

	}

	/** Run the skinning and normal passes on `renderer` unless its targets hold this pose. */
	_runPasses( renderer ) {

		if ( this._passes.run( renderer, this._version ) ) this._rigUploaded = this.nInfluences > 0;

	}

	/** The rig's define on both materials, and the muscles' and ARKit's on the skinning pass. */
	_setDefine( define ) {

		this._rigDefine = define;
		const defines = define === null ? {} : { [ define ]: '' };
		this.mesh.material.defines = defines;
		this.mesh.material.needsUpdate = true;
		const skin = this._passes.skinMaterial;
		skin.defines = { ...defines };
		if ( this.muscles !== null ) skin.defines.MUSCLE_TARGETS = this.muscles.nTargets;
		if ( this.arkit !== null ) skin.defines.ARKIT_TARGETS = this.arkit.nTargets;
		skin.needsUpdate = true;

	}

	/** The jaw weights as the skinning pass's `jawWeight` attribute (made once per face). */
	_setJawWeights( weights ) {

		const geometry = this.mesh.geometry;
		if ( ! geometry.hasAttribute( 'jawWeight' ) ) {

			const attribute = new BufferAttribute( new Float32Array( this.nVertices ), 1 );
			geometry.setAttribute( 'jawWeight', attribute );
			this._passes.setSkinAttribute( 'jawWeight', attribute );

		}

		const attribute = geometry.getAttribute( 'jawWeight' );
		attribute.array.set( weights );
		attribute.needsUpdate = true;

	}

	_disposeRigTextures() {

		for ( const name of [ 'displacementTexture', 'skinWeightTexture' ] ) {

			this._skinUniforms[ name ].value?.dispose();
			this._skinUniforms[ name ].value = null;

		}

		this._displacements = null;

	}

}

function describe( value ) {

	return value?.constructor ? `${ value.constructor.name }${ value.length !== undefined ? ` of length ${ value.length }` : '' }` : String( value );

}
