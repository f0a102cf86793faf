// Display pass of SkinnedFace: the surface at the positions the skinning pass
// (skin_pass.vert) wrote, with the deformed vertex normals, lit in face.frag.
// three.js's ShaderMaterial prefix declares position, normal and the matrices.
//
// Normals: the exact normals of the deformed surface, not the rest normals (which would
// light an open jaw as if it were closed). A vertex's normal is the area-weighted sum of
// its triangles' normals, as three.js's computeVertexNormals does at rest, from the
// skinned positions of its neighbours: incidenceTexture lists, for each triangle of each
// vertex, the other two corners in winding order (texels incidence.x .. incidence.x +
// incidence.y - 1). About 6 triangles a vertex, read from a texture written once per pose.

#include "skinning.glsl"

uniform highp sampler2D skinnedPositions; // the skinning pass's target
uniform highp sampler2D incidenceTexture; // RG32F: vertex indices (exact in float32 below 2^24)
uniform int heatJoint;                    // joint whose weights colour the surface; -1: off

in uvec2 incidence; // first texel and count in incidenceTexture

out vec3 vViewPosition; // view space
out vec3 vNormal;       // view space
out float vHeat;        // weight of heatJoint

ivec2 skinTexel( const in int index ) {

	return ivec2( index % SKIN_TEXTURE_WIDTH, index / SKIN_TEXTURE_WIDTH );

}

vec3 skinnedPosition( const in int vertex ) {

	return texelFetch( skinnedPositions, skinTexel( vertex ), 0 ).xyz;

}

void main() {

	vec3 skinned = skinnedPosition( gl_VertexID );

	vec3 areaNormal = vec3( 0.0 );
	int first = int( incidence.x );
	int end = first + int( incidence.y );
	for ( int i = first; i < end; i ++ ) {

		vec2 corners = texelFetch( incidenceTexture, skinTexel( i ), 0 ).xy;
		areaNormal += cross( skinnedPosition( int( corners.x ) ) - skinned, skinnedPosition( int( corners.y ) ) - skinned );

	}

	// only triangles crushed to nothing leave no normal: keep the rest one
	vec3 objectNormal = dot( areaNormal, areaNormal ) > 0.0 ? areaNormal : normal;

	vec4 viewPosition = modelViewMatrix * vec4( skinned, 1.0 );
	vViewPosition = viewPosition.xyz;
	vNormal = normalMatrix * objectNormal;
	vHeat = heatJoint >= 0 ? skinWeightOf( gl_VertexID, heatJoint ) : 0.0;

	gl_Position = projectionMatrix * viewPosition;

}
