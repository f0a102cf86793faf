// Skinning pass of SkinnedFace: web/shaders/skinning.glsl (or, driven by muscles,
// muscles.glsl) over every vertex, one point per
// vertex (drawArrays, so gl_VertexID is the vertex index) into its texel of an RGBA32F
// target (vertex_texels.glsl). face.vert draws from that texture and deformedPositions()
// reads it back: the shader-vs-CPU test checks what is drawn.

#include "skinning.glsl"
#include "muscles.glsl"
#include "vertex_texels.glsl"

uniform vec2 passSize; // target width and height, texels

flat out vec3 vValue; // skinned position, mesh units

void main() {

	#if defined( MUSCLE_TARGETS )

		vValue = muscleDrive ? musclePosition( gl_VertexID, position ) : position + skinDisplacement( gl_VertexID );

	#else

		vValue = position + skinDisplacement( gl_VertexID );

	#endif
	gl_Position = texelClipPosition( gl_VertexID, passSize );
	gl_PointSize = 1.0;

}
