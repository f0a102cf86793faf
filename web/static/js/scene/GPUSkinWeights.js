import { BufferAttribute, IntType } from 'three';

import { SKIN_TEXTURE_WIDTH, exactTexture } from './VertexPasses.js';

/**
 * A rig's skin weights in the form web/shaders/skinning.glsl reads them: up to 8
 * influences per vertex as vertex attributes (`skinIndex`, `skinWeight`, `skinIndex1`,
 * `skinWeight1`; define SKIN_SPARSE), denser rigs as an RGBA32F texture of every joint's
 * weight per vertex (`skinWeightTexture`, 4 joints a texel; define SKIN_DENSE). A rig
 * uploads once; `update` rewrites some vertices' rows and uploads only their ranges.
 */
export class GPUSkinWeights {

	static MAX_SPARSE_INFLUENCES = 8;

	/**
	 * @param {import('three').BufferGeometry} geometry - the face's; the attributes go on it.
	 * @param {import('./VertexPasses.js').VertexPasses} passes - the skinning pass shares them.
	 * @param {{skinWeightTexture: {value: *}, skinQuads: {value: number}}} uniforms - the
	 *   skinning uniforms; the dense texture goes in `skinWeightTexture` (freed by its owner).
	 */
	constructor( geometry, passes, uniforms ) {

		this._geometry = geometry;
		this._passes = passes;
		this._uniforms = uniforms;

	}

	/**
	 * Upload a whole rig.
	 * @param {Uint16Array} indices - (V*k) joint indices, each below the rig's joint count.
	 * @param {Float32Array} weights - (V*k) weights.
	 * @param {number} k - influences per vertex.
	 * @param {number} quads - ceil(joints / 4): texels per vertex of the dense texture.
	 * @returns {'SKIN_SPARSE'|'SKIN_DENSE'} the shader define of the layout used.
	 */
	set( indices, weights, k, quads ) {

		if ( k <= GPUSkinWeights.MAX_SPARSE_INFLUENCES ) {

			this._setAttributes( indices, weights, k );
			return 'SKIN_SPARSE';

		}

		const v = indices.length / k;
		const stride = 4 * quads; // floats per vertex
		const height = Math.ceil( v * quads / SKIN_TEXTURE_WIDTH );
		const dense = new Float32Array( 4 * SKIN_TEXTURE_WIDTH * height );
		// a scatter-add, not a copy: k may be below N with any joint order, and a joint listed
		// twice counts twice, as in the CPU twin's sparse matrix
		for ( let i = 0; i < v; i ++ ) {

			const row = i * stride, slot = i * k;
			for ( let s = 0; s < k; s ++ ) dense[ row + indices[ slot + s ] ] += weights[ slot + s ];

		}

		this._uniforms.skinWeightTexture.value = exactTexture( dense, SKIN_TEXTURE_WIDTH, height );
		return 'SKIN_DENSE';

	}

	/**
	 * Rewrite the rows of `vertices` from the rig's (V*k) arrays.
	 * @param {ArrayLike<number>} vertices - checked vertex indices.
	 * @param {Uint16Array} indices - (V*k) joint indices.
	 * @param {Float32Array} weights - (V*k) weights.
	 * @param {number} k - influences per vertex, as given to `set`.
	 * @param {boolean} partial - upload only the rows' ranges (three.js merges adjacent
	 *   ones); false before the rig's first upload, which must send everything.
	 */
	update( vertices, indices, weights, k, partial ) {

		if ( k <= GPUSkinWeights.MAX_SPARSE_INFLUENCES ) {

			const { slots, values } = this._attributes();
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
			return;

		}

		const texture = this._uniforms.skinWeightTexture.value;
		const dense = texture.image.data;
		const stride = 4 * this._uniforms.skinQuads.value;
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

	/** The sparse layout's attributes, made once: three.js frees an attribute's buffer only with its geometry. */
	_attributes() {

		const geometry = this._geometry, v = geometry.getAttribute( 'position' ).count;
		if ( ! geometry.hasAttribute( 'skinIndex' ) ) {

			for ( const [ name, ArrayType ] of [ [ 'skinIndex', Uint16Array ], [ 'skinWeight', Float32Array ], [ 'skinIndex1', Uint16Array ], [ 'skinWeight1', Float32Array ] ] ) {

				const attribute = new BufferAttribute( new ArrayType( 4 * v ), 4 );
				if ( ArrayType === Uint16Array ) attribute.gpuType = IntType; // uvec4 in the shader, not normalised floats
				geometry.setAttribute( name, attribute );
				this._passes.setSkinAttribute( name, attribute );

			}

		}

		return {
			slots: [ geometry.getAttribute( 'skinIndex' ), geometry.getAttribute( 'skinIndex1' ) ],
			values: [ geometry.getAttribute( 'skinWeight' ), geometry.getAttribute( 'skinWeight1' ) ],
		};

	}

	_setAttributes( indices, weights, k ) {

		const { slots, values } = this._attributes();
		for ( const attribute of [ ...slots, ...values ] ) attribute.array.fill( 0 );
		for ( let i = 0, v = indices.length / k; i < v; i ++ ) {

			for ( let s = 0; s < k; s ++ ) {

				const half = s >> 2, lane = 4 * i + ( s & 3 );
				slots[ half ].array[ lane ] = indices[ i * k + s ];
				values[ half ].array[ lane ] = weights[ i * k + s ];

			}

		}

		for ( const attribute of [ ...slots, ...values ] ) attribute.needsUpdate = true;

	}

}
