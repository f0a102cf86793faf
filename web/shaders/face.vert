// Display pass of SkinnedFace: the surface at the positions the skinning pass wrote, with
// the normals the normal pass wrote (both per pose, not per draw), lit in face.frag.
// three.js's ShaderMaterial prefix declares position, normal, uv and the matrices.

#include "skinning.glsl"
#include "vertex_texels.glsl"

uniform highp sampler2D skinnedNormals; // the normal pass's target: unit normals, object space
uniform int heatJoint;                  // joint whose weights colour the surface; -1: off

out vec3 vViewPosition; // view space
out vec3 vNormal;       // view space
out float vHeat;        // weight of heatJoint
out vec2 vUv;           // texture coordinates (0, 0 for a mesh without uv)

void main() {

	vec4 viewPosition = modelViewMatrix * vec4( skinnedPosition( gl_VertexID ), 1.0 );
	vViewPosition = viewPosition.xyz;
	vNormal = normalMatrix * texelFetch( skinnedNormals, skinTexel( gl_VertexID ), 0 ).xyz;
	vHeat = heatJoint >= 0 ? skinWeightOf( gl_VertexID, heatJoint ) : 0.0;
	vUv = uv;

	gl_Position = projectionMatrix * viewPosition;

}
