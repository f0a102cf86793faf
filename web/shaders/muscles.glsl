// The played muscles (Woodward et al. §4 in the form retarget/muscles/morphs.py plays them,
// issue 15): one morph target per muscle, then the jaw as a joint with linear blend
// skinning, glTF's order (morph targets first, the skin after, glTF 2.0 §3.7.3):
//
//     m = v0 + sum_t w[t] * target[t, v]
//     v = m + jawWeight[v] * ( R(jawAxis, jawAngle) (m - jawPivot) + jawPivot - m )
//
// The GPU twin of `played_displacements`. Weights come from the contractions (the page's
// PlayedMuscles.weights: a muscle's c_m / high_m, a corrective's that times jaw / jaw_high),
// so the targets are alike here: the muscles', then the correctives.
//
// MUSCLE_TARGETS (defined by SkinnedFace.setMuscles) is the target count T; without it a
// face has no muscles and this chunk is empty. Targets are read as morph_targets.glsl
// says (a vertex's T targets adjacent in an RGBA32F texture). Needs skinning.glsl and
// morph_targets.glsl first.

#if defined( MUSCLE_TARGETS )

	uniform bool muscleDrive; // the muscles pose the face, not the feature points' skinning
	uniform highp sampler2D muscleTargetTexture;
	uniform float muscleWeights[ MUSCLE_TARGETS ];
	uniform vec3 jawPivot;  // a point on the hinge axis, mesh units
	uniform vec3 jawAxis;   // unit; a positive angle opens the mouth
	uniform float jawAngle; // radians

	in float jawWeight; // the vertex's weight on the jaw joint, the rest on the static root

	// Position of vertex `vertex` at rest position `rest`, posed by the muscles.
	vec3 musclePosition( const in int vertex, const in vec3 rest ) {

		vec3 morphed = rest;
		MORPH_TARGETS_ADD( morphed, muscleTargetTexture, muscleWeights, MUSCLE_TARGETS, vertex )

		// Rodrigues: R r = r cos + (axis x r) sin + axis (axis . r)(1 - cos)
		vec3 r = morphed - jawPivot;
		float c = cos( jawAngle ), s = sin( jawAngle );
		vec3 turned = r * c + cross( jawAxis, r ) * s + jawAxis * dot( jawAxis, r ) * ( 1.0 - c ) + jawPivot;
		return morphed + jawWeight * ( turned - morphed );

	}

#endif
