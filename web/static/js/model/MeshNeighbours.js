/**
 * A triangle mesh's vertex adjacency (CSR: vertex v's neighbours are
 * `neighbours[offsets[v]..offsets[v + 1]]`, the other two vertices of each triangle it is
 * in) and the surface-connected neighbourhoods a brush reaches.
 */
export class MeshNeighbours {

	/**
	 * @param {ArrayLike<number>} faces - (3F) vertex indices.
	 * @param {number} nVertices
	 */
	constructor( faces, nVertices ) {

		const counts = new Uint32Array( nVertices + 1 );
		for ( let f = 0; f < faces.length; f += 3 ) for ( let c = 0; c < 3; c ++ ) counts[ faces[ f + c ] + 1 ] += 2;
		for ( let v = 0; v < nVertices; v ++ ) counts[ v + 1 ] += counts[ v ];
		const neighbours = new Uint32Array( counts[ nVertices ] ), fill = counts.slice( 0, nVertices );
		for ( let f = 0; f < faces.length; f += 3 ) {

			for ( let c = 0; c < 3; c ++ ) {

				const v = faces[ f + c ];
				neighbours[ fill[ v ] ++ ] = faces[ f + ( c + 1 ) % 3 ];
				neighbours[ fill[ v ] ++ ] = faces[ f + ( c + 2 ) % 3 ];

			}

		}

		this.faces = faces;
		this.offsets = counts;
		this.neighbours = neighbours;
		this._stamp = new Uint32Array( nVertices ); // per-vertex visit marks of the flood fill
		this._stampId = 0;

	}

	/**
	 * The vertices within `radius` of `center` that the surface connects to triangle
	 * `faceIndex` through vertices within it (so a brush on the upper lip leaves the lower
	 * lip alone), and their distances from the centre.
	 * @param {ArrayLike<number>} positions - (3V) mesh units.
	 * @param {{x: number, y: number, z: number}} center - mesh units.
	 * @param {number} faceIndex - the triangle under the centre.
	 * @param {number} radius - mesh units.
	 * @returns {{vertices: number[], distances: number[]}}
	 */
	within( positions, center, faceIndex, radius ) {

		const { faces, offsets, neighbours } = this;
		if ( ++ this._stampId > 0xfffffff0 ) {

			this._stamp.fill( 0 );
			this._stampId = 1;

		}

		const stamp = this._stamp, id = this._stampId, r2 = radius * radius;
		const queue = [ faces[ 3 * faceIndex ], faces[ 3 * faceIndex + 1 ], faces[ 3 * faceIndex + 2 ] ];
		for ( const v of queue ) stamp[ v ] = id;
		const vertices = [], distances = [];
		for ( let q = 0; q < queue.length; q ++ ) {

			const v = queue[ q ];
			const dx = positions[ 3 * v ] - center.x, dy = positions[ 3 * v + 1 ] - center.y, dz = positions[ 3 * v + 2 ] - center.z;
			const d2 = dx * dx + dy * dy + dz * dz;
			if ( d2 >= r2 ) continue;
			vertices.push( v );
			distances.push( Math.sqrt( d2 ) );
			for ( let e = offsets[ v ]; e < offsets[ v + 1 ]; e ++ ) {

				const u = neighbours[ e ];
				if ( stamp[ u ] !== id ) {

					stamp[ u ] = id;
					queue.push( u );

				}

			}

		}

		return { vertices, distances };

	}

	/**
	 * The mean of `value` over vertex v's neighbours (each once per triangle they share);
	 * `value(v)` for a vertex in no triangle.
	 * @param {number} v
	 * @param {(u: number) => number} value
	 */
	mean( v, value ) {

		const { offsets, neighbours } = this;
		let sum = 0;
		for ( let e = offsets[ v ]; e < offsets[ v + 1 ]; e ++ ) sum += value( neighbours[ e ] );
		const n = offsets[ v + 1 ] - offsets[ v ];
		return n ? sum / n : value( v );

	}

}
