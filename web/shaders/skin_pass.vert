// Skinning pass of SkinnedFace: web/shaders/skinning.glsl over every vertex, one point per
// vertex (drawArrays, so gl_VertexID is the vertex index) written to texel
// (v % SKIN_TEXTURE_WIDTH, v / SKIN_TEXTURE_WIDTH) of an RGBA32F target. face.vert draws
// from that texture and deformedPositions() reads it back: the test checks what is drawn.

#include "skinning.glsl"

uniform vec2 skinPassSize; // target width and height, texels

flat out vec3 vSkinned;

void main() {

	int vertex = gl_VertexID;
	vSkinned = position + skinDisplacement( vertex );

	vec2 texel = vec2( vertex % SKIN_TEXTURE_WIDTH, vertex / SKIN_TEXTURE_WIDTH ) + 0.5;
	gl_Position = vec4( texel / skinPassSize * 2.0 - 1.0, 0.0, 1.0 );
	gl_PointSize = 1.0;

}
