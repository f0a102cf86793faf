// Morph targets in a float texture, the one way the face's shaders read them (the played
// muscles, muscles.glsl; ARKit's 52 blendshapes, arkit.glsl):
//
//     sum_t weights[t] * target[t, vertex]
//
// Targets live in an RGBA32F texture, xyz of target t for vertex v at texel v * COUNT + t,
// row-major, SKIN_TEXTURE_WIDTH texels wide: a vertex's targets are adjacent, one fetch
// stream per vertex (SkinnedFace / ArkitMorphs pack them). A macro, because GLSL ES has
// no arrays of unsized length as parameters: each user has its own weight array of its
// own COUNT. Needs skinning.glsl (SKIN_TEXTURE_WIDTH) first.

#define MORPH_TARGETS_ADD( SUM, TEXTURE, WEIGHTS, COUNT, VERTEX ) { \
	int morphFirst = ( VERTEX ) * ( COUNT ); \
	ivec2 morphTexel = ivec2( morphFirst % SKIN_TEXTURE_WIDTH, morphFirst / SKIN_TEXTURE_WIDTH ); \
	for ( int morphT = 0; morphT < ( COUNT ); morphT ++ ) { \
		SUM += WEIGHTS[ morphT ] * texelFetch( TEXTURE, morphTexel, 0 ).xyz; \
		morphTexel.x ++; \
		if ( morphTexel.x == SKIN_TEXTURE_WIDTH ) morphTexel = ivec2( 0, morphTexel.y + 1 ); \
	} \
}
