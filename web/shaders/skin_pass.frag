// Writes the skinned position; w = 1 marks the texel as written (deformedPositions checks
// that every vertex came back).

flat in vec3 vSkinned;

layout( location = 0 ) out highp vec4 skinnedPosition;

void main() {

	skinnedPosition = vec4( vSkinned, 1.0 );

}
