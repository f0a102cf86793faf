// Normal pass of SkinnedFace, after the skinning pass: the unit normal of the deformed
// surface at every vertex, into its texel of an RGBA32F target that face.vert reads.
//
// Rest normals would light an open jaw as if it were closed, so these are the normals of
// the deformed mesh: a vertex's normal is the area-weighted sum of its triangles' normals
// (three.js's computeVertexNormals, here on the skinned positions), over every triangle at
// its position (the copies a UV seam or an STL makes share theirs: no crease along a seam).
// incidenceTexture lists, for each such triangle, the other two corners in winding order,
// at texels incidence.x .. incidence.x + incidence.y - 1. Runs once per pose, not per draw.

#include "skinning.glsl"
#include "vertex_texels.glsl"

uniform highp sampler2D incidenceTexture; // RG32F: vertex indices (exact in float32 below 2^24)
uniform vec2 passSize;

in uvec2 incidence; // first texel and count in incidenceTexture

flat out vec3 vValue; // unit normal, object space

void main() {

	vec3 p = skinnedPosition( gl_VertexID );
	vec3 areaNormal = vec3( 0.0 );
	int first = int( incidence.x );
	int end = first + int( incidence.y );
	for ( int i = first; i < end; i ++ ) {

		vec2 corners = texelFetch( incidenceTexture, skinTexel( i ), 0 ).xy;
		areaNormal += cross( skinnedPosition( int( corners.x ) ) - p, skinnedPosition( int( corners.y ) ) - p );

	}

	// only triangles crushed to nothing leave no normal: keep the rest one
	vValue = dot( areaNormal, areaNormal ) > 0.0 ? normalize( areaNormal ) : normal;
	gl_Position = texelClipPosition( gl_VertexID, passSize );
	gl_PointSize = 1.0;

}
