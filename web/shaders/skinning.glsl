// Linear blend skinning with feature points as translation-only joints (Dutreve et al.
// 2008, §3.1):
//
//     v = v0 + sum_k w[v, k] * d[j[v, k]]
//
// The GPU twin of retarget/skin.py `skin_displacements`. Rows may sum to less than 1 (the
// rest belongs to the static root joint) and dense deformers have small negative weights:
// nothing here clamps or normalises them.
//
// One of two defines picks where the weights live (SkinnedFace.setRig sets it):
//   SKIN_SPARSE  at most 8 influences per vertex as vertex attributes, glTF's JOINTS_0/1 and
//                WEIGHTS_0/1 under three.js's names (skinIndex, skinWeight, skinIndex1,
//                skinWeight1); unused slots have weight 0.
//   SKIN_DENSE   every joint for every vertex in an RGBA32F texture, 4 joints a texel:
//                vertex v's joints 4q..4q+3 are texel t = v * skinQuads + q, row-major in a
//                texture SKIN_TEXTURE_WIDTH texels wide. Joints past N are padded with 0.
// Neither define: no rig, the rest pose.
//
// Included (as text, by SkinnedFace) by skin_pass.vert, which skins every vertex into a
// texture that face.vert draws and deformedPositions() reads back for the shader-vs-CPU
// test, and by face.vert for the heat map's skinWeightOf.

#define SKIN_TEXTURE_WIDTH 4096

// Feature displacements, joint j at texel (j, 0), xyz in mesh units; padded to a whole
// number of quads with zeros so the dense loop never reads garbage.
uniform highp sampler2D displacementTexture;

#if defined( SKIN_DENSE )

	uniform highp sampler2D skinWeightTexture;
	uniform int skinQuads; // ceil( N / 4 ): texels per vertex

#elif defined( SKIN_SPARSE )

	in uvec4 skinIndex;
	in vec4 skinWeight;
	in uvec4 skinIndex1;
	in vec4 skinWeight1;

#endif

vec3 jointDisplacement( const in int joint ) {

	return texelFetch( displacementTexture, ivec2( joint, 0 ), 0 ).xyz;

}

#if defined( SKIN_DENSE )

	ivec2 skinWeightTexel( const in int texel ) {

		return ivec2( texel % SKIN_TEXTURE_WIDTH, texel / SKIN_TEXTURE_WIDTH );

	}

#endif

// Displacement of vertex `vertex` (its index in the position attribute), mesh units.
vec3 skinDisplacement( const in int vertex ) {

	vec3 displacement = vec3( 0.0 );

	#if defined( SKIN_DENSE )

		ivec2 texel = skinWeightTexel( vertex * skinQuads );

		for ( int q = 0; q < skinQuads; q ++ ) {

			vec4 w = texelFetch( skinWeightTexture, texel, 0 );
			int j = 4 * q;
			displacement += w.x * jointDisplacement( j ) + w.y * jointDisplacement( j + 1 )
				+ w.z * jointDisplacement( j + 2 ) + w.w * jointDisplacement( j + 3 );

			texel.x ++;
			if ( texel.x == SKIN_TEXTURE_WIDTH ) texel = ivec2( 0, texel.y + 1 );

		}

	#elif defined( SKIN_SPARSE )

		displacement = skinWeight.x * jointDisplacement( int( skinIndex.x ) )
			+ skinWeight.y * jointDisplacement( int( skinIndex.y ) )
			+ skinWeight.z * jointDisplacement( int( skinIndex.z ) )
			+ skinWeight.w * jointDisplacement( int( skinIndex.w ) )
			+ skinWeight1.x * jointDisplacement( int( skinIndex1.x ) )
			+ skinWeight1.y * jointDisplacement( int( skinIndex1.y ) )
			+ skinWeight1.z * jointDisplacement( int( skinIndex1.z ) )
			+ skinWeight1.w * jointDisplacement( int( skinIndex1.w ) );

	#endif

	return displacement;

}

// Weight of joint `joint` on vertex `vertex` (0 when it has none), for the heat map.
float skinWeightOf( const in int vertex, const in int joint ) {

	#if defined( SKIN_DENSE )

		vec4 w = texelFetch( skinWeightTexture, skinWeightTexel( vertex * skinQuads + joint / 4 ), 0 );
		return w[ joint % 4 ];

	#elif defined( SKIN_SPARSE )

		uvec4 j = uvec4( joint );
		// a joint may sit in several slots (duplicates add up, as in the CPU twin)
		return dot( skinWeight, vec4( equal( skinIndex, j ) ) ) + dot( skinWeight1, vec4( equal( skinIndex1, j ) ) );

	#else

		return 0.0;

	#endif

}
