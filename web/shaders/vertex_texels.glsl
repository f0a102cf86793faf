// Per-vertex values that the skinning and normal passes write, read back by vertex index:
// vertex v is texel (v % SKIN_TEXTURE_WIDTH, v / SKIN_TEXTURE_WIDTH) of an RGBA32F target.
// Needs skinning.glsl (SKIN_TEXTURE_WIDTH) first.

uniform highp sampler2D skinnedPositions; // the skinning pass's target: xyz mesh units

ivec2 skinTexel( const in int index ) {

	return ivec2( index % SKIN_TEXTURE_WIDTH, index / SKIN_TEXTURE_WIDTH );

}

vec3 skinnedPosition( const in int vertex ) {

	return texelFetch( skinnedPositions, skinTexel( vertex ), 0 ).xyz;

}

// Where a pass draws vertex `vertex`'s point: the centre of its texel, in clip space.
vec4 texelClipPosition( const in int vertex, const in vec2 targetSize ) {

	return vec4( ( vec2( skinTexel( vertex ) ) + 0.5 ) / targetSize * 2.0 - 1.0, 0.0, 1.0 );

}
