// Skinning pass of SkinnedFace: web/shaders/skinning.glsl (or, driven by muscles,
// muscles.glsl; by ARKit's blendshapes, arkit.glsl) over every vertex, one point per
// vertex (drawArrays, so gl_VertexID is the vertex index) into its texel of an RGBA32F
// target (vertex_texels.glsl). face.vert draws from that texture and deformedPositions()
// reads it back: the shader-vs-CPU test checks what is drawn.

#include "skinning.glsl"
#include "morph_targets.glsl"
#include "muscles.glsl"
#include "arkit.glsl"
#include "vertex_texels.glsl"

uniform vec2 passSize; // target width and height, texels

flat out vec3 vValue; // skinned position, mesh units

void main() {

	// the drive in use: ARKit's shapes, the muscles, or the feature points' skinning
	#if defined( ARKIT_TARGETS )

		if ( arkitDrive ) vValue = arkitPosition( gl_VertexID, position ); else

	#endif
	#if defined( MUSCLE_TARGETS )

		if ( muscleDrive ) vValue = musclePosition( gl_VertexID, position ); else

	#endif
	vValue = position + skinDisplacement( gl_VertexID );
	gl_Position = texelClipPosition( gl_VertexID, passSize );
	gl_PointSize = 1.0;

}
