// Fragment stage of the skinning and normal passes: each point is one texel of an
// RGBA32F target, written with its vertex's value; w = 1 marks the texel as written
// (SkinnedFace checks that every vertex came back).

flat in vec3 vValue;

layout( location = 0 ) out highp vec4 texel;

void main() {

	texel = vec4( vValue, 1.0 );

}
